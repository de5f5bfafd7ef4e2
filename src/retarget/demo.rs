//! A human demonstration as the retargeting reads it: per frame the hand's 21 keypoints and the
//! object's pose, the frame rate and the frame they are given in. [`load_dexmv`] reads DexMV's
//! layout (`.npz`: `hand_joints` [N, 21, 3] in metres, `object_pose` [M, 4, 4], the 1-based
//! `hand_frame_index` / `object_frame_index` that pair them, `fps`; `../shared/demos/SOURCES.md`
//! documents the arrays). As DexMV's own loader (`load_hand_object_data_v2`) does, the object's
//! poses are turned by 180° about the camera's z axis ([`dexmv_object_in_hand_camera`]): its
//! object estimator's camera frame is the hand estimator's so turned; read as stored, the bottle
//! of DexMV's example would stand on its cap in a camera that looks up at the table.
//!
//! [`load_csv`] reads dextrain's own CSV layout: comment lines first (`# frame: camera` or
//! `# frame: world`, the frame of every position and pose; without one, `camera`), then a header
//! `t,wrist_x,wrist_y,wrist_z,thumb_cmc_x,…,little_tip_z,object_x,object_y,object_z,object_qw,
//! object_qx,object_qy,object_qz` ([`csv_header`]) and one row per frame: its time (s, from 0,
//! evenly spaced: the rate is 1 / the spacing), the 21 keypoints (m) and the object's pose (m, a
//! unit quaternion w, x, y, z). [`load_demo_mcap`] reads the same in MCAP (a JSON message per
//! frame). [`load_demo`] picks the reader by the file's extension.
//!
//! Keypoints are in the MANO / OpenPose order ([`KEYPOINT_NAMES`]): 0 the wrist; 1–4 the thumb
//! (CMC, MCP, IP, tip); 5–8 the index finger (MCP, PIP, DIP, tip); 9–12 middle; 13–16 ring; 17–20
//! little. Every problem is a one-line error naming the file, the array (or column) and the frame.

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

/// That one frame's keypoints are a human hand in metres: each within [`MAX_DEMO_DISTANCE_M`] of
/// the origin, the wrist within [`MAX_PALM_LENGTH_M`] of the middle knuckle; else an error that
/// begins with `place` (the file and the frame).
fn check_hand(k: &[Vec3; HUMAN_KEYPOINTS], place: &str) -> Result<()> {
    for (i, p) in k.iter().enumerate() {
        ensure!(p.length() <= MAX_DEMO_DISTANCE_M, "{place} keypoint {i} ({}) is {:.1} m from the origin; expected metres (under {MAX_DEMO_DISTANCE_M} m)", KEYPOINT_NAMES[i], p.length());
    }
    let palm = (k[9] - k[0]).length();
    ensure!(palm > 0.0 && palm <= MAX_PALM_LENGTH_M, "{place}: wrist to middle knuckle is {palm:.3} m; expected a human hand in metres (under {MAX_PALM_LENGTH_M} m)");
    Ok(())
}

/// A DexMV object pose (its object estimator's camera frame) in the hand's camera frame: turned by
/// 180° about z, `(x, y, z) → (−x, −y, z)`, as DexMV's `load_hand_object_data_v2` left-multiplies
/// it.
pub fn dexmv_object_in_hand_camera(pose: Pose) -> Pose {
    let turn = Quat::from_rotation_z(std::f32::consts::PI);
    Pose { pos: Vec3::new(-pose.pos.x, -pose.pos.y, pose.pos.z), rot: (turn * pose.rot).normalize() }
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
        }
        check_hand(&k, &format!("{file}: hand_joints frame {f}"))?;
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
        demo.object.push(dexmv_object_in_hand_camera(Pose { pos, rot: Quat::from_mat3(&rot).normalize() }));
    }
    Ok(demo)
}

/// The header of dextrain's CSV demonstration layout ([`load_csv`]).
pub fn csv_header() -> String {
    let mut cols = vec!["t".to_string()];
    for name in KEYPOINT_NAMES {
        cols.extend(["x", "y", "z"].map(|a| format!("{name}_{a}")));
    }
    cols.extend(["object_x", "object_y", "object_z", "object_qw", "object_qx", "object_qy", "object_qz"].map(String::from));
    cols.join(",")
}

/// The keypoints and the object's pose of one frame as a CSV row of [`csv_header`]'s columns.
pub fn csv_row(t: f64, keypoints: &[Vec3; HUMAN_KEYPOINTS], object: &Pose) -> String {
    let mut v = vec![format!("{t}")];
    for k in keypoints {
        v.extend([k.x, k.y, k.z].map(|c| c.to_string()));
    }
    let (p, q) = (object.pos, object.rot);
    v.extend([p.x, p.y, p.z, q.w, q.x, q.y, q.z].map(|c| c.to_string()));
    v.join(",")
}

