//! `[hand]` and `[wrist]`: the hand's URDF, its joint servos and contact friction, and the floating
//! wrist's PD controller (docs/design.md §4).

use std::collections::BTreeMap;
use std::fmt;

use anyhow::Result;
use serde::de::{self, MapAccess, Visitor, value::MapAccessDeserializer};
use serde::{Deserialize, Deserializer, Serialize};

use super::Check;

// Bounds shared with the URDF loader (the `hand` module checks a URDF's values against them; the config's
// overrides are checked against the same ones).
/// Largest |coordinate| (m) of an origin, and largest collision size or mesh extent (real: < 0.5 m).
pub const MAX_LENGTH_M: f64 = 10.0;
/// Largest effort limit (N·m) of a joint (real: ≤ 1000, SCHUNK SVH).
pub const MAX_EFFORT_NM: f64 = 1e5;
/// Largest velocity limit (rad/s) of a joint (real: ≤ 40).
pub const MAX_VELOCITY_RAD_S: f64 = 1e4;

/// What to do with a `<mesh>` collision element, which the simulator cannot represent: fit a
/// primitive to it (`mesh::fit`: the smallest of that kind, by volume, that contains every vertex,
/// in the mesh's principal axes or whatever frame is tighter; STL or OBJ files are read).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MeshApprox {
    /// A mesh collision is an error that names the link (the default).
    #[default]
    Error,
    /// The smallest oriented box around the mesh.
    Box,
    /// The smallest capsule around the mesh, or the smallest sphere where that is tighter.
    Capsule,
}

/// `[hand]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HandConfig {
    /// URDF of the hand, relative to the config file's directory.
    pub urdf: String,
    /// The fingertips, in the order the task uses them: each a frame name (`"link_3.0_tip"`, a
    /// URDF link, possibly merged by a fixed joint; the tip is its origin) or a point on a link
    /// (`{ link = "fingertip", offset = [0.0, -0.05, 0.015], name = "index_pad" }`). Empty = every
    /// URDF link whose name contains "tip" (case-insensitive), the most distal one per finger
    /// chain; a warning when their number differs from the number of finger chains.
    pub fingertips: Vec<FingertipSpec>,
    /// What to do with mesh collision geometry: "error", "box" or "capsule" (bounding-box approximations).
    pub mesh_approx: MeshApprox,
    /// Position gain of every finger joint servo (N·m/rad).
    pub kp: f32,
    /// Velocity gain of every finger joint servo (N·m·s/rad).
    pub kd: f32,
    /// Rotor inertia added to every finger joint (kg·m²).
    pub armature: f32,
    /// Per-joint overrides of `kp` (joint name -> N·m/rad).
    pub joint_kp: BTreeMap<String, f32>,
    /// Per-joint overrides of `kd` (joint name -> N·m·s/rad).
    pub joint_kd: BTreeMap<String, f32>,
    /// Coulomb friction coefficient of the hand's links.
    pub friction: f32,
    /// Initial joint positions (joint name -> rad); joints not named start at 0 clamped into their limits.
    pub init_joints: BTreeMap<String, f32>,
    /// Effort limits (N·m) that replace the URDF's: one number for every movable joint, or a table
    /// joint name -> N·m (the joints not named keep the URDF's). None (the default): the URDF's,
    /// where a missing or zero `effort` is an error.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub effort: Option<JointLimitOverride>,
    /// Velocity limits (rad/s) that replace the URDF's: one number for every movable joint, or a
    /// table joint name -> rad/s (the joints not named keep the URDF's). None (the default): the
    /// URDF's, where a missing or zero `velocity` is an error.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub velocity: Option<JointLimitOverride>,
}

/// One entry of `hand.fingertips`: a frame name, or a point on a link. Written as a string or as
/// a table `{ link, offset, name }` (deserialised by hand: serde's untagged enums answer a typo
/// with "data did not match any variant", naming neither the key nor what is expected).
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum FingertipSpec {
    /// The origin of a URDF link (frame), possibly one merged into its parent by a fixed joint; the
    /// tip is named after the frame.
    Frame(String),
    /// A point on a link, in that link's frame: `{ link = "...", offset = [x, y, z], name = "..." }`.
    Link(LinkTip),
}

/// A fingertip at a point on a link: `{ link = "...", offset = [x, y, z], name = "..." }`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkTip {
    /// The URDF link the tip is on (a link merged by a fixed joint resolves to the link it was
    /// merged into, its fixed-joint origins composed with `offset`).
    pub link: String,
    /// Position of the tip in the link's frame (m); [0, 0, 0] = the link's origin.
    #[serde(default)]
    pub offset: [f32; 3],
    /// The tip's name (observations, `task.hand.thumb`, references); default the link's name. Two
    /// tips on one link need distinct names.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
}

