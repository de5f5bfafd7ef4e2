//! `[object]`: the manipulated object (or the set of objects each env draws one from) and where it
//! starts on the table. What each entry becomes (pieces, mass properties) is the `object` module's job.

use anyhow::Result;
use serde::{Deserialize, Serialize};

use super::Check;
use crate::geom::ObjectShape;
use crate::mesh::fit::PrimitiveKind;

/// Most objects in one run (`[[object.set]]` entries).
pub const MAX_OBJECTS: usize = 64;

/// Mass (kg) of a primitive object that gives neither `mass` nor `density`.
pub const DEFAULT_PRIMITIVE_MASS: f32 = 0.1;
/// Density (kg/m³) of a mesh object that gives neither `mass` nor `density` (nor a URDF mass):
/// water's, as dex-hand-teleop loads its YCB hulls.
pub const DEFAULT_DENSITY: f32 = 1000.0;

/// What a mesh piece may become, in the TOML: the primitives `"sphere"`, `"capsule"`, `"box"`,
/// `"cylinder"`, and `"hull"` (the piece's own convex hull, where no primitive fits it within
/// `hull_above_gap`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PieceKind {
    Sphere,
    Capsule,
    Box,
    Cylinder,
    Hull,
}

impl PieceKind {
    /// The fitter's kind (`None` for the hull).
    pub fn primitive(self) -> Option<PrimitiveKind> {
        match self {
            PieceKind::Sphere => Some(PrimitiveKind::Sphere),
            PieceKind::Capsule => Some(PrimitiveKind::Capsule),
            PieceKind::Box => Some(PrimitiveKind::Box),
            PieceKind::Cylinder => Some(PrimitiveKind::Cylinder),
            PieceKind::Hull => None,
        }
    }
}

/// One mesh file or a list of them (each file's OBJ groups/objects are separate pieces).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum MeshFiles {
    /// `mesh = "bottle.obj"`.
    One(String),
    /// `mesh = ["body.stl", "cap.stl"]`.
    Many(Vec<String>),
}

impl MeshFiles {
    /// The files, in order.
    pub fn files(&self) -> Vec<&str> {
        match self {
            MeshFiles::One(f) => vec![f.as_str()],
            MeshFiles::Many(v) => v.iter().map(String::as_str).collect(),
        }
    }
}

/// The geometry and mass of one object: exactly one of `shape`, `mesh`, `urdf` (none = the default
/// 5 cm cube), and at most one of `mass`, `density`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObjectItem {
    /// Name in eval reports and `dextrain check` (default: the mesh or URDF file's stem, or the
    /// shape's type).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// A primitive: `{ type = "box", half_extents = [..] }`, `{ type = "sphere", radius = .. }`,
    /// `{ type = "capsule", radius = .., half_length = .. }` or `{ type = "cylinder", radius = .., half_length = .. }`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shape: Option<ObjectShape>,
    /// A closed triangle mesh (OBJ or STL), or a list of them, relative to the config file: each
    /// OBJ group/object (`g`/`o`) and each file is one convex piece. The mesh frame is the object's
    /// frame (its pose in references and recordings).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mesh: Option<MeshFiles>,
    /// A single-link URDF (e.g. pybullet-object-models' `model.urdf`), relative to the config file:
    /// its `<collision>` meshes and primitives are the pieces, its `<mass>` the mass (unless `mass`
    /// or `density` is set); its inertia block is not used (often a placeholder).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub urdf: Option<String>,
    /// Mass (kg). Unset: from `density`, else the URDF's mass, else 0.1 kg for a primitive and
    /// 1000 kg/m³ × volume for a mesh.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mass: Option<f32>,
    /// Density (kg/m³); the mass is density × the pieces' volume.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub density: Option<f32>,
    /// Factor applied to the mesh's coordinates (0.001 for a mesh in millimetres).
    pub mesh_scale: f32,
    /// What a mesh piece may become: the smallest (by volume) of the primitives listed that
    /// contains all its vertices, or with `"hull"` listed, its convex hull where that primitive
    /// sticks out of the hull by more than `hull_above_gap` (or where no primitive is listed).
    pub pieces_as: Vec<PieceKind>,
    /// How far (m) a piece's best primitive may stick out of the piece's convex hull before the
    /// hull is used instead (with `"hull"` in `pieces_as`).
    pub hull_above_gap: f32,
}

impl Default for ObjectItem {
    fn default() -> Self {
        ObjectItem {
            name: None,
            shape: None,
            mesh: None,
            urdf: None,
            mass: None,
            density: None,
            mesh_scale: 1.0,
            pieces_as: vec![PieceKind::Box, PieceKind::Cylinder, PieceKind::Capsule, PieceKind::Sphere, PieceKind::Hull],
            hull_above_gap: 0.003,
        }
    }
}

/// The default object: a 5 cm cube.
pub const DEFAULT_SHAPE: ObjectShape = ObjectShape::Box { half_extents: [0.025, 0.025, 0.025] };