/// Reads dextrain's CSV demonstration layout (module documentation).
pub fn load_csv(path: &Path) -> Result<HumanDemo> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| anyhow!("{file}: cannot read it: {e}"))?;
    let mut frame = "camera".to_string();
    let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
    let header = loop {
        let Some((n, line)) = lines.next() else { return Err(anyhow!("{file}: no header line; expected `{}`", csv_header())) };
        match line.strip_prefix('#') {
            Some(comment) => {
                if let Some(name) = comment.trim().strip_prefix("frame:") {
                    frame = name.trim().to_string();
                    ensure!(frame == "camera" || frame == "world", "{file}: line {}: frame `{frame}`; expected `camera` or `world`", n + 1);
                }
            }
            None => break line,
        }
    };
    let want = csv_header();
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    let expected: Vec<&str> = want.split(',').collect();
    ensure!(cols.len() == expected.len(), "{file}: the header has {} columns; expected {} (t, 21 keypoints × 3, the object's position and quaternion)", cols.len(), expected.len());
    if let Some((got, exp)) = cols.iter().zip(&expected).find(|(a, b)| a != b) {
        return Err(anyhow!("{file}: header column `{got}` where `{exp}` was expected"));
    }
    let mut demo = HumanDemo { fps: 0.0, keypoints: Vec::new(), object: Vec::new(), frame };
    let mut times: Vec<f64> = Vec::new();
    for (n, line) in lines {
        let f = times.len();
        let values: Vec<f64> = line
            .split(',')
            .enumerate()
            .map(|(c, v)| v.trim().parse::<f64>().map_err(|_| anyhow!("{file}: line {} (frame {f}): column `{}` is `{}`; expected a number", n + 1, expected.get(c).unwrap_or(&"?"), v.trim())))
            .collect::<Result<_>>()?;
        ensure!(values.len() == expected.len(), "{file}: line {} (frame {f}) has {} values; expected {}", n + 1, values.len(), expected.len());
        ensure!(values.iter().all(|v| v.is_finite()), "{file}: line {} (frame {f}): a value is not finite", n + 1);
        let mut k = [Vec3::ZERO; HUMAN_KEYPOINTS];
        for (i, p) in k.iter_mut().enumerate() {
            *p = Vec3::new(values[1 + 3 * i] as f32, values[2 + 3 * i] as f32, values[3 + 3 * i] as f32);
        }
        let o = 1 + 3 * HUMAN_KEYPOINTS;
        let pos = Vec3::new(values[o] as f32, values[o + 1] as f32, values[o + 2] as f32);
        let q = Quat::from_xyzw(values[o + 4] as f32, values[o + 5] as f32, values[o + 6] as f32, values[o + 3] as f32);
        push_frame(&mut demo, &format!("{file}: frame {f}"), k, Pose { pos, rot: q })?;
        times.push(values[0]);
    }
    demo.fps = rate_of(&file, &times)?;
    Ok(demo)
}

/// The frame rate of frames at `times` (s): from 0, evenly spaced; else an error naming `file` and
/// the frame.
fn rate_of(file: &str, times: &[f64]) -> Result<f64> {
    ensure!(times.len() >= 2, "{file}: {} frame(s); expected two at least (the rate is their spacing)", times.len());
    ensure!(times[0] == 0.0, "{file}: frame 0 is at t = {}; expected 0", times[0]);
    let dt = times[1] - times[0];
    ensure!(dt > 0.0, "{file}: frame 1 is at t = {}; expected times increasing from 0", times[1]);
    for (f, t) in times.iter().enumerate() {
        ensure!((t - f as f64 * dt).abs() <= 1e-6 + 1e-3 * dt, "{file}: frame {f} is at t = {t}; expected evenly spaced frames ({} s apart, as frames 0 and 1)", dt);
    }
    Ok(1.0 / dt)
}

/// The MCAP topic of dextrain's demonstration layout ([`load_demo_mcap`]), its messages' JSON
/// Schema name and its metadata record's name.
pub const DEMO_TOPIC: &str = "/dextrain/human_demo";
pub const DEMO_SCHEMA_NAME: &str = "dextrain.HumanDemoFrame";
pub const DEMO_METADATA_NAME: &str = "dextrain.human_demo";

/// A JSON number of `v` at `field`, or an error naming it.
fn json_number(v: &serde_json::Value, field: &str) -> std::result::Result<f64, String> {
    v.as_f64().filter(|x| x.is_finite()).ok_or_else(|| format!("field `{field}` is {v}; expected a finite number"))
}

