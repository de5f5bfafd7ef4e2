//! Objects from the config: primitives, meshes (OBJ pieces, STL files) and single-link URDFs.
//!
//! Every problem is a one-line error naming the config file and key, or the mesh/URDF file and
//! the piece, and what was expected.

use std::path::{Path, PathBuf};

use anyhow::{Result, anyhow};
use glam::{DMat3, DQuat, DVec3};

use super::{HullPiece, MAX_HULL_VERTICES, MAX_PIECES, MassSource, ObjectModel, ObjectPiece, PieceFit, object_inertia, shape_volume};
use crate::config::object::{DEFAULT_DENSITY, DEFAULT_PRIMITIVE_MASS};
use crate::config::{Config, ObjectItem, PieceKind};
use crate::geom::{ObjectShape, Pose};
use crate::mesh::fit::{FittedShape, PrimitiveKind, fit_tightest_with_hull};
use crate::mesh::hull::convex_hull;
use crate::mesh::mass::{MassProperties, combine, is_closed, mass_properties};
use crate::mesh::read::{TriangleMesh, parse_obj_pieces, parse_stl_mesh};

/// Largest mesh or URDF file read (bytes).
pub const MAX_OBJECT_FILE_BYTES: u64 = 64 << 20;

/// The run's objects: `[[object.set]]`'s entries in order, or the one `[object]` describes.
pub fn load_objects(cfg: &Config) -> Result<Vec<ObjectModel>> {
    let file = cfg.source.display().to_string();
    let items = cfg.object.items();
    let objects: Vec<ObjectModel> = items.iter().map(|(key, item)| load_object(item, key, &file, &|p| cfg.resolve(p))).collect::<Result<_>>()?;
    // references and eval reports name objects: each name once
    for (j, o) in objects.iter().enumerate() {
        if let Some(i) = objects[..j].iter().position(|p| p.name == o.name) {
            return Err(anyhow!("{file}: `{}` and `{}` are both named '{}': expected a unique `name` per object", items[i].0, items[j].0, o.name));
        }
    }
    Ok(objects)
}

/// What a mesh piece becomes (`pieces_as`, `hull_above_gap`).
struct PieceRule {
    /// The primitive kinds listed (the box alone when only the hull is).
    kinds: Vec<PrimitiveKind>,
    /// Whether the hull may replace the best primitive, and beyond which gap (m); −1 (every gap
    /// exceeds it: always the hull) when no primitive is listed.
    hull: Option<f64>,
}

impl PieceRule {
    fn of(item: &ObjectItem) -> PieceRule {
        let kinds: Vec<PrimitiveKind> = item.pieces_as.iter().filter_map(|k| k.primitive()).collect();
        let hull = item.pieces_as.contains(&PieceKind::Hull).then(|| if kinds.is_empty() { -1.0 } else { item.hull_above_gap as f64 });
        PieceRule { kinds: if kinds.is_empty() { vec![PrimitiveKind::Box] } else { kinds }, hull }
    }
}

/// A mesh or URDF piece before its mass is known: the collision primitive and the solid's mass
/// properties at unit density.
struct RawPiece {
    piece: ObjectPiece,
    mass: MassProperties,
}

