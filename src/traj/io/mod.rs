//! Reference trajectory files: MCAP (one JSON message per keyframe) and CSV (one row per
//! keyframe). The format is documented for users in `docs/references.md` (section "Reference trajectory format"); keep the two in
//! step (tests/traj.rs checks that the JSON Schema and the examples there match this code).
//!
//! Reading is strict and never panics: every problem is a one-line error naming the file, the
//! frame (MCAP: the index of the message on the reference topic, in file order, from 0) or CSV
//! line (from 1), the field or column, and what was expected. Values a simulation cannot hold are
//! errors too: times beyond [`MAX_DURATION_S`], positions beyond ±[`MAX_POSITION_M`], joint values
//! beyond ±[`MAX_JOINT_RAD`], more than [`MAX_KEYFRAMES`] frames.
//!
//! Numbers are parsed from their text with the standard library (correctly rounded, f32 values
//! straight to f32), and written in the shortest form that reads back to the same value, so a
//! save/load round trip reproduces every f32 and f64 exactly.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::fmt;
use std::io::Cursor;
use std::path::Path;

use anyhow::{Result, anyhow};
use glam::{DVec4, Quat, Vec3};
use serde::ser::{Serialize, SerializeMap, Serializer};

use super::{MAX_DURATION_S, MAX_JOINT_RAD, MAX_KEYFRAMES, MAX_POSITION_M, QUAT_NORM_TOLERANCE, Trajectory, is_valid_name};
use crate::geom::Pose;
use crate::traj::Keyframe;

mod csv_rows;
mod json;
mod mcap_messages;

use csv_rows::*;
use mcap_messages::*;

/// MCAP topic of the reference messages.
pub const REFERENCE_TOPIC: &str = "/dextrain/reference";
/// MCAP schema name of the reference messages (schema encoding `jsonschema`, message encoding
/// `json`).
pub const REFERENCE_SCHEMA_NAME: &str = "dextrain.ReferenceFrame";
/// Name of the MCAP metadata record describing the file (`format_version`, `generator`).
pub const REFERENCE_METADATA_NAME: &str = "dextrain.reference";
/// Value of `format_version` in the metadata record. Readers reject other versions.
pub const FORMAT_VERSION: &str = "1";

/// The JSON Schema (draft 2020-12) of one reference message, stored as the MCAP schema.
pub const REFERENCE_JSON_SCHEMA: &str = r##"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "dextrain.ReferenceFrame",
  "description": "One keyframe of a dextrain reference trajectory. Units: metres, radians, seconds. Poses and positions are in the world frame, z up.",
  "type": "object",
  "properties": {
    "t": {
      "description": "Time of the keyframe (s) from the start of the reference.",
      "type": "number",
      "minimum": 0
    },
    "wrist": {
      "description": "Pose of the wrist (the hand's root link).",
      "$ref": "#/$defs/Pose"
    },
    "joints": {
      "description": "Joint position targets (rad) by joint name. Every frame names the same joints.",
      "type": "object",
      "propertyNames": { "$ref": "#/$defs/Name" },
      "additionalProperties": { "type": "number" }
    },
    "fingertips": {
      "description": "Optional fingertip positions by fingertip name. In every frame or in none; every frame names the same fingertips.",
      "type": "object",
      "propertyNames": { "$ref": "#/$defs/Name" },
      "additionalProperties": { "$ref": "#/$defs/Point" }
    },
    "object": {
      "description": "Optional pose of the manipulated object. In every frame or in none.",
      "$ref": "#/$defs/Pose"
    }
  },
  "required": ["t", "wrist", "joints"],
  "additionalProperties": false,
  "$defs": {
    "Name": {
      "type": "string",
      "pattern": "^[^\\s,\"\\u0000-\\u001f]+$"
    },
    "Point": {
      "description": "A position (m).",
      "type": "object",
      "properties": {
        "x": { "type": "number" },
        "y": { "type": "number" },
        "z": { "type": "number" }
      },
      "required": ["x", "y", "z"],
      "additionalProperties": false
    },
    "Pose": {
      "description": "A position (m) and an orientation as a unit quaternion (qx, qy, qz, qw).",
      "type": "object",
      "properties": {
        "x": { "type": "number" },
        "y": { "type": "number" },
        "z": { "type": "number" },
        "qx": { "type": "number" },
        "qy": { "type": "number" },
        "qz": { "type": "number" },
        "qw": { "type": "number" }
      },
      "required": ["x", "y", "z", "qx", "qy", "qz", "qw"],
      "additionalProperties": false
    }
  }
}
"##;