impl FingertipSpec {
    /// The tip's name: the frame's, or the table's `name` (default its link's).
    pub fn name(&self) -> &str {
        match self {
            FingertipSpec::Frame(f) => f,
            FingertipSpec::Link(t) => t.name.as_deref().unwrap_or(&t.link),
        }
    }
}

impl From<&str> for FingertipSpec {
    fn from(frame: &str) -> Self {
        FingertipSpec::Frame(frame.to_string())
    }
}

impl From<String> for FingertipSpec {
    fn from(frame: String) -> Self {
        FingertipSpec::Frame(frame)
    }
}

impl<'de> Deserialize<'de> for FingertipSpec {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = FingertipSpec;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a fingertip frame name (a string) or a table { link = \"<link>\", offset = [x, y, z], name = \"<tip>\" } (offset and name optional)")
            }
            fn visit_str<E: de::Error>(self, v: &str) -> std::result::Result<FingertipSpec, E> {
                Ok(FingertipSpec::Frame(v.to_string()))
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> std::result::Result<FingertipSpec, A::Error> {
                // the table's own errors (an unknown key, a missing `link`) keep serde's words
                LinkTip::deserialize(MapAccessDeserializer::new(map)).map(FingertipSpec::Link)
            }
        }
        d.deserialize_any(V)
    }
}

/// `hand.effort` / `hand.velocity`: limits that replace the URDF's. Written as a number or a
/// table (deserialised by hand, for the reason given at [`FingertipSpec`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum JointLimitOverride {
    /// One limit for every movable joint (mimic followers included).
    All(f32),
    /// Limits by joint name; the joints not named keep the URDF's.
    PerJoint(BTreeMap<String, f32>),
}

impl JointLimitOverride {
    /// The limit this override gives `joint`, if any.
    pub fn get(&self, joint: &str) -> Option<f32> {
        match self {
            JointLimitOverride::All(v) => Some(*v),
            JointLimitOverride::PerJoint(m) => m.get(joint).copied(),
        }
    }
}

impl<'de> Deserialize<'de> for JointLimitOverride {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = JointLimitOverride;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("one limit for every movable joint (a number) or a table of limits by joint name ({ joint = number, ... })")
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> std::result::Result<JointLimitOverride, E> {
                Ok(JointLimitOverride::All(v as f32))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> std::result::Result<JointLimitOverride, E> {
                Ok(JointLimitOverride::All(v as f32))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> std::result::Result<JointLimitOverride, E> {
                Ok(JointLimitOverride::All(v as f32))
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> std::result::Result<JointLimitOverride, A::Error> {
                BTreeMap::<String, f32>::deserialize(MapAccessDeserializer::new(map)).map(JointLimitOverride::PerJoint)
            }
        }
        d.deserialize_any(V)
    }
}

/// `[wrist]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WristConfig {
    /// Initial wrist position (m, world).
    pub init_pos: [f32; 3],
    /// Initial wrist orientation as roll, pitch, yaw (rad; R = Rz(yaw)·Ry(pitch)·Rx(roll)).
    pub init_rpy: [f32; 3],
    /// Translational stiffness of the wrist PD (N/m).
    pub kp_lin: f32,
    /// Translational damping of the wrist PD (N·s/m).
    pub kd_lin: f32,
    /// Force limit of the wrist PD (N).
    pub force_limit: f32,
    /// Rotational stiffness of the wrist PD (N·m/rad).
    pub kp_rot: f32,
    /// Rotational damping of the wrist PD (N·m·s/rad).
    pub kd_rot: f32,
    /// Torque limit of the wrist PD (N·m).
    pub torque_limit: f32,
    /// Mass added to the hand's own for the wrist's translation (kg): the arm's reflected mass.
    pub added_mass: f32,
    /// Inertia added to the hand's own for the wrist's rotation (kg·m²): the arm's reflected inertia.
    pub added_inertia: f32,
}

impl Default for HandConfig {
    fn default() -> Self {
        HandConfig {
            urdf: "hands/dexhand16.urdf".into(),
            fingertips: Vec::new(),
            mesh_approx: MeshApprox::Error,
            kp: 3.0,
            kd: 0.1,
            armature: 0.002,
            joint_kp: BTreeMap::new(),
            joint_kd: BTreeMap::new(),
            friction: 1.0,
            init_joints: BTreeMap::new(),
            effort: None,
            velocity: None,
        }
    }
}