/// One object. `key`: its key prefix in the config (`object`, `object.set[2]`), `file`: the
/// config file, `resolve`: a config path to a file path.
pub fn load_object(item: &ObjectItem, key: &str, file: &str, resolve: &dyn Fn(&str) -> PathBuf) -> Result<ObjectModel> {
    let kinds = PieceRule::of(item);
    if let Some(shape) = item.primitive() {
        let name = item.name.clone().unwrap_or_else(|| shape_name(&shape).to_string());
        let (mass, source) = match (item.mass, item.density) {
            (Some(m), _) => (m, MassSource::Given),
            (None, Some(d)) => (d * shape_volume(&shape), MassSource::Density),
            (None, None) => (DEFAULT_PRIMITIVE_MASS, MassSource::Default),
        };
        check_mass(mass, file, key)?;
        return Ok(ObjectModel::primitive(&name, shape, mass, source));
    }
    let (raw, sources, urdf_mass) = if let Some(m) = &item.mesh {
        let mut raw = Vec::new();
        let mut sources = Vec::new();
        for f in m.files() {
            let path = resolve(f);
            raw.extend(mesh_pieces(&path, item.mesh_scale, &kinds, &Pose::IDENTITY, &format!("{key}.mesh in {file}"))?);
            sources.push(path);
        }
        (raw, sources, None)
    } else {
        let u = item.urdf.as_deref().unwrap_or_default();
        let path = resolve(u);
        let (raw, mass) = urdf_pieces(&path, item.mesh_scale, &kinds, &format!("{key}.urdf in {file}"))?;
        (raw, vec![path], mass)
    };
    let first = sources.first().map(|p| p.display().to_string()).unwrap_or_default();
    if raw.is_empty() {
        return Err(anyhow!("{first}: no collision pieces ({key} in {file}); expected at least one closed mesh piece"));
    }
    if raw.len() > MAX_PIECES {
        return Err(anyhow!("{first}: {} collision pieces ({key} in {file}); expected at most {MAX_PIECES} (MAX_PIECES): merge pieces or decompose more coarsely", raw.len()));
    }
    let parts: Vec<MassProperties> = raw.iter().map(|r| r.mass).collect();
    let total = combine(&parts).map_err(|e| anyhow!("{first}: the pieces' mass properties: {e} ({key} in {file})"))?;
    let (mass, source) = match (item.mass, item.density, urdf_mass) {
        (Some(m), _, _) => (m, MassSource::Given),
        (None, Some(d), _) => (d * total.volume as f32, MassSource::Density),
        (None, None, Some(m)) => (m, MassSource::Urdf),
        (None, None, None) => (DEFAULT_DENSITY * total.volume as f32, MassSource::Default),
    };
    check_mass(mass, file, key)?;
    // principal moments at unit density, scaled to the mass: I = I₁ · m / V
    let (moments, axes) = total.principal();
    let axes = if axes.determinant() < 0.0 { DMat3::from_cols(axes.x_axis, axes.y_axis, -axes.z_axis) } else { axes };
    let name = item.name.clone().unwrap_or_else(|| {
        let stem = |p: &Path| p.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();
        // YCB-style layouts name the folder, not the file (006_mustard_bottle/collision.obj)
        let p = &sources[0];
        let s = stem(p);
        match p.parent() {
            Some(d) if ["collision", "collision_vhacd", "model", "mesh"].contains(&s.as_str()) && !stem(d).is_empty() => stem(d),
            _ => s,
        }
    });
    Ok(ObjectModel {
        name,
        sources,
        pieces: raw.into_iter().map(|r| r.piece).collect(),
        mass,
        mass_source: source,
        volume: total.volume as f32,
        com: total.center_of_mass.as_vec3(),
        inertia: (moments * (mass as f64 / total.volume)).as_vec3(),
        principal: DQuat::from_mat3(&axes).normalize().as_quat(),
    })
}

fn check_mass(mass: f32, file: &str, key: &str) -> Result<()> {
    if mass.is_finite() && (1e-4..=1e3).contains(&mass) {
        Ok(())
    } else {
        Err(anyhow!("{file}: `{key}`: the object's mass comes to {mass} kg; expected a mass in [1e-4, 1000] kg (set `mass` or `density`)"))
    }
}

fn shape_name(s: &ObjectShape) -> &'static str {
    match s {
        ObjectShape::Sphere { .. } => "sphere",
        ObjectShape::Box { .. } => "box",
        ObjectShape::Capsule { .. } => "capsule",
        ObjectShape::Cylinder { .. } => "cylinder",
    }
}

/// Reads a file of at most [`MAX_OBJECT_FILE_BYTES`]; `whence` says which key named it.
fn read_file(path: &Path, what: &str, whence: &str) -> Result<Vec<u8>> {
    let meta = std::fs::metadata(path).map_err(|e| anyhow!("{}: cannot read {what} ({whence}): {e}", path.display()))?;
    if meta.len() > MAX_OBJECT_FILE_BYTES {
        return Err(anyhow!("{}: {} bytes ({whence}); expected a {what} of at most {MAX_OBJECT_FILE_BYTES} bytes", path.display(), meta.len()));
    }
    std::fs::read(path).map_err(|e| anyhow!("{}: cannot read {what} ({whence}): {e}", path.display()))
}

