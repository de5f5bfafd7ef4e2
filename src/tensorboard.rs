//! TensorBoard event files, written by hand (no TensorFlow, no protobuf crate).
//!
//! An event file is a sequence of TFRecords:
//!
//! ```text
//! u64 LE  length of data
//! u32 LE  masked crc32c of the 8 length bytes
//! [u8]    data: one serialised `tensorflow.Event` protobuf
//! u32 LE  masked crc32c of data
//! ```
//!
//! The first event carries `file_version = "brain.Event:2"`; every later one a `Summary` with one
//! `simple_value` scalar. The subset of tensorflow/core/util/event.proto and summary.proto used here:
//!
//! ```text
//! Event   { double wall_time = 1; int64 step = 2; string file_version = 3; Summary summary = 5; }
//! Summary { repeated Value value = 1; }
//! Value   { string tag = 1; float simple_value = 2; }
//! ```
//!
//! [`read_scalars`] reads such a file back (checking both CRCs of every record); tests/metrics.rs also
//! reads it with TensorBoard's own `EventAccumulator` when Python's `tensorboard` package is installed.

use std::fs::{File, OpenOptions};
use std::io::{BufWriter, ErrorKind, Write};
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use anyhow::{Context, Result, anyhow, bail};

/// The `file_version` string of the first event of every event file.
pub const FILE_VERSION: &str = "brain.Event:2";

/// Writes one TensorBoard event file: the file_version event, then one event per scalar.
pub struct EventWriter {
    path: PathBuf,
    out: BufWriter<File>,
}

impl EventWriter {
    /// Creates `dir/events.out.tfevents.<unix secs>.<hostname>.<pid>.dextrain` and writes the
    /// file_version event ("brain.Event:2"). Never overwrites: if that name is taken (a second writer
    /// in the same second), `.<n>` is inserted before `.dextrain`.
    pub fn create(dir: &Path) -> Result<EventWriter> {
        let now = SystemTime::now().duration_since(UNIX_EPOCH).unwrap_or_default();
        let stem = format!("events.out.tfevents.{}.{}.{}", now.as_secs(), hostname(), std::process::id());
        let mut n = 0u32;
        let (path, file) = loop {
            let name = if n == 0 { format!("{stem}.dextrain") } else { format!("{stem}.{n}.dextrain") };
            let path = dir.join(name);
            match OpenOptions::new().write(true).create_new(true).open(&path) {
                Ok(file) => break (path, file),
                Err(e) if e.kind() == ErrorKind::AlreadyExists && n < 1000 => n += 1,
                Err(e) => return Err(e).with_context(|| format!("creating event file {}", path.display())),
            }
        };
        let mut writer = EventWriter { path, out: BufWriter::new(file) };
        let mut event = Vec::with_capacity(32);
        put_double(&mut event, 1, now.as_secs_f64()); // wall_time
        put_bytes(&mut event, 3, FILE_VERSION.as_bytes()); // file_version
        writer.write_record(&event)?;
        writer.flush()?;
        Ok(writer)
    }

    /// The path of the event file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Writes one event holding the scalar `value` under `tag` at `step`; `wall_time` is seconds since
    /// the Unix epoch (what TensorBoard's "relative" and "wall" x axes show). Buffered: call
    /// [`EventWriter::flush`] to make it visible to a running TensorBoard.
    pub fn add_scalar(&mut self, tag: &str, step: i64, value: f32, wall_time: f64) -> Result<()> {
        let mut val = Vec::with_capacity(tag.len() + 8);
        put_bytes(&mut val, 1, tag.as_bytes()); // Value.tag
        put_key(&mut val, 2, WIRE_FIXED32); // Value.simple_value
        val.extend_from_slice(&value.to_le_bytes());
        let mut summary = Vec::with_capacity(val.len() + 4);
        put_bytes(&mut summary, 1, &val); // Summary.value
        let mut event = Vec::with_capacity(summary.len() + 24);
        put_double(&mut event, 1, wall_time); // Event.wall_time
        put_key(&mut event, 2, WIRE_VARINT); // Event.step
        put_varint(&mut event, step as u64); // int64: negative steps are 10-byte two's complement
        put_bytes(&mut event, 5, &summary); // Event.summary
        self.write_record(&event)
    }

    /// Flushes buffered events to the file.
    pub fn flush(&mut self) -> Result<()> {
        self.out.flush().with_context(|| format!("writing event file {}", self.path.display()))
    }

