//! NumPy's array files: `.npy` (one array) and `.npz` (a zip archive of `.npy` members, stored by
//! `numpy.savez` or deflated by `numpy.savez_compressed`), as human demonstrations ship them
//! (DexMV's, `retarget::demo`). Little-endian `f4`, `f8`, `i4` and `i8` arrays in C order, format
//! versions 1–3; anything else (a pickled object array, Fortran order, big-endian data) is a
//! one-line error naming the file, the member and what was expected, as is a truncated file.

use std::collections::BTreeMap;
use std::io::Read;
use std::path::Path;

use anyhow::{Context, Result, anyhow, bail, ensure};

/// An array's values, in its element type.
#[derive(Clone, Debug, PartialEq)]
pub enum NpyData {
    F32(Vec<f32>),
    F64(Vec<f64>),
    I32(Vec<i32>),
    I64(Vec<i64>),
}

/// One array: its shape (C order, the last index fastest) and values.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    pub shape: Vec<usize>,
    pub data: NpyData,
}

impl NpyArray {
    /// The values as f64 (integers converted exactly up to 2⁵³).
    pub fn to_f64(&self) -> Vec<f64> {
        match &self.data {
            NpyData::F32(v) => v.iter().map(|&x| x as f64).collect(),
            NpyData::F64(v) => v.clone(),
            NpyData::I32(v) => v.iter().map(|&x| x as f64).collect(),
            NpyData::I64(v) => v.iter().map(|&x| x as f64).collect(),
        }
    }

    /// The element type's NumPy name (`float32`, …).
    pub fn dtype(&self) -> &'static str {
        match self.data {
            NpyData::F32(_) => "float32",
            NpyData::F64(_) => "float64",
            NpyData::I32(_) => "int32",
            NpyData::I64(_) => "int64",
        }
    }
}

/// The value of `key` in the header's dict text (`'descr': '<f4', 'fortran_order': False,
/// 'shape': (122, 61), }`): the text after `'key':` up to the next top-level comma or brace.
fn header_field<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let at = header.find(&format!("'{key}'"))? + key.len() + 2;
    let rest = header[at..].trim_start().strip_prefix(':')?.trim_start();
    let mut depth = 0;
    for (i, c) in rest.char_indices() {
        match c {
            '(' | '[' => depth += 1,
            ')' | ']' => depth -= 1,
            ',' | '}' if depth == 0 => return Some(rest[..i].trim()),
            _ => {}
        }
        if depth < 0 {
            return None;
        }
    }
    None
}

/// Parses one `.npy` file's bytes (`what` names it in errors).
pub fn parse_npy(bytes: &[u8], what: &str) -> Result<NpyArray> {
    ensure!(bytes.len() >= 10 && &bytes[..6] == b"\x93NUMPY", "{what}: not a .npy array (no \\x93NUMPY magic)");
    let (major, header_at, header_len) = match bytes[6] {
        1 => (1, 10, u16::from_le_bytes([bytes[8], bytes[9]]) as usize),
        2 | 3 => {
            ensure!(bytes.len() >= 12, "{what}: truncated .npy header");
            (bytes[6], 12, u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize)
        }
        v => bail!("{what}: .npy format version {v}, expected 1, 2 or 3"),
    };
    let data_at = header_at + header_len;
    ensure!(bytes.len() >= data_at, "{what}: truncated .npy header ({} bytes, {data_at} expected)", bytes.len());
    let header = std::str::from_utf8(&bytes[header_at..data_at]).map_err(|_| anyhow!("{what}: the .npy header is not text (format {major})"))?;
    let descr = header_field(header, "descr").ok_or_else(|| anyhow!("{what}: the .npy header has no 'descr'"))?.trim_matches(['\'', '"']);
    let fortran = header_field(header, "fortran_order").ok_or_else(|| anyhow!("{what}: the .npy header has no 'fortran_order'"))?;
    ensure!(fortran == "False", "{what}: a Fortran-order array; expected C order (numpy.ascontiguousarray before saving)");
    let shape_text = header_field(header, "shape").ok_or_else(|| anyhow!("{what}: the .npy header has no 'shape'"))?;
    let inner = shape_text.trim().strip_prefix('(').and_then(|s| s.strip_suffix(')')).ok_or_else(|| anyhow!("{what}: shape {shape_text:?} is not a tuple"))?;
    let shape = inner
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>().map_err(|_| anyhow!("{what}: shape {shape_text:?} has a dimension that is not a count")))
        .collect::<Result<Vec<usize>>>()?;
    let count = shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d)).ok_or_else(|| anyhow!("{what}: shape {shape_text:?} is too large"))?;
    let body = &bytes[data_at..];
    let need = |size: usize| -> Result<&[u8]> {
        let want = count.checked_mul(size).ok_or_else(|| anyhow!("{what}: shape {shape_text:?} is too large"))?;
        ensure!(body.len() >= want, "{what}: {} bytes of data for shape {shape_text:?} of {descr} ({want} expected)", body.len());
        Ok(&body[..want])
    };
    let data = match descr {
        "<f4" => NpyData::F32(need(4)?.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap_or_default())).collect()),
        "<f8" => NpyData::F64(need(8)?.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap_or_default())).collect()),
        "<i4" => NpyData::I32(need(4)?.chunks_exact(4).map(|c| i32::from_le_bytes(c.try_into().unwrap_or_default())).collect()),
        "<i8" => NpyData::I64(need(8)?.chunks_exact(8).map(|c| i64::from_le_bytes(c.try_into().unwrap_or_default())).collect()),
        other => bail!("{what}: element type '{other}'; expected little-endian float32, float64, int32 or int64 ('<f4', '<f8', '<i4', '<i8')"),
    };
    Ok(NpyArray { shape, data })
}

/// Every array of a `.npz` archive, by name (the member's name without `.npy`).
pub fn read_npz(path: &Path) -> Result<BTreeMap<String, NpyArray>> {
    let file = std::fs::File::open(path).with_context(|| format!("{}: cannot open", path.display()))?;
    let mut zip = zip::ZipArchive::new(file).map_err(|e| anyhow!("{}: not a .npz archive (zip): {e}", path.display()))?;
    let mut out = BTreeMap::new();
    for i in 0..zip.len() {
        let mut member = zip.by_index(i).map_err(|e| anyhow!("{}: member {i}: {e}", path.display()))?;
        let name = member.name().to_string();
        let Some(key) = name.strip_suffix(".npy") else { continue };
        let mut bytes = Vec::with_capacity(member.size() as usize);
        member.read_to_end(&mut bytes).map_err(|e| anyhow!("{}: member {name}: {e}", path.display()))?;
        let array = parse_npy(&bytes, &format!("{}: {name}", path.display()))?;
        out.insert(key.to_string(), array);
    }
    Ok(out)
}
