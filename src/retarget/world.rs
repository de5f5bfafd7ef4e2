//! The world frame of a demonstration given in a camera's frame: the table plane and gravity from
//! the object at rest, so that the demonstration lands on the simulator's table.
//!
//! 1. **Rest.** The frames from the first while the object stays within [`REST_RADIUS_M`] of its
//!    first position (a video estimate jitters by centimetres): the object stands on its support
//!    there. Its resting pose is the median position and the first frame's rotation.
//! 2. **Up.** The object rests on one of its faces: up is one of its six axis directions (±x, ±y,
//!    ±z of its model frame) as the resting rotation turns them — the one nearest the frame's
//!    expected up ([`DemoFrame::expected_up`]: for a camera, between its image's up (−y in OpenCV's
//!    and DexMV's convention) and back toward it (−z): a tabletop recording's camera is upright and
//!    looks down on the table; +z for a world frame). The report gives the hand's clearance over
//!    the table this implies (the lowest [`HAND_PERCENTILE`] of its keypoints): a negative one says
//!    the demonstration's hand and object estimates disagree (the contact clean-up re-grounds the
//!    hand). A user who knows better names the axis (`--object-up`, [`ObjectAxis`]).
//! 3. **Table.** The support plane is the lowest point of the object's collision shape along up,
//!    at rest.
//! 4. **World.** z along up; x the frame's x laid into the table plane; the origin on the table
//!    below the resting object, moved to the config's object position (x, y; the table at z = 0).

use anyhow::{Result, ensure};
use glam::{Mat3, Quat, Vec3};

use super::demo::HumanDemo;
use crate::geom::Pose;

/// The object is at rest while within this distance of its first position (m).
pub const REST_RADIUS_M: f32 = 0.04;
/// The low percentile of the hand keypoints' heights that picks up (a few outlying keypoints of a
/// video estimate may dip below the table).
pub const HAND_PERCENTILE: f32 = 0.01;
/// Fewest frames at rest for the estimate.
pub const MIN_REST_FRAMES: usize = 3;

/// The frame a demonstration's poses are given in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DemoFrame {
    /// A camera's (x right, y down, z forward: OpenCV's).
    Camera,
    /// A world frame with z up.
    World,
}

impl DemoFrame {
    /// The frame's expected up (unit), that picks among the object's six axis directions.
    pub fn expected_up(self) -> Vec3 {
        match self {
            DemoFrame::Camera => Vec3::new(0.0, -1.0, -1.0).normalize(),
            DemoFrame::World => Vec3::Z,
        }
    }

    /// From a demo's frame name: `camera` or `world`.
    pub fn parse(name: &str) -> Option<DemoFrame> {
        match name {
            "camera" => Some(DemoFrame::Camera),
            "world" => Some(DemoFrame::World),
            _ => None,
        }
    }
}

/// An axis direction of the object's model frame (`--object-up`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ObjectAxis {
    #[value(name = "+x")]
    PosX,
    #[value(name = "-x")]
    NegX,
    #[value(name = "+y")]
    PosY,
    #[value(name = "-y")]
    NegY,
    #[value(name = "+z")]
    PosZ,
    #[value(name = "-z")]
    NegZ,
}

impl ObjectAxis {
    /// Every axis direction, with the name the report gives it.
    pub const ALL: [(ObjectAxis, Vec3, &'static str); 6] = [
        (ObjectAxis::PosX, Vec3::X, "+x"),
        (ObjectAxis::NegX, Vec3::NEG_X, "-x"),
        (ObjectAxis::PosY, Vec3::Y, "+y"),
        (ObjectAxis::NegY, Vec3::NEG_Y, "-y"),
        (ObjectAxis::PosZ, Vec3::Z, "+z"),
        (ObjectAxis::NegZ, Vec3::NEG_Z, "-z"),
    ];
}

/// What was estimated, and the map from the demonstration's frame to the world.
#[derive(Clone, Debug)]
pub struct WorldEstimate {
    /// Frames at rest at the start.
    pub rest_frames: usize,
    /// Up, in the demonstration's frame.
    pub up_in_demo: Vec3,
    /// The object's axis (in its model frame) that points up at rest (`"+z"`, …).
    pub object_axis_up: String,
    /// Whether that axis was given (`--object-up`) rather than estimated.
    pub object_axis_given: bool,
    /// The lowest [`HAND_PERCENTILE`] of the hand's keypoints above the table (m; negative: the
    /// demonstration's hand passes through the table, its estimate disagreeing with the object's).
    pub hand_clearance_m: f32,
    /// The table plane's height along up in the demonstration's frame (m).
    pub table_height_in_demo: f32,
    /// demo → world: `p_w = rot · (p − anchor) + target`.
    pub rot: Quat,
    pub anchor: Vec3,
    pub target: Vec3,
}

impl WorldEstimate {
    /// A point of the demonstration's frame in the world.
    pub fn point(&self, p: Vec3) -> Vec3 {
        self.rot * (p - self.anchor) + self.target
    }