    /// One TFRecord: length, crc(length), data, crc(data).
    fn write_record(&mut self, data: &[u8]) -> Result<()> {
        let len = (data.len() as u64).to_le_bytes();
        let mut head = [0u8; 12];
        head[..8].copy_from_slice(&len);
        head[8..].copy_from_slice(&masked_crc32c(&len).to_le_bytes());
        let tail = masked_crc32c(data).to_le_bytes();
        (|| {
            self.out.write_all(&head)?;
            self.out.write_all(data)?;
            self.out.write_all(&tail)
        })()
        .with_context(|| format!("writing event file {}", self.path.display()))
    }
}

/// The host name for event file names (as TensorFlow does), "localhost" when it cannot be read.
fn hostname() -> String {
    let mut buf = [0u8; 256];
    // SAFETY: buf is writable for buf.len() bytes; gethostname writes at most that many.
    let rc = unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) };
    let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
    let name: String = String::from_utf8_lossy(&buf[..end])
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '.' || c == '_' { c } else { '_' })
        .collect();
    if rc != 0 || name.is_empty() { "localhost".to_string() } else { name }
}

// ---------------------------------------------------------------------------------------------
// CRC-32C

/// CRC-32C (Castagnoli, reflected polynomial 0x82F63B78) lookup table, built at compile time.
const CRC32C_TABLE: [u32; 256] = {
    let mut table = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut crc = i as u32;
        let mut k = 0;
        while k < 8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0x82F6_3B78 } else { crc >> 1 };
            k += 1;
        }
        table[i] = crc;
        i += 1;
    }
    table
};

/// CRC-32C (Castagnoli) of `data`: `crc32c(b"123456789") == 0xE3069283`.
pub fn crc32c(data: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in data {
        crc = CRC32C_TABLE[((crc ^ b as u32) & 0xFF) as usize] ^ (crc >> 8);
    }
    !crc
}

/// TFRecord's masked CRC-32C: `((crc >> 15) | (crc << 17)) + 0xa282ead8` (wrapping).
pub fn masked_crc32c(data: &[u8]) -> u32 {
    let crc = crc32c(data);
    crc.rotate_right(15).wrapping_add(0xA282_EAD8)
}

// ---------------------------------------------------------------------------------------------
// Protobuf encoding (the few wire types the Event message needs)

const WIRE_VARINT: u32 = 0;
const WIRE_FIXED64: u32 = 1;
const WIRE_LEN: u32 = 2;
const WIRE_FIXED32: u32 = 5;

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// Field key: (field number << 3) | wire type.
fn put_key(out: &mut Vec<u8>, field: u32, wire: u32) {
    put_varint(out, ((field << 3) | wire) as u64);
}

fn put_double(out: &mut Vec<u8>, field: u32, v: f64) {
    put_key(out, field, WIRE_FIXED64);
    out.extend_from_slice(&v.to_le_bytes());
}

fn put_bytes(out: &mut Vec<u8>, field: u32, bytes: &[u8]) {
    put_key(out, field, WIRE_LEN);
    put_varint(out, bytes.len() as u64);
    out.extend_from_slice(bytes);
}

// ---------------------------------------------------------------------------------------------
// Reading

/// One scalar read back from an event file, with its wall time.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct ScalarEvent {
    pub tag: String,
    pub step: i64,
    pub value: f32,
    pub wall_time: f64,
}

/// Reads every scalar (`simple_value`) of an event file back: (tag, step, value), in file order,
/// checking both CRCs of every record. A truncated or corrupted file is an error naming the file and
/// the byte offset of the bad record.
pub fn read_scalars(path: &Path) -> Result<Vec<(String, i64, f32)>> {
    let events = read_scalar_events(path, false)?;
    Ok(events.into_iter().map(|e| (e.tag, e.step, e.value)).collect())
}

/// Like [`read_scalars`], with wall times. With `stop_at_bad_record`, a bad record (the torn tail of
/// a run that was killed while writing) ends the read instead of failing it.
pub(crate) fn read_scalar_events(path: &Path, stop_at_bad_record: bool) -> Result<Vec<ScalarEvent>> {
    let bytes = std::fs::read(path).with_context(|| format!("reading event file {}", path.display()))?;
    let mut out = Vec::new();
    let mut pos = 0usize;
    while pos < bytes.len() {
        let data = match record_at(&bytes, pos) {
            Ok(data) => data,
            Err(_) if stop_at_bad_record => break,
            Err(e) => bail!("event file {}: record at byte {pos}: {e}", path.display()),
        };
        match parse_event(data, &mut out) {
            Ok(()) => {}
            Err(_) if stop_at_bad_record => break,
            Err(e) => bail!("event file {}: record at byte {pos}: {e}", path.display()),
        }
        pos += 16 + data.len();
    }
    Ok(out)
}

