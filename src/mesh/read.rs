//! Reading mesh files: the vertices of binary and ASCII STL and of OBJ files, and their
//! triangles.
//!
//! [`parse_stl`] and [`parse_obj`] read only the vertex positions (every fit and hull in
//! [`crate::mesh`] needs only those); faces, normals and colours are skipped. An STL lists each
//! triangle's three corners, so a vertex shared by several triangles appears several times; the
//! consumers handle duplicates. [`parse_stl_mesh`] and [`parse_obj_pieces`] read the triangles
//! too, as [`TriangleMesh`]es with shared vertices (for mass properties and closedness:
//! [`crate::mesh::mass`]). Errors are one line saying what was expected; the caller adds the file
//! name.

use std::collections::HashMap;

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
        v.push(obj_position(it).map_err(|e| format!("OBJ line {}: {e}", ln + 1))?);
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

// ------------------------------------------------------------------------------ triangle meshes

/// A triangle mesh: shared vertices and triangles that index them.
///
/// A closed mesh wound counter-clockwise seen from outside (outward normals by the right-hand
/// rule) encloses a solid; [`crate::mesh::mass`] integrates over it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriangleMesh {
    /// Vertex positions (units of the file; metres in dextrain).
    pub vertices: Vec<DVec3>,
    /// Triangles as three indices into `vertices`, in the file's winding order.
    pub triangles: Vec<[u32; 3]>,
}

/// The triangles of a binary or ASCII STL file (see [`parse_stl`]: every three consecutive
/// vertices are one triangle), with exactly equal vertices welded into one so that neighbouring
/// triangles share their edges (−0.0 and 0.0 count as equal; nothing is welded by distance).
pub fn parse_stl_mesh(b: &[u8]) -> Result<TriangleMesh, String> {
    let corners = parse_stl(b)?; // 3 per triangle; parse_stl reads exactly 3 per facet in binary
    if corners.len() % 3 != 0 {
        return Err(format!("an STL needs three vertices per triangle, found {} vertices", corners.len()));
    }
    let mut mesh = TriangleMesh::default();
    let mut index: HashMap<[u64; 3], u32> = HashMap::new();
    for tri in corners.chunks_exact(3) {
        let mut t = [0u32; 3];
        for (k, p) in tri.iter().enumerate() {
            // + 0.0 turns −0.0 into 0.0, the only two different bit patterns of equal finite values
            let key = [(p.x + 0.0).to_bits(), (p.y + 0.0).to_bits(), (p.z + 0.0).to_bits()];
            t[k] = match index.get(&key) {
                Some(&i) => i,
                None => {
                    let i = u32::try_from(mesh.vertices.len()).map_err(|_| "an STL with more than 2^32 distinct vertices".to_string())?;
                    mesh.vertices.push(*p);
                    index.insert(key, i);
                    i
                }
            };
        }
        mesh.triangles.push(t);
    }
    Ok(mesh)
}

/// One named piece of an OBJ file: the faces of one `o` object or `g` group.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshPiece {
    /// The name after `o` or `g` ("default" for faces before any `o`/`g` line, or a nameless one).
    pub name: String,
    /// The piece's triangles, with only the vertices they use (in order of first use).
    pub mesh: TriangleMesh,
}