/// Quaternions this close to unit length are taken exactly as written; further off (but within
/// [`QUAT_NORM_TOLERANCE`]) they are normalised.
const QUAT_KEEP_TOLERANCE: f64 = 1e-6;

const POSE_KEYS: [&str; 7] = ["x", "y", "z", "qx", "qy", "qz", "qw"];
const POINT_KEYS: [&str; 3] = ["x", "y", "z"];
const TOP_KEYS: [&str; 5] = ["t", "wrist", "joints", "fingertips", "object"];

fn generator() -> String {
    format!("dextrain {}", env!("CARGO_PKG_VERSION"))
}

// ---------------------------------------------------------------------------------------------
// Public API
// ---------------------------------------------------------------------------------------------

impl Trajectory {
    /// Reads a reference file, by extension: `.mcap` or `.csv` (any case).
    pub fn load(path: impl AsRef<Path>) -> Result<Trajectory> {
        let path = path.as_ref();
        let name = path.display().to_string();
        match extension(path).as_deref() {
            Some("mcap") => {
                let bytes = std::fs::read(path).map_err(|e| fail(&name, Loc::File, format!("cannot read: {e}")))?;
                Trajectory::from_mcap_bytes(&bytes, &name)
            }
            Some("csv") => {
                let bytes = std::fs::read(path).map_err(|e| fail(&name, Loc::File, format!("cannot read: {e}")))?;
                let text = std::str::from_utf8(&bytes).map_err(|e| {
                    fail(
                        &name,
                        Loc::File,
                        format!("expected UTF-8 text, got invalid UTF-8 at byte {}", e.valid_up_to()),
                    )
                })?;
                Trajectory::from_csv_str(text, &name)
            }
            other => Err(bad_extension(&name, other)),
        }
    }