impl Default for WristConfig {
    fn default() -> Self {
        WristConfig {
            init_pos: [0.0, 0.0, 0.15],
            init_rpy: [0.0, 0.0, 0.0],
            kp_lin: 2000.0,
            kd_lin: 100.0,
            force_limit: 100.0,
            kp_rot: 50.0,
            kd_rot: 2.0,
            torque_limit: 20.0,
            added_mass: 0.5,
            added_inertia: 0.01,
        }
    }
}

impl HandConfig {
    /// Checks `[hand]` (the URDF itself is checked when it loads).
    pub fn validate(&self, c: &Check) -> Result<()> {
        if self.urdf.trim().is_empty() {
            return Err(c.err("hand.urdf", "\"\"", "the path of a URDF file"));
        }
        c.non_neg("hand.kp", self.kp)?;
        c.non_neg("hand.kd", self.kd)?;
        c.in_range("hand.armature", self.armature, 1e-7, 10.0, "a rotor inertia in kg·m² in [1e-7, 10] (it keeps the finger joints stable)")?;
        for (k, v) in &self.joint_kp {
            c.non_neg(&format!("hand.joint_kp.{k}"), *v)?;
        }
        for (k, v) in &self.joint_kd {
            c.non_neg(&format!("hand.joint_kd.{k}"), *v)?;
        }
        c.non_neg("hand.friction", self.friction)?;
        for (k, v) in &self.init_joints {
            c.finite(&format!("hand.init_joints.{k}"), *v)?;
        }
        for (i, tip) in self.fingertips.iter().enumerate() {
            let key = format!("hand.fingertips[{i}]");
            match tip {
                FingertipSpec::Frame(f) if f.trim().is_empty() => {
                    return Err(c.err(&key, "\"\"", "a fingertip frame name or a table { link = \"<link>\", offset = [x, y, z] }"));
                }
                FingertipSpec::Frame(_) => {}
                FingertipSpec::Link(t) => {
                    if t.link.trim().is_empty() {
                        return Err(c.err(&format!("{key}.link"), "\"\"", "the name of a link of the hand"));
                    }
                    for (k, v) in t.offset.iter().enumerate() {
                        let m = MAX_LENGTH_M as f32;
                        c.in_range(&format!("{key}.offset[{k}]"), *v, -m, m, &format!("a finite offset within ±{m} m (the link's frame)"))?;
                    }
                    if t.name.as_deref().is_some_and(|n| n.trim().is_empty()) {
                        return Err(c.err(&format!("{key}.name"), "\"\"", "a non-empty fingertip name (leave it out for the link's name)"));
                    }
                }
            }
            if let Some(j) = self.fingertips[..i].iter().position(|o| o.name() == tip.name()) {
                return Err(c.err(
                    &key,
                    format!("{:?}", tip.name()),
                    &format!("a fingertip name distinct from hand.fingertips[{j}]'s (two tips on one link need distinct `name`s)"),
                ));
            }
        }
        for (what, limit, unit, max) in [("effort", &self.effort, "N·m", MAX_EFFORT_NM), ("velocity", &self.velocity, "rad/s", MAX_VELOCITY_RAD_S)] {
            let allowed = format!("a limit in (0, {max}] {unit}");
            let check = |key: &str, v: f32| if v.is_finite() && v > 0.0 && f64::from(v) <= max { Ok(()) } else { Err(c.err(key, v, &allowed)) };
            match limit {
                None => {}
                Some(JointLimitOverride::All(v)) => check(&format!("hand.{what}"), *v)?,
                Some(JointLimitOverride::PerJoint(m)) => {
                    for (k, v) in m {
                        check(&format!("hand.{what}.{k}"), *v)?;
                    }
                }
            }
        }
        Ok(())
    }
}

impl WristConfig {
    /// Checks `[wrist]`.
    pub fn validate(&self, c: &Check) -> Result<()> {
        for (i, v) in self.init_pos.iter().enumerate() {
            c.finite(&format!("wrist.init_pos[{i}]"), *v)?;
        }
        for (i, v) in self.init_rpy.iter().enumerate() {
            c.finite(&format!("wrist.init_rpy[{i}]"), *v)?;
        }
        for (key, v) in [
            ("wrist.kp_lin", self.kp_lin),
            ("wrist.kd_lin", self.kd_lin),
            ("wrist.force_limit", self.force_limit),
            ("wrist.kp_rot", self.kp_rot),
            ("wrist.kd_rot", self.kd_rot),
            ("wrist.torque_limit", self.torque_limit),
            ("wrist.added_mass", self.added_mass),
            ("wrist.added_inertia", self.added_inertia),
        ] {
            c.non_neg(key, v)?;
        }
        Ok(())
    }
}