/// The pieces of one mesh file, its vertices multiplied by `scale` and placed by `pose`: each OBJ
/// group/object is a piece, an STL file is one.
fn mesh_pieces(path: &Path, scale: f32, kinds: &PieceRule, pose: &Pose, whence: &str) -> Result<Vec<RawPiece>> {
    let f = path.display();
    let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    let bytes = read_file(path, "mesh", whence)?;
    let named: Vec<(String, TriangleMesh)> = match ext.as_str() {
        "obj" => parse_obj_pieces(&bytes).map_err(|e| anyhow!("{f}: {e} ({whence})"))?.into_iter().map(|p| (p.name, p.mesh)).collect(),
        "stl" => {
            let name = path.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default();
            vec![(name, parse_stl_mesh(&bytes).map_err(|e| anyhow!("{f}: {e} ({whence})"))?)]
        }
        _ => return Err(anyhow!("{f}: unsupported mesh format '.{ext}' ({whence}); expected a .obj or .stl file")),
    };
    if named.is_empty() {
        return Err(anyhow!("{f}: no faces ({whence}); expected a closed triangle mesh"));
    }
    // before fitting every piece of a file that has far too many
    if named.len() > MAX_PIECES {
        return Err(anyhow!("{f}: {} collision pieces ({whence}); expected at most {MAX_PIECES} (MAX_PIECES): merge pieces or decompose more coarsely", named.len()));
    }
    let (rot, pos) = (pose.rot.as_dquat(), pose.pos.as_dvec3());
    let mut out = Vec::with_capacity(named.len());
    for (name, mut mesh) in named {
        for v in &mut mesh.vertices {
            *v = pos + rot * (*v * scale as f64); // p' = t + R (s p)
        }
        out.push(piece_of_mesh(&name, &mesh, kinds).map_err(|e| anyhow!("{f}: piece '{name}': {e} ({whence})"))?);
    }
    Ok(out)
}

/// A mesh piece's fitted primitive and its solid's mass properties (unit density).
fn piece_of_mesh(name: &str, mesh: &TriangleMesh, kinds: &PieceRule) -> Result<RawPiece, String> {
    if !is_closed(mesh) {
        return Err("the piece is not closed (an edge is not used once each way by two triangles); expected a closed, consistently wound triangle mesh per piece".to_string());
    }
    let mass = mass_properties(mesh).map_err(|e| format!("{e}; expected a closed mesh that encloses a volume"))?;
    let hull = convex_hull(&mesh.vertices)?;
    let fit = fit_tightest_with_hull(&mesh.vertices, &hull, &kinds.kinds)?;
    let shape = match fit.shape {
        FittedShape::Sphere { radius } => ObjectShape::Sphere { radius: radius as f32 },
        FittedShape::Capsule { radius, half_length } => ObjectShape::Capsule { radius: radius as f32, half_length: half_length as f32 },
        FittedShape::Box { half_extents: h } => ObjectShape::Box { half_extents: h.as_vec3().to_array() },
        FittedShape::Cylinder { radius, half_length } => ObjectShape::Cylinder { radius: radius as f32, half_length: half_length as f32 },
    };
    let mut pose = Pose::new(fit.centre.as_vec3(), fit.rot.as_quat().normalize());
    // the hull where the primitive sticks out too far, and it is small enough to collide fast
    let use_hull = kinds.hull.is_some_and(|gap| fit.max_gap > gap) && hull.vertices.len() <= MAX_HULL_VERTICES;
    let hull = use_hull.then(|| {
        // the piece frame: at the vertices' mean, the mesh's axes
        let c = hull.vertices.iter().copied().sum::<DVec3>() / hull.vertices.len() as f64;
        pose = Pose::new(c.as_vec3(), glam::Quat::IDENTITY);
        let planes = hull.faces.iter().zip(&hull.normals).map(|(f, n)| (n.as_vec3(), n.dot(hull.vertices[f[0]] - c) as f32)).collect();
        HullPiece {
            vertices: hull.vertices.iter().map(|v| (*v - c).as_vec3()).collect(),
            faces: hull.faces.iter().map(|f| f.map(|i| i as u32)).collect(),
            planes,
        }
    });
    let fit = PieceFit { name: name.to_string(), vertices: mesh.vertices.len(), volume_ratio: fit.volume_ratio(), max_gap: fit.max_gap };
    Ok(RawPiece { piece: ObjectPiece { shape, pose, hull, fit: Some(fit) }, mass })
}