    /// Writes the reference, by extension: `.mcap` or `.csv` (any case).
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        match extension(path).as_deref() {
            Some("mcap") => self.save_mcap(path),
            Some("csv") => self.save_csv(path),
            other => Err(bad_extension(&path.display().to_string(), other)),
        }
    }

    /// Writes the reference as MCAP (zstd-compressed chunks), whatever the extension.
    pub fn save_mcap(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let name = path.display().to_string();
        let bytes = self.to_mcap_bytes().map_err(|e| fail(&name, Loc::File, format!("cannot save: {e}")))?;
        crate::files::create_parent_dir(path).map_err(|e| fail(&name, Loc::File, format!("{e:#}")))?;
        std::fs::write(path, bytes).map_err(|e| fail(&name, Loc::File, format!("cannot write: {e}")))
    }

    /// Writes the reference as CSV, whatever the extension.
    pub fn save_csv(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let name = path.display().to_string();
        let text = self.to_csv_string().map_err(|e| fail(&name, Loc::File, format!("cannot save: {e}")))?;
        crate::files::create_parent_dir(path).map_err(|e| fail(&name, Loc::File, format!("{e:#}")))?;
        std::fs::write(path, text).map_err(|e| fail(&name, Loc::File, format!("cannot write: {e}")))
    }

    /// Reads an MCAP reference held in memory; `source` names it in errors (e.g. the file name).
    /// Accepts any chunk compression (none, zstd, lz4) and any number of channels on
    /// [`REFERENCE_TOPIC`] (messages of other topics are ignored); frames may come in any order
    /// and are sorted by `t`. The messages' log times are not used. Reading stops at the data end
    /// record (the summary is not needed); a file that ends before it is an error.
    pub fn from_mcap_bytes(bytes: &[u8], source: &str) -> Result<Trajectory> {
        if bytes.is_empty() {
            return Err(fail(source, Loc::File, "empty file: expected an MCAP file"));
        }
        let mcap_err = |e: mcap::McapError| {
            fail(source, Loc::File, format!("expected a readable MCAP file, got a read error: {e}"))
        };

        let mut raws = Vec::new();
        let mut object_name = None;
        let mut other_topics = BTreeSet::new();
        // channel id -> (topic, message encoding)
        let mut channels: HashMap<u16, (String, String)> = HashMap::new();
        let mut records = McapRecords::new(bytes);
        let mut complete = false;
        while let Some(record) = records.next_record() {
            use mcap::records::Record;
            match record.map_err(mcap_err)? {
                Record::Metadata(m) if m.name == REFERENCE_METADATA_NAME => {
                    if let Some(o) = m.metadata.get("object") {
                        object_name = Some(check_object_name(source, o)?);
                    }
                    let got = match m.metadata.get("format_version") {
                        Some(v) if v == FORMAT_VERSION => continue,
                        Some(v) => format!("{v:?}"),
                        None => "nothing".to_string(),
                    };
                    return Err(fail(
                        source,
                        Loc::File,
                        format!(
                            "metadata `{REFERENCE_METADATA_NAME}`: field `format_version`: expected {FORMAT_VERSION:?}, got {got}"
                        ),
                    ));
                }
                Record::Channel(ch) => {
                    channels.insert(ch.id, (ch.topic, ch.message_encoding));
                }
                Record::Message { header, data } => {
                    let Some((topic, encoding)) = channels.get(&header.channel_id) else {
                        return Err(fail(
                            source,
                            Loc::File,
                            format!(
                                "expected a readable MCAP file, got a message on channel {} before any channel record with that id",
                                header.channel_id
                            ),
                        ));
                    };
                    if topic != REFERENCE_TOPIC {
                        other_topics.insert(format!("{topic:?}"));
                        continue;
                    }
                    let loc = Loc::Frame(raws.len());
                    if raws.len() >= MAX_KEYFRAMES {
                        return Err(fail(source, loc, too_many_frames()));
                    }
                    if encoding != "json" {
                        return Err(fail(
                            source,
                            loc,
                            format!(
                                "channel {} on `{REFERENCE_TOPIC}`: message encoding: expected \"json\", got {encoding:?}",
                                header.channel_id
                            ),
                        ));
                    }
                    let text = std::str::from_utf8(&data).map_err(|e| {
                        fail(
                            source,
                            loc,
                            format!("expected a UTF-8 JSON message, got invalid UTF-8 at byte {}", e.valid_up_to()),
                        )
                    })?;
                    let value = json::parse(text).map_err(|e| fail(source, loc, e))?;
                    raws.push(raw_frame_from_json(&value, loc).map_err(|e| fail(source, loc, e))?);
                }
                // The summary after the data section only repeats what came before.
                Record::DataEnd(_) => {
                    complete = true;
                    break;
                }
                _ => {}
            }
        }
        if !complete {
            return Err(fail(
                source,
                Loc::File,
                "expected a complete MCAP file, got one that ends before its data end record (truncated?)",
            ));
        }
        if raws.is_empty() {
            let others = if other_topics.is_empty() {
                String::new()
            } else {
                format!(" (topics in the file: {})", other_topics.into_iter().collect::<Vec<_>>().join(", "))
            };
            return Err(fail(
                source,
                Loc::File,
                format!("no messages on topic `{REFERENCE_TOPIC}`: expected at least 1 frame{others}"),
            ));
        }
        assemble(source, raws).map(|t| Trajectory { object_name, ..t })
    }

    /// The MCAP file [`save_mcap`](Self::save_mcap) writes: a `dextrain.reference` metadata
    /// record, one schema and one channel on [`REFERENCE_TOPIC`], one message per frame with log
    /// and publish time `t` in ns, in zstd-compressed chunks.
    pub fn to_mcap_bytes(&self) -> Result<Vec<u8>> {
        self.validate()?;
        let e = |e: mcap::McapError| anyhow!("cannot write MCAP: {e}");
        let mut w = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .profile("")
            .library(generator())
            .create(Cursor::new(Vec::new()))
            .map_err(e)?;
        let mut metadata = BTreeMap::from([
            ("format_version".to_string(), FORMAT_VERSION.to_string()),
            ("generator".to_string(), generator()),
        ]);
        if let Some(o) = &self.object_name {
            metadata.insert("object".to_string(), o.clone());
        }
        w.write_metadata(&mcap::records::Metadata { name: REFERENCE_METADATA_NAME.into(), metadata }).map_err(e)?;
        let schema = w.add_schema(REFERENCE_SCHEMA_NAME, "jsonschema", REFERENCE_JSON_SCHEMA.as_bytes()).map_err(e)?;
        let channel = w.add_channel(schema, REFERENCE_TOPIC, "json", &BTreeMap::new()).map_err(e)?;
        for (i, frame) in self.frames.iter().enumerate() {
            let data = serde_json::to_vec(&MessageSer { traj: self, frame })?;
            let ns = (frame.t * 1e9).round() as u64;
            let header = mcap::records::MessageHeader {
                channel_id: channel,
                sequence: i as u32,
                log_time: ns,
                publish_time: ns,
            };
            w.write_to_known_channel(&header, &data).map_err(e)?;
        }
        w.finish().map_err(e)?;
        Ok(w.into_inner().into_inner())
    }

    /// Reads a CSV reference held in memory; `source` names it in errors (e.g. the file name).
    /// See `docs/references.md` (section "Reference trajectory format") for the columns. Blank lines and lines starting with `#`
    /// are skipped, cells are trimmed, rows may come in any order (they are sorted by `t`).
    pub fn from_csv_str(text: &str, source: &str) -> Result<Trajectory> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        // `# object: NAME` (a comment line, before the header) names the demonstration's object
        let mut object_name = None;
        for l in text.lines() {
            let l = l.trim();
            if let Some(rest) = l.strip_prefix('#') {
                if let Some(name) = rest.trim().strip_prefix("object:") {
                    object_name = Some(check_object_name(source, name.trim())?);
                }
            } else if !l.is_empty() {
                break;
            }
        }
        let mut lines =
            text.split('\n').enumerate().map(|(i, l)| (i + 1, l.strip_suffix('\r').unwrap_or(l))).filter(|(_, l)| {
                let l = l.trim();
                !l.is_empty() && !l.starts_with('#')
            });
        let Some((header_line, header)) = lines.next() else {
            return Err(fail(source, Loc::File, "empty file: expected a header row starting `t,wrist_x,...`"));
        };
        let layout = CsvLayout::parse(header).map_err(|e| fail(source, Loc::Line(header_line), e))?;
        let mut raws = Vec::new();
        for (n, line) in lines {
            let loc = Loc::Line(n);
            if raws.len() >= MAX_KEYFRAMES {
                return Err(fail(source, loc, too_many_frames()));
            }
            raws.push(layout.row(line, loc).map_err(|e| fail(source, loc, e))?);
        }
        if raws.is_empty() {
            return Err(fail(source, Loc::File, "no data rows after the header: expected at least 1 frame"));
        }
        assemble(source, raws).map(|t| Trajectory { object_name, ..t })
    }

    /// The CSV text [`save_csv`](Self::save_csv) writes: `# object: NAME` when the reference names
    /// its object, the header, then one row per frame.
    pub fn to_csv_string(&self) -> Result<String> {
        use std::fmt::Write;
        self.validate()?;
        let mut cols: Vec<String> = vec!["t".into()];
        cols.extend(POSE_KEYS.iter().map(|k| format!("wrist_{k}")));
        cols.extend(self.joint_names.iter().map(|j| format!("joint:{j}")));
        let tips = self.has_fingertips();
        if tips {
            for name in &self.fingertip_names {
                cols.extend(POINT_KEYS.iter().map(|a| format!("tip:{name}:{a}")));
            }
        }
        let object = self.has_object();
        if object {
            cols.extend(POSE_KEYS.iter().map(|k| format!("object_{k}")));
        }
        let mut out = self.object_name.as_ref().map_or(String::new(), |o| format!("# object: {o}\n"));
        out.push_str(&cols.join(","));
        out.push('\n');
        for f in &self.frames {
            let _ = write!(out, "{}", f.t);
            let mut put = |x: f32| {
                let _ = write!(out, ",{x}");
            };
            pose_values(&f.wrist).into_iter().for_each(&mut put);
            f.joints.iter().for_each(|&x| put(x));
            if let (true, Some(p)) = (tips, &f.fingertips) {
                p.iter().flat_map(|v| v.to_array()).for_each(&mut put);
            }
            if let (true, Some(p)) = (object, &f.object) {
                pose_values(p).into_iter().for_each(&mut put);
            }
            out.push('\n');
        }
        Ok(out)
    }
}