impl ObjectItem {
    /// The primitive shape, if this item is one (the default cube when no geometry is given).
    pub fn primitive(&self) -> Option<ObjectShape> {
        if self.mesh.is_some() || self.urdf.is_some() { None } else { Some(self.shape.unwrap_or(DEFAULT_SHAPE)) }
    }

    /// Checks one object; `key` is its key prefix (`object` or `object.set[i]`).
    pub fn validate(&self, c: &Check, key: &str) -> Result<()> {
        let given = [self.shape.is_some(), self.mesh.is_some(), self.urdf.is_some()].iter().filter(|b| **b).count();
        if given > 1 {
            return Err(c.msg(format!("`{key}` sets more than one of `shape`, `mesh`, `urdf`: expected exactly one way to give the object's geometry")));
        }
        if self.mass.is_some() && self.density.is_some() {
            return Err(c.msg(format!("`{key}` sets both `mass` and `density`: expected at most one of them")));
        }
        if let Some(shape) = self.shape {
            match shape {
                ObjectShape::Sphere { radius } => c.in_range(&format!("{key}.shape.radius"), radius, 1e-4, 10.0, "a radius in m in [1e-4, 10]")?,
                ObjectShape::Box { half_extents } => {
                    for (i, v) in half_extents.iter().enumerate() {
                        c.in_range(&format!("{key}.shape.half_extents[{i}]"), *v, 1e-4, 10.0, "a half extent in m in [1e-4, 10]")?;
                    }
                }
                ObjectShape::Capsule { radius, half_length } | ObjectShape::Cylinder { radius, half_length } => {
                    c.in_range(&format!("{key}.shape.radius"), radius, 1e-4, 10.0, "a radius in m in [1e-4, 10]")?;
                    c.in_range(&format!("{key}.shape.half_length"), half_length, 0.0, 10.0, "a half length in m in [0, 10]")?;
                }
            }
        }
        if let Some(m) = &self.mesh {
            let files = m.files();
            if files.is_empty() || files.iter().any(|f| f.trim().is_empty()) {
                return Err(c.err(&format!("{key}.mesh"), format!("{files:?}"), "a mesh file (.obj or .stl) or a non-empty list of them"));
            }
        }
        if let Some(u) = &self.urdf
            && u.trim().is_empty()
        {
            return Err(c.err(&format!("{key}.urdf"), "\"\"", "the path of a single-link URDF file"));
        }
        if let Some(m) = self.mass {
            c.in_range(&format!("{key}.mass"), m, 1e-4, 1e3, "a mass in kg in [1e-4, 1000]")?;
        }
        if let Some(d) = self.density {
            c.in_range(&format!("{key}.density"), d, 1.0, 1e5, "a density in kg/m³ in [1, 1e5]")?;
        }
        c.in_range(&format!("{key}.mesh_scale"), self.mesh_scale, 1e-6, 1e3, "a factor in [1e-6, 1000]")?;
        if self.pieces_as.is_empty() {
            return Err(c.err(&format!("{key}.pieces_as"), "[]", "a non-empty list of \"sphere\", \"capsule\", \"box\", \"cylinder\", \"hull\""));
        }
        c.in_range(&format!("{key}.hull_above_gap"), self.hull_above_gap, 0.0, 1.0, "a distance in m in [0, 1]")?;
        Ok(())
    }

    /// The item with its file paths made absolute by `absolute` (for a run's saved config).
    pub fn with_paths(&self, absolute: impl Fn(&str) -> String) -> ObjectItem {
        let mut out = self.clone();
        out.mesh = self.mesh.as_ref().map(|m| match m {
            MeshFiles::One(f) => MeshFiles::One(absolute(f)),
            MeshFiles::Many(v) => MeshFiles::Many(v.iter().map(|f| absolute(f)).collect()),
        });
        out.urdf = self.urdf.as_deref().map(absolute);
        out
    }
}