    /// A pose of the demonstration's frame in the world.
    pub fn pose(&self, p: &Pose) -> Pose {
        Pose { pos: self.point(p.pos), rot: (self.rot * p.rot).normalize() }
    }
}

/// The world frame of `demo` for an object whose collision shape has the points `shape` (its
/// model frame), put at `target_xy` on the table (z = 0); `object_up` names the object's axis that
/// points up at rest, else it is estimated.
pub fn estimate_world(demo: &HumanDemo, frame: DemoFrame, shape: &[Vec3], target_xy: [f32; 2], object_up: Option<ObjectAxis>) -> Result<WorldEstimate> {
    ensure!(!demo.object.is_empty(), "the demonstration has no object poses: no table to put it on");
    ensure!(!shape.is_empty(), "the object has no collision points");
    let first = demo.object[0].pos;
    let rest_frames = demo.object.iter().take_while(|p| (p.pos - first).length() <= REST_RADIUS_M).count();
    ensure!(
        rest_frames >= MIN_REST_FRAMES,
        "the object moves {:.0} mm by frame {rest_frames}: expected it at rest (within {:.0} mm) for its first {MIN_REST_FRAMES} frames, where the table is found",
        (demo.object[rest_frames.min(demo.object.len() - 1)].pos - first).length() * 1e3,
        REST_RADIUS_M * 1e3
    );
    let median = |axis: usize| {
        let mut v: Vec<f32> = demo.object[..rest_frames].iter().map(|p| p.pos[axis]).collect();
        v.sort_by(f32::total_cmp);
        v[v.len() / 2]
    };
    let rest_pos = Vec3::new(median(0), median(1), median(2));
    let rest_rot = demo.object[0].rot;
    let expected = frame.expected_up();
    // the table a candidate up implies, and the hand's low percentile above it
    let table_along = |up: Vec3| shape.iter().map(|v| (rest_pos + rest_rot * *v).dot(up)).fold(f32::INFINITY, f32::min);
    let hand_clearance = |up: Vec3| {
        let table = table_along(up);
        let mut h: Vec<f32> = demo.keypoints.iter().flatten().map(|k| k.dot(up) - table).collect();
        h.sort_by(f32::total_cmp);
        h[((h.len() as f32 * HAND_PERCENTILE) as usize).min(h.len() - 1)]
    };
    let axes: Vec<(ObjectAxis, Vec3, &str)> = ObjectAxis::ALL.iter().map(|&(a, v, n)| (a, (rest_rot * v).normalize(), n)).collect();
    let (up, name) = match object_up {
        Some(given) => axes.iter().find(|a| a.0 == given).map(|a| (a.1, a.2)).expect("every axis is listed"),
        None => axes.iter().map(|a| (a.1, a.2)).max_by(|a, b| a.0.dot(expected).total_cmp(&b.0.dot(expected))).expect("six axes"),
    };
    // the support plane: the lowest collision point along up
    let table = table_along(up);
    // z up; x the frame's x in the table plane (its z where x is nearly up)
    let mut x = Vec3::X - up * Vec3::X.dot(up);
    if x.length() < 0.1 {
        x = Vec3::Z - up * Vec3::Z.dot(up);
    }
    let x = x.normalize();
    let y = up.cross(x);
    let rot = Quat::from_mat3(&Mat3::from_cols(x, y, up).transpose()).normalize(); // rows x, y, up: demo → world
    let anchor = rest_pos - up * (rest_pos.dot(up) - table); // on the table below the resting object
    Ok(WorldEstimate {
        rest_frames,
        up_in_demo: up,
        object_axis_up: name.to_string(),
        object_axis_given: object_up.is_some(),
        hand_clearance_m: hand_clearance(up),
        table_height_in_demo: table,
        rot,
        anchor,
        target: Vec3::new(target_xy[0], target_xy[1], 0.0),
    })
}