fn extension(path: &Path) -> Option<String> {
    path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase())
}

fn bad_extension(name: &str, ext: Option<&str>) -> anyhow::Error {
    let got = match ext {
        Some(e) => format!("`.{e}`"),
        None => "none".into(),
    };
    fail(name, Loc::File, format!("unknown trajectory file extension: expected `.mcap` or `.csv`, got {got}"))
}

/// The records of an MCAP file held in memory, chunks unpacked, with every record length and chunk
/// size bounded: `mcap::MessageStream` trusts the lengths inside chunks, so a corrupt file could
/// make it try to allocate petabytes (an abort, not an error).
pub struct McapRecords<'a> {
    reader: mcap::sans_io::LinearReader,
    rest: &'a [u8],
    done: bool,
}

impl<'a> McapRecords<'a> {
    pub fn new(bytes: &'a [u8]) -> Self {
        // A record is never longer than the file, except inside compressed chunks: allow those
        // 64 MiB more. (A reference frame is a few kB.)
        let limit = bytes.len().saturating_add(64 << 20);
        let options = mcap::sans_io::LinearReaderOptions::default()
            .with_record_length_limit(limit)
            .with_validate_chunk_crcs(true)
            .with_skip_end_magic(true);
        McapRecords { reader: mcap::sans_io::LinearReader::new_with_options(options), rest: bytes, done: false }
    }

