//! `[hand]` and `[wrist]`: the hand's URDF, its joint servos and contact friction, and the floating
//! wrist's PD controller (DESIGN §4).

use std::collections::BTreeMap;

use anyhow::Result;
use serde::{Deserialize, Serialize};

use super::Check;
use crate::hand::MeshApprox;

/// `[hand]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HandConfig {
    /// URDF of the hand, relative to the config file's directory.
    pub urdf: String,
    /// Fingertip frame names; empty = every link whose name ends in "tip".
    pub fingertips: Vec<String>,
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
