//! The JSON message types a recording writes (dextrain's own and Foxglove's).

use super::*;

#[derive(Serialize, Clone, Copy, Debug)]
pub(super) struct FgTime {
    pub(super) sec: u32,
    pub(super) nsec: u32,
}

impl FgTime {
    pub(super) fn from_ns(ns: u64) -> Self {
        FgTime { sec: (ns / 1_000_000_000).min(u32::MAX as u64) as u32, nsec: (ns % 1_000_000_000) as u32 }
    }
}

#[derive(Serialize, Clone, Copy, Debug)]
pub(super) struct FgDuration {
    pub(super) sec: i32,
    pub(super) nsec: u32,
}

#[derive(Serialize, Clone, Copy, Debug)]
pub(super) struct FgVec3 {
    pub(super) x: f32,
    pub(super) y: f32,
    pub(super) z: f32,
}

#[derive(Serialize, Clone, Copy, Debug)]
pub(super) struct FgQuat {
    pub(super) x: f32,
    pub(super) y: f32,
    pub(super) z: f32,
    pub(super) w: f32,
}

#[derive(Serialize, Clone, Copy, Debug)]
pub(super) struct FgPose {
    pub(super) position: FgVec3,
    pub(super) orientation: FgQuat,
}

#[derive(Serialize, Clone, Copy, Debug)]
pub(super) struct FgColor {
    pub(super) r: f32,
    pub(super) g: f32,
    pub(super) b: f32,
    pub(super) a: f32,
}

/// A cube or sphere primitive.
#[derive(Serialize, Clone, Debug)]
pub(super) struct FgShape {
    pub(super) pose: FgPose,
    pub(super) size: FgVec3,
    pub(super) color: FgColor,
}

#[derive(Serialize, Clone, Debug)]
pub(super) struct FgCylinder {
    pub(super) pose: FgPose,
    pub(super) size: FgVec3,
    pub(super) bottom_scale: f32,
    pub(super) top_scale: f32,
    pub(super) color: FgColor,
}

#[derive(Serialize, Clone, Debug)]
pub(super) struct FgArrow {
    pub(super) pose: FgPose,
    pub(super) shaft_length: f32,
    pub(super) shaft_diameter: f32,
    pub(super) head_length: f32,
    pub(super) head_diameter: f32,
    pub(super) color: FgColor,
}

#[derive(Serialize, Clone, Debug)]
pub(super) struct FgKeyValue {
    pub(super) key: String,
    pub(super) value: String,
}

#[derive(Serialize, Clone, Debug)]
pub(super) struct FgEntity {
    pub(super) timestamp: FgTime,
    pub(super) frame_id: String,
    pub(super) id: String,
    pub(super) lifetime: FgDuration,
    pub(super) frame_locked: bool,
    pub(super) metadata: Vec<FgKeyValue>,
    pub(super) arrows: Vec<FgArrow>,
    pub(super) cubes: Vec<FgShape>,
    pub(super) spheres: Vec<FgShape>,
    pub(super) cylinders: Vec<FgCylinder>,
    pub(super) lines: Vec<Value>,
    pub(super) triangles: Vec<Value>,
    pub(super) texts: Vec<Value>,
    pub(super) models: Vec<Value>,
}

#[derive(Serialize, Debug)]
pub(super) struct FgDeletion {
    pub(super) timestamp: FgTime,
    /// 0 = MATCHING_ID, 1 = ALL.
    #[serde(rename = "type")]
    pub(super) kind: u32,
    pub(super) id: String,
}

#[derive(Serialize, Debug, Default)]
pub(super) struct FgSceneUpdate {
    pub(super) deletions: Vec<FgDeletion>,
    pub(super) entities: Vec<FgEntity>,
}

#[derive(Serialize, Debug)]
pub(super) struct FgTransform {
    pub(super) timestamp: FgTime,
    pub(super) parent_frame_id: String,
    pub(super) child_frame_id: String,
    pub(super) translation: FgVec3,
    pub(super) rotation: FgQuat,
}

impl FgTransform {
    pub(super) fn new(timestamp: FgTime, parent: &str, child: &str, pose: &Pose) -> Self {
        FgTransform {
            timestamp,
            parent_frame_id: parent.to_string(),
            child_frame_id: child.to_string(),
            translation: fv(pose.pos),
            rotation: fq(pose.rot),
        }
    }
}

#[derive(Serialize, Debug)]
pub(super) struct FgFrameTransforms<'a> {
    pub(super) transforms: &'a [FgTransform],
}

/// A vector for Foxglove messages: non-finite components become 0.
pub(super) fn fv(v: Vec3) -> FgVec3 {
    let c = |x: f32| if x.is_finite() { x } else { 0.0 };
    FgVec3 { x: c(v.x), y: c(v.y), z: c(v.z) }
}

/// A rotation for Foxglove messages: normalized, the identity if not finite or zero.
pub(super) fn fq(q: Quat) -> FgQuat {
    let n = q.length();
    if q.is_finite() && n > 1e-12 {
        let q = q / n;
        FgQuat { x: q.x, y: q.y, z: q.z, w: q.w }
    } else {
        FgQuat { x: 0.0, y: 0.0, z: 0.0, w: 1.0 }
    }
}

impl From<&Pose> for FgPose {
    fn from(p: &Pose) -> Self {
        FgPose { position: fv(p.pos), orientation: fq(p.rot) }
    }
}

#[derive(Serialize, Debug)]
pub(super) struct HandStateMsg<'a> {
    pub(super) timestamp: FgTime,
    pub(super) t: f64,
    pub(super) joint_names: &'a [String],
    pub(super) position: &'a [f32],
    pub(super) velocity: &'a [f32],
    pub(super) target: &'a [f32],
}

#[derive(Serialize, Debug)]
pub(super) struct PoseMsg {
    pub(super) x: f32,
    pub(super) y: f32,
    pub(super) z: f32,
    pub(super) qx: f32,
    pub(super) qy: f32,
    pub(super) qz: f32,
    pub(super) qw: f32,
}

impl From<&Pose> for PoseMsg {
    fn from(p: &Pose) -> Self {
        PoseMsg { x: p.pos.x, y: p.pos.y, z: p.pos.z, qx: p.rot.x, qy: p.rot.y, qz: p.rot.z, qw: p.rot.w }
    }
}

#[derive(Serialize, Debug)]
pub(super) struct PosesMsg {
    pub(super) timestamp: FgTime,
    pub(super) t: f64,
    pub(super) wrist: PoseMsg,
    pub(super) object: PoseMsg,
    pub(super) object_ref: Option<PoseMsg>,
}

#[derive(Serialize, Debug)]
pub(super) struct XyzMsg {
    pub(super) x: f32,
    pub(super) y: f32,
    pub(super) z: f32,
}

impl From<Vec3> for XyzMsg {
    fn from(v: Vec3) -> Self {
        XyzMsg { x: v.x, y: v.y, z: v.z }
    }
}

#[derive(Serialize, Debug)]
pub(super) struct ContactMsg<'a> {
    pub(super) kind: &'static str,
    pub(super) index: u32,
    pub(super) link: Option<&'a str>,
    pub(super) pos: XyzMsg,
    pub(super) normal: XyzMsg,
    pub(super) depth: f32,
    pub(super) force: XyzMsg,
}

#[derive(Serialize, Debug)]
pub(super) struct ContactsMsg<'a> {
    pub(super) timestamp: FgTime,
    pub(super) t: f64,
    pub(super) contacts: Vec<ContactMsg<'a>>,
}