/// A primitive piece at `pose` and its solid's mass properties (unit density: mass = volume).
fn primitive_piece(shape: ObjectShape, pose: Pose) -> RawPiece {
    let volume = shape_volume(&shape) as f64;
    let diag = object_inertia(shape.code(), glam::Vec3::from(shape.size_params()), volume as f32).as_dvec3();
    let r = DMat3::from_quat(pose.rot.as_dquat());
    let inertia = r * DMat3::from_diagonal(diag) * r.transpose(); // R diag(I) Rᵀ
    RawPiece { piece: ObjectPiece { shape, pose, hull: None, fit: None }, mass: MassProperties { volume, center_of_mass: pose.pos.as_dvec3(), inertia } }
}

/// The pieces and the `<mass>` (if positive) of a single-link URDF: each `<collision>` is one mesh
/// (its pieces) or primitive, at its `<origin>`; mesh paths are relative to the URDF's directory.
fn urdf_pieces(path: &Path, scale: f32, kinds: &PieceRule, whence: &str) -> Result<(Vec<RawPiece>, Option<f32>)> {
    let f = path.display();
    let bytes = read_file(path, "URDF", whence)?;
    let text = String::from_utf8_lossy(&bytes);
    let robot = urdf_rs::read_from_string(&text).map_err(|e| {
        let msg = e.to_string().replace(['\n', '\r'], " ");
        anyhow!("{f}: cannot parse the object URDF ({whence}): {}", crate::text::clip(msg.trim(), 200))
    })?;
    if robot.links.len() != 1 {
        return Err(anyhow!("{f}: {} links ({whence}); expected a single-link object URDF", robot.links.len()));
    }
    let link = &robot.links[0];
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."));
    let mut out = Vec::new();
    for (i, c) in link.collision.iter().enumerate() {
        let o = &c.origin;
        let rot = (DQuat::from_rotation_z(o.rpy.0[2]) * DQuat::from_rotation_y(o.rpy.0[1]) * DQuat::from_rotation_x(o.rpy.0[0])).normalize();
        let pose = Pose::new(DVec3::from_array(o.xyz.0).as_vec3(), rot.as_quat());
        let s = scale;
        let bad = |what: &str| anyhow!("{f}: link '{}' <collision> {i}: {what} ({whence})", link.name);
        let shape = match c.geometry {
            urdf_rs::Geometry::Mesh { ref filename, scale: ms } => {
                let m = ms.map_or([1.0; 3], |v| v.0);
                if m[0] != m[1] || m[1] != m[2] || !(m[0] > 0.0 && m[0].is_finite()) {
                    return Err(bad(&format!("mesh scale {m:?}; expected one positive factor for all three axes")));
                }
                let name = filename.strip_prefix("file://").unwrap_or(filename);
                if name.starts_with("package://") {
                    return Err(bad(&format!("mesh '{filename}'; expected a path relative to the URDF's directory (package:// is not resolved for objects)")));
                }
                let p = Path::new(name);
                let mesh_path = if p.is_absolute() { p.to_path_buf() } else { dir.join(p) };
                let placed = Pose::new(pose.pos * s, pose.rot);
                out.extend(mesh_pieces(&mesh_path, s * m[0] as f32, kinds, &placed, whence)?);
                continue;
            }
            urdf_rs::Geometry::Box { size } => ObjectShape::Box { half_extents: [size.0[0], size.0[1], size.0[2]].map(|v| (v * 0.5) as f32 * s) },
            urdf_rs::Geometry::Sphere { radius } => ObjectShape::Sphere { radius: radius as f32 * s },
            urdf_rs::Geometry::Cylinder { radius, length } => ObjectShape::Cylinder { radius: radius as f32 * s, half_length: (length * 0.5) as f32 * s },
            urdf_rs::Geometry::Capsule { radius, length } => ObjectShape::Capsule { radius: radius as f32 * s, half_length: (length * 0.5) as f32 * s },
        };
        let sizes = shape.size_params();
        let positive = match shape {
            ObjectShape::Box { .. } => sizes.iter().all(|v| *v > 0.0),
            _ => sizes[0] > 0.0 && sizes[1] >= 0.0,
        };
        if !sizes.iter().all(|v| v.is_finite()) || !positive {
            return Err(bad(&format!("primitive sizes {sizes:?}; expected positive finite sizes")));
        }
        out.push(primitive_piece(shape, Pose::new(pose.pos * s, pose.rot)));
    }
    let m = link.inertial.mass.value;
    let urdf_mass = (m.is_finite() && m > 0.0).then_some(m as f32);
    Ok((out, urdf_mass))
}
