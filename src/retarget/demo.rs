//! A human demonstration as the retargeting reads it: per frame the hand's 21 keypoints and the
//! object's pose, the frame rate and the frame they are given in. [`load_dexmv`] reads DexMV's
//! layout (`.npz`: `hand_joints` [N, 21, 3] in metres, `object_pose` [M, 4, 4], the 1-based
//! `hand_frame_index` / `object_frame_index` that pair them, `fps`; `../shared/demos/SOURCES.md`
//! documents the arrays).
//!
//! Keypoints are in the MANO / OpenPose order ([`KEYPOINT_NAMES`]): 0 the wrist; 1–4 the thumb
//! (CMC, MCP, IP, tip); 5–8 the index finger (MCP, PIP, DIP, tip); 9–12 middle; 13–16 ring; 17–20
//! little. Every problem is a one-line error naming the file, the array and the frame.

use std::path::Path;

use anyhow::{Result, anyhow, ensure};
use glam::{Mat3, Quat, Vec3};

use crate::geom::Pose;
use crate::traj::npy::{NpyArray, read_npz};

/// Keypoints of a human hand.
pub const HUMAN_KEYPOINTS: usize = 21;

/// The keypoints' names, in order.
pub const KEYPOINT_NAMES: [&str; HUMAN_KEYPOINTS] = [
    "wrist", "thumb_cmc", "thumb_mcp", "thumb_ip", "thumb_tip", "index_mcp", "index_pip", "index_dip", "index_tip", "middle_mcp", "middle_pip",
    "middle_dip", "middle_tip", "ring_mcp", "ring_pip", "ring_dip", "ring_tip", "little_mcp", "little_pip", "little_dip", "little_tip",
];

/// Largest distance of a keypoint or the object from the frame's origin that is taken as metres
/// (a demo in millimetres fails here).
pub const MAX_DEMO_DISTANCE_M: f32 = 10.0;

/// Largest distance between a hand's wrist and its middle knuckle taken as a human hand (m).
pub const MAX_PALM_LENGTH_M: f32 = 0.3;

/// A human hand–object demonstration.
#[derive(Clone, Debug)]
pub struct HumanDemo {
    /// Frames per second.
    pub fps: f64,
    /// Per frame, the 21 keypoints (m, in `frame`).
    pub keypoints: Vec<[Vec3; HUMAN_KEYPOINTS]>,
    /// Per frame, the object's pose (in `frame`).
    pub object: Vec<Pose>,
    /// The frame the poses are in (DexMV's: "camera").
    pub frame: String,
}

/// The array `key` of `arrays`, or an error naming the file.
fn array<'a>(arrays: &'a std::collections::BTreeMap<String, NpyArray>, key: &str, file: &str) -> Result<&'a NpyArray> {
    arrays.get(key).ok_or_else(|| anyhow!("{file}: no array `{key}` (a DexMV demo has hand_joints, object_pose, hand_frame_index, object_frame_index, fps)"))
}

/// Reads a DexMV demonstration (`.npz`).
pub fn load_dexmv(path: &Path) -> Result<HumanDemo> {
    let file = path.display().to_string();
    let arrays = read_npz(path)?;
    let joints = array(&arrays, "hand_joints", &file)?;
    ensure!(
        joints.shape.len() == 3 && joints.shape[1] == HUMAN_KEYPOINTS && joints.shape[2] == 3 && joints.shape[0] > 0,
        "{file}: hand_joints has shape {:?}; expected [frames, 21, 3]",
        joints.shape
    );
    let poses = array(&arrays, "object_pose", &file)?;
    ensure!(poses.shape.len() == 3 && poses.shape[1] == 4 && poses.shape[2] == 4, "{file}: object_pose has shape {:?}; expected [frames, 4, 4]", poses.shape);
    let hand_index = array(&arrays, "hand_frame_index", &file)?.to_f64();
    let object_index = array(&arrays, "object_frame_index", &file)?.to_f64();
    let fps_values = array(&arrays, "fps", &file)?.to_f64();
    let fps = match fps_values.as_slice() {
        [f] if f.is_finite() && *f > 0.0 => *f,
        other => return Err(anyhow!("{file}: fps is {other:?}; expected one positive number")),
    };
    let frames = joints.shape[0];
    ensure!(hand_index.len() == frames, "{file}: hand_frame_index has {} entries for {frames} frames of hand_joints", hand_index.len());
    ensure!(object_index.len() == poses.shape[0], "{file}: object_frame_index has {} entries for {} object poses", object_index.len(), poses.shape[0]);
    let kp = joints.to_f64();
    let pose_values = poses.to_f64();
    let mut demo = HumanDemo { fps, keypoints: Vec::with_capacity(frames), object: Vec::with_capacity(frames), frame: "camera".into() };
    for f in 0..frames {
        let mut k = [Vec3::ZERO; HUMAN_KEYPOINTS];
        for (i, p) in k.iter_mut().enumerate() {
            let at = (f * HUMAN_KEYPOINTS + i) * 3;
            *p = Vec3::new(kp[at] as f32, kp[at + 1] as f32, kp[at + 2] as f32);
            ensure!(p.is_finite(), "{file}: hand_joints frame {f} keypoint {i} ({}) is not finite", KEYPOINT_NAMES[i]);
            ensure!(p.length() <= MAX_DEMO_DISTANCE_M, "{file}: hand_joints frame {f} keypoint {i} ({}) is {:.1} m from the origin; expected metres (under {MAX_DEMO_DISTANCE_M} m)", KEYPOINT_NAMES[i], p.length());
        }
        let palm = (k[9] - k[0]).length();
        ensure!(palm > 0.0 && palm <= MAX_PALM_LENGTH_M, "{file}: hand_joints frame {f}: wrist to middle knuckle is {palm:.3} m; expected a human hand in metres (under {MAX_PALM_LENGTH_M} m)");
        // the object pose of the same source frame
        let source = hand_index[f];
        let o = object_index.iter().position(|&i| i == source).ok_or_else(|| anyhow!("{file}: hand frame {f} (source frame {source}) has no object_pose with that object_frame_index"))?;
        let m = &pose_values[o * 16..o * 16 + 16]; // row-major 4 × 4
        ensure!(m.iter().all(|v| v.is_finite()), "{file}: object_pose frame {o} is not finite");
        ensure!(m[12] == 0.0 && m[13] == 0.0 && m[14] == 0.0 && m[15] == 1.0, "{file}: object_pose frame {o}: last row {:?}; expected [0, 0, 0, 1]", &m[12..16]);
        let rot = Mat3::from_cols(
            Vec3::new(m[0] as f32, m[4] as f32, m[8] as f32),
            Vec3::new(m[1] as f32, m[5] as f32, m[9] as f32),
            Vec3::new(m[2] as f32, m[6] as f32, m[10] as f32),
        );
        // the estimate's rotation is orthonormal only roughly (SOURCES.md: to 7.4e-3): the nearest
        // rotation's quaternion, normalised
        ensure!((rot.determinant() - 1.0).abs() < 0.05, "{file}: object_pose frame {o}: its rotation's determinant is {:.3}; expected 1", rot.determinant());
        let pos = Vec3::new(m[3] as f32, m[7] as f32, m[11] as f32);
        ensure!(pos.length() <= MAX_DEMO_DISTANCE_M, "{file}: object_pose frame {o} is {:.1} m from the origin; expected metres", pos.length());
        demo.keypoints.push(k);
        demo.object.push(Pose { pos, rot: Quat::from_mat3(&rot).normalize() });
    }
    Ok(demo)
}