/// One message of the MCAP layout: its time, keypoints and object pose.
fn demo_message(v: &serde_json::Value) -> std::result::Result<(f64, [Vec3; HUMAN_KEYPOINTS], Pose), String> {
    let t = json_number(&v["t"], "t")?;
    let kps = v["keypoints"].as_array().ok_or_else(|| format!("field `keypoints` is {}; expected an array of 21 [x, y, z]", v["keypoints"]))?;
    if kps.len() != HUMAN_KEYPOINTS {
        return Err(format!("field `keypoints` has {} keypoints; expected 21 (the MANO / OpenPose order)", kps.len()));
    }
    let mut k = [Vec3::ZERO; HUMAN_KEYPOINTS];
    for (i, p) in kps.iter().enumerate() {
        let xyz = p.as_array().filter(|a| a.len() == 3).ok_or_else(|| format!("field `keypoints[{i}]` ({}) is {p}; expected [x, y, z]", KEYPOINT_NAMES[i]))?;
        let c = |j: usize| json_number(&xyz[j], &format!("keypoints[{i}][{j}]")).map(|x| x as f32);
        k[i] = Vec3::new(c(0)?, c(1)?, c(2)?);
    }
    let o = &v["object"];
    let n = |key: &str| json_number(&o[key], &format!("object.{key}")).map(|x| x as f32);
    let pose = Pose { pos: Vec3::new(n("x")?, n("y")?, n("z")?), rot: Quat::from_xyzw(n("qx")?, n("qy")?, n("qz")?, n("qw")?) };
    Ok((t, k, pose))
}

/// Reads dextrain's MCAP demonstration layout (docs/file-formats.md): a metadata record
/// [`DEMO_METADATA_NAME`] whose `frame` is `camera` or `world` (without it, `camera`), and one JSON
/// message per frame on [`DEMO_TOPIC`]: `{"t": s, "keypoints": [[x, y, z] × 21], "object": {"x",
/// "y", "z", "qx", "qy", "qz", "qw"}}`, in log-time order, times from 0 evenly spaced; other
/// topics are ignored.
pub fn load_demo_mcap(path: &Path) -> Result<HumanDemo> {
    use mcap::records::Record;
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| anyhow!("{file}: cannot read it: {e}"))?;
    let mut demo = HumanDemo { fps: 0.0, keypoints: Vec::new(), object: Vec::new(), frame: "camera".into() };
    let mut channels = std::collections::HashMap::new();
    let mut times = Vec::new();
    let mut records = crate::traj::io::McapRecords::new(&bytes);
    while let Some(record) = records.next_record() {
        match record.map_err(|e| anyhow!("{file}: expected a readable MCAP file: {e}"))? {
            Record::Metadata(m) if m.name == DEMO_METADATA_NAME => {
                if let Some(frame) = m.metadata.get("frame") {
                    ensure!(frame == "camera" || frame == "world", "{file}: metadata `{DEMO_METADATA_NAME}`: field `frame` is `{frame}`; expected `camera` or `world`");
                    demo.frame = frame.clone();
                }
            }
            Record::Channel(ch) => {
                channels.insert(ch.id, (ch.topic, ch.message_encoding));
            }
            Record::Message { header, data } => {
                let Some((topic, encoding)) = channels.get(&header.channel_id) else { continue };
                if topic != DEMO_TOPIC {
                    continue;
                }
                let f = times.len();
                ensure!(encoding == "json", "{file}: frame {f}: message encoding `{encoding}` on {DEMO_TOPIC}; expected `json`");
                let value: serde_json::Value = serde_json::from_slice(&data).map_err(|e| anyhow!("{file}: frame {f}: not JSON: {e}"))?;
                let (t, k, object) = demo_message(&value).map_err(|e| anyhow!("{file}: frame {f}: {e}"))?;
                push_frame(&mut demo, &format!("{file}: frame {f}"), k, object)?;
                times.push(t);
            }
            _ => {}
        }
    }
    ensure!(!times.is_empty(), "{file}: no message on {DEMO_TOPIC}; expected one per frame (docs/file-formats.md)");
    demo.fps = rate_of(&file, &times)?;
    Ok(demo)
}

/// Checks one frame (a human hand in metres, the object within reach, a unit quaternion) and adds
/// it to `demo`; errors begin with `place` (the file and the frame).
fn push_frame(demo: &mut HumanDemo, place: &str, k: [Vec3; HUMAN_KEYPOINTS], object: Pose) -> Result<()> {
    check_hand(&k, place)?;
    ensure!(object.pos.length() <= MAX_DEMO_DISTANCE_M, "{place}: the object is {:.1} m from the origin; expected metres", object.pos.length());
    ensure!((object.rot.length() - 1.0).abs() < 1e-3, "{place}: the object's quaternion has norm {:.4}; expected a unit quaternion", object.rot.length());
    demo.keypoints.push(k);
    demo.object.push(Pose { pos: object.pos, rot: object.rot.normalize() });
    Ok(())
}

/// Reads a demonstration: DexMV's `.npz` layout ([`load_dexmv`]), dextrain's `.csv` ([`load_csv`])
/// or `.mcap` ([`load_demo_mcap`]).
pub fn load_demo(path: &Path) -> Result<HumanDemo> {
    match path.extension().and_then(|e| e.to_str()) {
        Some("npz") => load_dexmv(path),
        Some("csv") => load_csv(path),
        Some("mcap") => load_demo_mcap(path),
        other => Err(anyhow!("{}: a demonstration is a DexMV `.npz`, or a dextrain `.csv` or `.mcap`, not `{}`", path.display(), other.unwrap_or(""))),
    }
}