    pub fn next_record(&mut self) -> Option<mcap::McapResult<mcap::records::Record<'static>>> {
        if self.done {
            return None;
        }
        while let Some(event) = self.reader.next_event() {
            match event {
                Ok(mcap::sans_io::LinearReadEvent::ReadRequest(need)) => {
                    let n = need.min(self.rest.len());
                    self.reader.insert(n).copy_from_slice(&self.rest[..n]);
                    self.reader.notify_read(n);
                    self.rest = &self.rest[n..];
                }
                Ok(mcap::sans_io::LinearReadEvent::Record { data, opcode }) => {
                    let record = mcap::parse_record(opcode, data).map(|r| r.into_owned());
                    self.done = record.is_err();
                    return Some(record);
                }
                Err(e) => {
                    self.done = true;
                    return Some(Err(e));
                }
            }
        }
        self.done = true;
        None
    }
}

// ---------------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------------

/// Where in a file a problem is.
#[derive(Clone, Copy, Debug)]
enum Loc {
    File,
    /// MCAP: index of the message on the reference topic, in file order.
    Frame(usize),
    /// CSV: line number from 1.
    Line(usize),
}

impl Loc {
    /// How a value is named at this place: a JSON field or a CSV column.
    fn field_word(self) -> &'static str {
        match self {
            Loc::Line(_) => "column",
            _ => "field",
        }
    }
}

impl fmt::Display for Loc {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Loc::File => write!(f, "the file"),
            Loc::Frame(i) => write!(f, "frame {i}"),
            Loc::Line(n) => write!(f, "line {n}"),
        }
    }
}

/// One-line error: `<source>: <frame i | line n>: <what>`.
fn fail(source: &str, loc: Loc, what: impl fmt::Display) -> anyhow::Error {
    let msg = match loc {
        Loc::File => format!("{source}: {what}"),
        loc => format!("{source}: {loc}: {what}"),
    };
    anyhow!(msg.replace(['\n', '\r'], " "))
}

// ---------------------------------------------------------------------------------------------
// Numbers and poses (shared by both readers); errors are "<label>: expected ..., got ..."
// ---------------------------------------------------------------------------------------------

fn describe_text(text: &str) -> String {
    if text.is_empty() { "an empty cell".into() } else { format!("{:?}", truncate(text)) }
}

/// A cell or value for a message: at most 40 characters.
fn truncate(s: &str) -> String {
    crate::text::clip(s, 40)
}

/// Parses a number's text as f64 (finite).
fn number_f64(text: &str, label: &str) -> Result<f64, String> {
    let x: f64 = text.parse().map_err(|_| format!("{label}: expected a number, got {}", describe_text(text)))?;
    if !x.is_finite() {
        return Err(format!("{label}: expected a finite number, got {}", truncate(text)));
    }
    Ok(x)
}

