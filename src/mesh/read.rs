//! Reading mesh files: the vertices of binary and ASCII STL and of OBJ files.
//!
//! Only the vertex positions are read (every fit and hull in [`crate::mesh`] needs only those);
//! faces, normals and colours are skipped. An STL lists each triangle's three corners, so a
//! vertex shared by several triangles appears several times; the consumers handle duplicates.
//! Errors are one line saying what was expected; the caller adds the file name.

use glam::DVec3;

/// Vertices of a binary or ASCII STL file (three per triangle, duplicates kept).
///
/// A file is binary when its length is exactly `84 + 50 · n` bytes, `n` being the triangle count
/// in bytes 80..84 (little-endian); otherwise it must be UTF-8 text starting with `solid`, and
/// every `vertex x y z` is read.
pub fn parse_stl(b: &[u8]) -> Result<Vec<DVec3>, String> {
    if b.len() >= 84 {
        let n = u32::from_le_bytes([b[80], b[81], b[82], b[83]]) as u64;
        if 84 + 50 * n == b.len() as u64 {
            let f = |o: usize| f32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]) as f64;
            let mut v = Vec::with_capacity(3 * n as usize);
            for t in 0..n as usize {
                let base = 84 + 50 * t + 12; // skip the normal
                for k in 0..3 {
                    let o = base + 12 * k;
                    v.push(DVec3::new(f(o), f(o + 4), f(o + 8)));
                }
            }
            return check_vertices(v);
        }
    }
    let text = std::str::from_utf8(b).ok().filter(|t| t.trim_start().starts_with("solid")).ok_or_else(|| {
        "neither a binary STL (84-byte header, 50 bytes per triangle) nor an ASCII STL (starting with 'solid')".to_string()
    })?;
    let mut v = Vec::new();
    let mut it = text.split_whitespace();
    while let Some(tok) = it.next() {
        if tok.eq_ignore_ascii_case("vertex") {
            let mut c = [0.0; 3];
            for x in &mut c {
                *x = it
                    .next()
                    .and_then(|s| s.parse::<f64>().ok())
                    .ok_or_else(|| "an ASCII STL 'vertex' line needs three numbers".to_string())?;
            }
            v.push(DVec3::from_array(c));
        }
    }
    check_vertices(v)
}

/// Vertices (`v x y z` lines; extra numbers such as vertex colours are ignored) of an OBJ file.
pub fn parse_obj(b: &[u8]) -> Result<Vec<DVec3>, String> {
    let text = String::from_utf8_lossy(b);
    let mut v = Vec::new();
    for (ln, line) in text.lines().enumerate() {
        let mut it = line.split_whitespace();
        if it.next() != Some("v") {
            continue;
        }
        let mut c = [0.0; 3];
        for x in &mut c {
            *x = it
                .next()
                .and_then(|s| s.parse::<f64>().ok())
                .ok_or_else(|| format!("OBJ line {}: a 'v' line needs three numbers", ln + 1))?;
        }
        v.push(DVec3::from_array(c));
    }
    check_vertices(v)
}

/// `v` unchanged when every coordinate is finite; an error otherwise. (An empty list is not an
/// error here: the caller says what it needs.)
pub fn check_vertices(v: Vec<DVec3>) -> Result<Vec<DVec3>, String> {
    if v.iter().all(|p| p.is_finite()) {
        Ok(v)
    } else {
        Err("a vertex has a non-finite coordinate".to_string())
    }
}