/// The data of the TFRecord starting at `pos`, after checking its framing and both CRCs.
fn record_at(bytes: &[u8], pos: usize) -> Result<&[u8]> {
    let head = bytes.get(pos..pos + 12).ok_or_else(|| anyhow!("truncated record header"))?;
    let len_bytes = &head[..8];
    let len_crc = u32::from_le_bytes([head[8], head[9], head[10], head[11]]);
    if masked_crc32c(len_bytes) != len_crc {
        bail!("length CRC mismatch");
    }
    let len = u64::from_le_bytes(len_bytes.try_into().expect("8 bytes"));
    let start = pos + 12;
    let end = usize::try_from(len).ok().and_then(|l| start.checked_add(l)).filter(|&e| e + 4 <= bytes.len());
    let end = end.ok_or_else(|| anyhow!("truncated record ({len} data bytes announced)"))?;
    let data = &bytes[start..end];
    let data_crc = u32::from_le_bytes(bytes[end..end + 4].try_into().expect("4 bytes"));
    if masked_crc32c(data) != data_crc {
        bail!("data CRC mismatch");
    }
    Ok(data)
}

/// A minimal protobuf reader over one message.
struct Proto<'a> {
    buf: &'a [u8],
    pos: usize,
}

/// A field's payload.
enum Field<'a> {
    Varint(u64),
    Fixed64([u8; 8]),
    Bytes(&'a [u8]),
    Fixed32([u8; 4]),
}

impl<'a> Proto<'a> {
    fn new(buf: &'a [u8]) -> Self {
        Proto { buf, pos: 0 }
    }

    fn varint(&mut self) -> Result<u64> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let b = *self.buf.get(self.pos).ok_or_else(|| anyhow!("truncated varint"))?;
            self.pos += 1;
            v |= ((b & 0x7F) as u64) << shift;
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        bail!("varint longer than 10 bytes")
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.buf.len());
        let end = end.ok_or_else(|| anyhow!("truncated field"))?;
        let s = &self.buf[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    /// The next (field number, payload), or None at the end of the message.
    fn next_field(&mut self) -> Result<Option<(u64, Field<'a>)>> {
        if self.pos >= self.buf.len() {
            return Ok(None);
        }
        let key = self.varint()?;
        let field = match (key & 7) as u32 {
            WIRE_VARINT => Field::Varint(self.varint()?),
            WIRE_FIXED64 => Field::Fixed64(self.take(8)?.try_into().expect("8 bytes")),
            WIRE_LEN => {
                let n = usize::try_from(self.varint()?).map_err(|_| anyhow!("field length overflows"))?;
                Field::Bytes(self.take(n)?)
            }
            WIRE_FIXED32 => Field::Fixed32(self.take(4)?.try_into().expect("4 bytes")),
            w => bail!("unsupported protobuf wire type {w}"),
        };
        Ok(Some((key >> 3, field)))
    }
}

/// Appends the simple_value scalars of one serialised Event to `out`.
fn parse_event(data: &[u8], out: &mut Vec<ScalarEvent>) -> Result<()> {
    let mut wall_time = 0.0;
    let mut step = 0i64;
    let mut summaries = Vec::new();
    let mut p = Proto::new(data);
    while let Some((num, field)) = p.next_field()? {
        match (num, field) {
            (1, Field::Fixed64(b)) => wall_time = f64::from_le_bytes(b),
            (2, Field::Varint(v)) => step = v as i64,
            (5, Field::Bytes(b)) => summaries.push(b),
            _ => {} // file_version, log messages, graphs, ...: not scalars
        }
    }
    for summary in summaries {
        let mut s = Proto::new(summary);
        while let Some((num, field)) = s.next_field()? {
            let (1, Field::Bytes(value)) = (num, field) else { continue };
            let mut tag = None;
            let mut simple = None;
            let mut v = Proto::new(value);
            while let Some((num, field)) = v.next_field()? {
                match (num, field) {
                    (1, Field::Bytes(b)) => {
                        tag = Some(String::from_utf8(b.to_vec()).map_err(|_| anyhow!("tag is not UTF-8"))?)
                    }
                    (2, Field::Fixed32(b)) => simple = Some(f32::from_le_bytes(b)),
                    _ => {}
                }
            }
            if let (Some(tag), Some(value)) = (tag, simple) {
                out.push(ScalarEvent { tag, step, value, wall_time });
            }
        }
    }
    Ok(())
}