/// Parses a number's text as f32 (finite, in range), straight from the text so that the shortest
/// representation of an f32 reads back exactly. Also returns the f64 reading.
fn number_f32(text: &str, label: &str) -> Result<(f32, f64), String> {
    let x64 = number_f64(text, label)?;
    match text.parse::<f32>() {
        Ok(x) if x.is_finite() => Ok((x, x64)),
        _ => Err(format!("{label}: expected a finite number within f32 range (|x| < 3.4e38), got {}", truncate(text))),
    }
}

fn time(text: &str, label: &str) -> Result<f64, String> {
    let t = number_f64(text, label)?;
    if t < 0.0 {
        return Err(format!("{label}: expected a time ≥ 0 (s), got {}", truncate(text)));
    }
    if t > MAX_DURATION_S {
        return Err(format!(
            "{label}: expected a time ≤ {MAX_DURATION_S} s (a reference lasts at most an hour, MAX_DURATION_S), got {}",
            truncate(text)
        ));
    }
    Ok(t)
}

/// A position coordinate (m): a finite f32 within ±[`MAX_POSITION_M`].
fn position(text: &str, label: &str) -> Result<f32, String> {
    let (x, x64) = number_f32(text, label)?;
    if x64.abs() > MAX_POSITION_M {
        return Err(format!(
            "{label}: expected a position within ±{MAX_POSITION_M} m of the world origin (MAX_POSITION_M), got {}",
            truncate(text)
        ));
    }
    Ok(x)
}

/// A joint target (rad): a finite f32 within ±[`MAX_JOINT_RAD`].
fn joint_value(text: &str, label: &str) -> Result<f32, String> {
    let (x, x64) = number_f32(text, label)?;
    if x64.abs() > MAX_JOINT_RAD {
        return Err(format!(
            "{label}: expected a joint value within ±{MAX_JOINT_RAD} rad (MAX_JOINT_RAD), got {}",
            truncate(text)
        ));
    }
    Ok(x)
}

fn too_many_frames() -> String {
    format!("expected at most {MAX_KEYFRAMES} frames in a reference (MAX_KEYFRAMES), got more")
}

/// A pose from the texts of x, y, z, qx, qy, qz, qw. `labels` name them in errors,
/// `quat_label` names the quaternion.
fn pose_from_texts(texts: [&str; 7], labels: &[String; 7], quat_label: &str) -> Result<Pose, String> {
    let mut v32 = [0f32; 7];
    let mut v64 = [0f64; 7];
    for k in 0..7 {
        (v32[k], v64[k]) = number_f32(texts[k], &labels[k])?;
        if k < 3 {
            position(texts[k], &labels[k])?;
        }
    }
    let q64 = DVec4::new(v64[3], v64[4], v64[5], v64[6]);
    let norm = q64.length();
    let dev = (norm - 1.0).abs();
    if dev.is_nan() || dev >= QUAT_NORM_TOLERANCE {
        return Err(format!(
            "{quat_label}: expected a unit quaternion (norm 1 ± {QUAT_NORM_TOLERANCE}), got norm {norm}"
        ));
    }
    let rot = if dev <= QUAT_KEEP_TOLERANCE {
        Quat::from_xyzw(v32[3], v32[4], v32[5], v32[6])
    } else {
        let q = q64 / norm;
        Quat::from_xyzw(q.x as f32, q.y as f32, q.z as f32, q.w as f32)
    };
    Ok(Pose { pos: Vec3::new(v32[0], v32[1], v32[2]), rot })
}

fn pose_values(p: &Pose) -> [f32; 7] {
    [p.pos.x, p.pos.y, p.pos.z, p.rot.x, p.rot.y, p.rot.z, p.rot.w]
}

// ---------------------------------------------------------------------------------------------
// Frames as read, before the names are checked across frames
// ---------------------------------------------------------------------------------------------

struct RawFrame {
    loc: Loc,
    t: f64,
    wrist: Pose,
    joints: Vec<(String, f32)>,
    fingertips: Option<Vec<(String, Vec3)>>,
    object: Option<Pose>,
}