/// `[object]`: the object's geometry and mass (the keys of [`ObjectItem`], for one object) or a set
/// of objects (`[[object.set]]`, each env draws one at every reset), and the settings they share.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObjectConfig {
    /// Name of the single object (see [`ObjectItem::name`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Primitive shape of the single object (see [`ObjectItem::shape`]); default a 5 cm cube.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shape: Option<ObjectShape>,
    /// Mesh file(s) of the single object (see [`ObjectItem::mesh`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mesh: Option<MeshFiles>,
    /// Single-link URDF of the single object (see [`ObjectItem::urdf`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub urdf: Option<String>,
    /// Mass (kg) of the single object (see [`ObjectItem::mass`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mass: Option<f32>,
    /// Density (kg/m³) of the single object (see [`ObjectItem::density`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub density: Option<f32>,
    /// Mesh coordinate factor of the single object (see [`ObjectItem::mesh_scale`]; unset = 1).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mesh_scale: Option<f32>,
    /// What the single object's mesh pieces may become (see [`ObjectItem::pieces_as`]; unset =
    /// every primitive and the hull).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pieces_as: Option<Vec<PieceKind>>,
    /// The single object's gap above which a hull replaces a primitive (see
    /// [`ObjectItem::hull_above_gap`]; unset = 3 mm).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hull_above_gap: Option<f32>,
    /// Several objects, each env drawing one at every reset (uniformly, from a hash of the seed,
    /// the env and the episode). When set, the single-object keys above must be unset.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub set: Vec<ObjectItem>,
    /// Coulomb friction coefficient (combined with the other body's by averaging).
    pub friction: f32,
    /// Coefficient of restitution of the object's contacts, in [0, 1).
    pub restitution: f32,
    /// Initial x, y (m) of the object frame's origin; the object starts resting on the table in
    /// its mesh's orientation turned by the yaw.
    pub init_xy: [f32; 2],
    /// Initial rotation about z (rad).
    pub init_yaw: f32,
    /// Half widths (m) of the uniform noise added to the initial x and y at each reset.
    pub xy_noise: [f32; 2],
    /// Half width (rad) of the uniform noise added to the initial yaw at each reset.
    pub yaw_noise: f32,
}

impl Default for ObjectConfig {
    fn default() -> Self {
        ObjectConfig {
            name: None,
            shape: None,
            mesh: None,
            urdf: None,
            mass: None,
            density: None,
            mesh_scale: None,
            pieces_as: None,
            hull_above_gap: None,
            set: Vec::new(),
            friction: 1.0,
            restitution: 0.0,
            init_xy: [0.0, 0.0],
            init_yaw: 0.0,
            xy_noise: [0.0, 0.0],
            yaw_noise: 0.0,
        }
    }
}

impl ObjectConfig {
    /// The single object's keys as an item.
    fn single(&self) -> ObjectItem {
        let d = ObjectItem::default();
        ObjectItem {
            name: self.name.clone(),
            shape: self.shape,
            mesh: self.mesh.clone(),
            urdf: self.urdf.clone(),
            mass: self.mass,
            density: self.density,
            mesh_scale: self.mesh_scale.unwrap_or(d.mesh_scale),
            pieces_as: self.pieces_as.clone().unwrap_or(d.pieces_as),
            hull_above_gap: self.hull_above_gap.unwrap_or(d.hull_above_gap),
        }
    }

    /// The objects of the run with their key prefixes: `[[object.set]]`'s entries, or the one
    /// object the `[object]` keys describe.
    pub fn items(&self) -> Vec<(String, ObjectItem)> {
        if self.set.is_empty() {
            vec![("object".to_string(), self.single())]
        } else {
            self.set.iter().enumerate().map(|(i, it)| (format!("object.set[{i}]"), it.clone())).collect()
        }
    }

    /// Checks `[object]`.
    pub fn validate(&self, c: &Check) -> Result<()> {
        if !self.set.is_empty() {
            let o = self;
            if o.name.is_some() || o.shape.is_some() || o.mesh.is_some() || o.urdf.is_some() || o.mass.is_some() || o.density.is_some()
                || o.mesh_scale.is_some() || o.pieces_as.is_some() || o.hull_above_gap.is_some()
            {
                return Err(c.msg("`[object]` sets an object's keys (name, shape, mesh, urdf, mass, density, mesh_scale, pieces_as, hull_above_gap) and `[[object.set]]`: expected the keys inside each `[[object.set]]` entry"));
            }
            if self.set.len() > MAX_OBJECTS {
                return Err(c.err("object.set", format!("{} entries", self.set.len()), &format!("at most {MAX_OBJECTS} objects")));
            }
        }
        for (key, item) in self.items() {
            item.validate(c, &key)?;
        }
        c.non_neg("object.friction", self.friction)?;
        c.unit_interval("object.restitution", self.restitution)?;
        for (i, v) in self.init_xy.iter().enumerate() {
            c.finite(&format!("object.init_xy[{i}]"), *v)?;
        }
        c.finite("object.init_yaw", self.init_yaw)?;
        for (i, v) in self.xy_noise.iter().enumerate() {
            c.non_neg(&format!("object.xy_noise[{i}]"), *v)?;
        }
        c.non_neg("object.yaw_noise", self.yaw_noise)
    }

    /// `[object]` with every mesh and URDF path made absolute by `absolute`, and the single
    /// object's piece settings written out (a run's saved config: it loads the same pieces later,
    /// whatever the defaults then).
    pub fn with_paths(&self, absolute: impl Fn(&str) -> String) -> ObjectConfig {
        let mut out = self.clone();
        let single = self.single();
        if self.set.is_empty() {
            (out.mesh_scale, out.pieces_as, out.hull_above_gap) = (Some(single.mesh_scale), Some(single.pieces_as.clone()), Some(single.hull_above_gap));
        }
        out.mesh = single.with_paths(&absolute).mesh;
        out.urdf = self.urdf.as_deref().map(&absolute);
        out.set = self.set.iter().map(|it| it.with_paths(&absolute)).collect();
        out
    }
}