/// The pieces of an OBJ file: every `o NAME` or `g NAME` line starts a new piece, faces before
/// any of them go into a piece named "default", and a piece without faces is dropped.
///
/// Read: `v x y z` (extra numbers such as a `w` or vertex colours are ignored) and `f` lines,
/// whose corners are `i`, `i/t`, `i//n` or `i/t/n` (only the vertex index `i` is used; 1-based,
/// or negative: −1 is the last vertex read so far). A polygon of more than three corners is
/// split into a fan (0, k, k + 1). Everything after a `#` and every other line (`vt`, `vn`,
/// `usemtl`, `s`, `l`, ...) is skipped. Errors are one line naming the OBJ line and what was
/// expected there.
pub fn parse_obj_pieces(b: &[u8]) -> Result<Vec<MeshPiece>, String> {
    let text = String::from_utf8_lossy(b);
    let mut vertices: Vec<DVec3> = Vec::new();
    let mut pieces = Vec::new();
    let mut name = "default".to_string();
    let mut faces: Vec<[usize; 3]> = Vec::new(); // the current piece's triangles, file-wide indices
    for (ln, line) in text.lines().enumerate() {
        let at = |what: String| format!("OBJ line {}: {what}", ln + 1);
        let line = line.split('#').next().unwrap_or("");
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => vertices.push(obj_vertex(it).map_err(at)?),
            Some("f") => {
                let corners = it.map(|c| obj_corner(c, vertices.len())).collect::<Result<Vec<usize>, String>>().map_err(at)?;
                if corners.len() < 3 {
                    return Err(at(format!("a face needs at least 3 corners, found {}", corners.len())));
                }
                faces.extend((1..corners.len() - 1).map(|k| [corners[0], corners[k], corners[k + 1]])); // fan
            }
            Some("o" | "g") => {
                pieces.extend(obj_piece(std::mem::take(&mut name), std::mem::take(&mut faces), &vertices));
                let rest: Vec<&str> = it.collect();
                name = if rest.is_empty() { "default".to_string() } else { rest.join(" ") };
            }
            _ => {}
        }
    }
    pieces.extend(obj_piece(name, faces, &vertices));
    Ok(pieces)
}

/// The position of a `v` line (the words after `v`): three finite numbers; more are ignored.
fn obj_vertex<'a>(words: impl Iterator<Item = &'a str>) -> Result<DVec3, String> {
    let p = obj_position(words)?;
    if !p.is_finite() {
        return Err(format!("a vertex has a non-finite coordinate ({p})"));
    }
    Ok(p)
}

/// The first three numbers of a `v` line (the words after `v`), finite or not.
fn obj_position<'a>(mut words: impl Iterator<Item = &'a str>) -> Result<DVec3, String> {
    let mut c = [0.0; 3];
    for x in &mut c {
        *x = words.next().and_then(|s| s.parse::<f64>().ok()).ok_or_else(|| "a 'v' line needs three numbers".to_string())?;
    }
    Ok(DVec3::from_array(c))
}

/// The 0-based vertex index of one face corner (`i`, `i/t`, `i//n`, `i/t/n`), `n` vertices having
/// been read so far: `i` is 1-based, or negative and counted back from the last vertex.
fn obj_corner(corner: &str, n: usize) -> Result<usize, String> {
    let word = corner.split('/').next().unwrap_or("");
    let i: i64 = word.parse().map_err(|_| format!("a face corner must start with a vertex index (a nonzero integer), found '{corner}'"))?;
    let index = if i > 0 { Some(i - 1) } else { (n as i64).checked_add(i) }; // −1 → n − 1
    match index {
        _ if i == 0 => Err("face index 0 is invalid (OBJ indices start at 1; negative ones count back from the last vertex)".to_string()),
        Some(k) if (0..n as i64).contains(&k) => Ok(k as usize),
        _ => Err(format!("face index {i} is out of range (the file has {n} vertices so far)")),
    }
}

/// A piece of the given triangles (file-wide vertex indices) with only the vertices they use,
/// re-indexed in order of first use; `None` without triangles.
fn obj_piece(name: String, faces: Vec<[usize; 3]>, vertices: &[DVec3]) -> Option<MeshPiece> {
    if faces.is_empty() {
        return None;
    }
    let mut local: HashMap<usize, u32> = HashMap::new();
    let mut mesh = TriangleMesh::default();
    for f in faces {
        let t = f.map(|g| {
            *local.entry(g).or_insert_with(|| {
                mesh.vertices.push(vertices[g]);
                (mesh.vertices.len() - 1) as u32
            })
        });
        mesh.triangles.push(t);
    }
    Some(MeshPiece { name, mesh })
}