/// Sorts by `t`, checks that times are distinct and that every frame has the joints, fingertips
/// and object of the earliest one, and builds the trajectory (names in the earliest frame's order).
fn assemble(source: &str, mut raws: Vec<RawFrame>) -> Result<Trajectory> {
    raws.sort_by(|a, b| a.t.total_cmp(&b.t));
    for w in raws.windows(2) {
        if w[1].t == w[0].t {
            return Err(fail(
                source,
                w[1].loc,
                format!(
                    "{} `t`: expected times strictly increasing after sorting (no two frames at the same time), got {} which {} also has",
                    w[1].loc.field_word(),
                    w[1].t,
                    w[0].loc
                ),
            ));
        }
    }
    let first = &raws[0];
    let joint_names: Vec<String> = first.joints.iter().map(|(n, _)| n.clone()).collect();
    let tip_names: Option<Vec<String>> = first.fingertips.as_ref().map(|p| p.iter().map(|(n, _)| n.clone()).collect());
    let joint_index: HashMap<&str, usize> = joint_names.iter().enumerate().map(|(i, n)| (n.as_str(), i)).collect();
    let tip_index: HashMap<&str, usize> =
        tip_names.iter().flatten().enumerate().map(|(i, n)| (n.as_str(), i)).collect();

    let mut frames = Vec::with_capacity(raws.len());
    for raw in &raws {
        let joints = reorder("joints", &raw.joints, &joint_index, first.loc).map_err(|e| fail(source, raw.loc, e))?;
        let fingertips = match (&raw.fingertips, &tip_names) {
            (Some(p), Some(_)) => {
                Some(reorder("fingertips", p, &tip_index, first.loc).map_err(|e| fail(source, raw.loc, e))?)
            }
            (None, None) => None,
            (Some(_), None) => {
                return Err(fail(
                    source,
                    raw.loc,
                    format!(
                        "field `fingertips`: expected fingertips in every frame or in none, got some here but none in {}",
                        first.loc
                    ),
                ));
            }
            (None, Some(_)) => {
                return Err(fail(
                    source,
                    raw.loc,
                    format!(
                        "field `fingertips`: expected fingertips in every frame or in none, got none here but some in {}",
                        first.loc
                    ),
                ));
            }
        };
        if raw.object.is_some() != first.object.is_some() {
            let (here, there) = if raw.object.is_some() { ("a pose", "none") } else { ("none", "a pose") };
            return Err(fail(
                source,
                raw.loc,
                format!(
                    "field `object`: expected an object pose in every frame or in none, got {here} here but {there} in {}",
                    first.loc
                ),
            ));
        }
        frames.push(Keyframe { t: raw.t, wrist: raw.wrist, joints, fingertips, object: raw.object });
    }
    Ok(Trajectory { joint_names, fingertip_names: tip_names.unwrap_or_default(), frames, object_name: None })
}

/// Puts `(name, value)` pairs into the order of `index`, which must hold exactly the same names.
fn reorder<T: Copy + Default>(
    field: &str,
    items: &[(String, T)],
    index: &HashMap<&str, usize>,
    reference: Loc,
) -> Result<Vec<T>, String> {
    let mut out = vec![T::default(); index.len()];
    let mut seen = vec![false; index.len()];
    let mut unexpected = Vec::new();
    for (name, v) in items {
        match index.get(name.as_str()) {
            Some(&i) => {
                out[i] = *v;
                seen[i] = true;
            }
            None => unexpected.push(format!("{name:?}")),
        }
    }
    if unexpected.is_empty() && seen.iter().all(|&s| s) {
        return Ok(out);
    }
    let mut missing: Vec<(usize, &str)> = index.iter().filter(|&(_, &i)| !seen[i]).map(|(&n, &i)| (i, n)).collect();
    missing.sort();
    let missing: Vec<String> = missing.into_iter().map(|(_, n)| format!("{n:?}")).collect();
    let mut got = Vec::new();
    if !missing.is_empty() {
        got.push(format!("missing {}", missing.join(", ")));
    }
    if !unexpected.is_empty() {
        got.push(format!("unexpected {}", unexpected.join(", ")));
    }
    Err(format!("field `{field}`: expected the same names as in {reference}, got {}", got.join("; ")))
}

/// A reference's object name: 1–100 characters, no control characters (one-line errors name them).
fn check_object_name(source: &str, name: &str) -> Result<String> {
    if name.is_empty() || name.chars().count() > 100 || name.chars().any(char::is_control) {
        return Err(fail(source, Loc::File, format!("object name {:?}: expected 1 to 100 characters without control characters", crate::text::clip(name, 40))));
    }
    Ok(name.to_string())
}
