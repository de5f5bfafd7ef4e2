//! Reference trajectories: file formats (MCAP and CSV round trips, Python-written files, every
//! kind of bad input), interpolation and resampling, joint mapping, and the user docs staying in
//! step with the code.

use std::collections::BTreeMap;
use std::f32::consts::FRAC_PI_2;
use std::io::Cursor;
use std::path::{Path, PathBuf};

use dextrain::geom::Pose;
use dextrain::traj::{
    FORMAT_VERSION, Keyframe, REFERENCE_JSON_SCHEMA, REFERENCE_METADATA_NAME, REFERENCE_SCHEMA_NAME, REFERENCE_TOPIC,
    Trajectory,
};
use glam::{Quat, Vec3};

// ---------------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------------

fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/traj")
}

/// Deterministic pseudo-random numbers (xorshift), so failures reproduce.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    /// Uniform in [-1, 1), with all 24 bits of mantissa in use (awkward decimal expansions).
    fn f32(&mut self) -> f32 {
        ((self.next_u64() >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
    }
    fn quat(&mut self) -> Quat {
        loop {
            let q = Quat::from_xyzw(self.f32(), self.f32(), self.f32(), self.f32());
            if q.length() > 0.1 {
                return q.normalize();
            }
        }
    }
    fn pose(&mut self) -> Pose {
        Pose::new(Vec3::new(self.f32(), self.f32(), self.f32()) * 0.7, self.quat())
    }
}

/// A trajectory with awkward values everywhere: joint names out of alphabetical order, f64 times
/// with 17 significant digits, tiny and large magnitudes, negative zero.
fn awkward_trajectory(tips: bool, object: bool) -> Trajectory {
    let mut rng = Rng(0x2545_F491_4F6C_DD1D);
    let joint_names: Vec<String> = ["th_j0", "if_j1", "if_j0", "mf:j0", "zz", "a"].map(String::from).to_vec();
    let fingertip_names: Vec<String> = if tips { ["th_tip", "if_tip"].map(String::from).to_vec() } else { Vec::new() };
    let mut frames = Vec::new();
    let mut t = 0.0f64;
    for k in 0..25 {
        let mut joints: Vec<f32> = joint_names.iter().map(|_| rng.f32() * 3.0).collect();
        if k == 3 {
            joints[0] = -0.0;
            joints[1] = 1e-30;
            joints[2] = 99.999_99; // near MAX_JOINT_RAD, the largest joint value a reference may hold
            joints[3] = f32::MIN_POSITIVE;
        }
        frames.push(Keyframe {
            t,
            wrist: rng.pose(),
            joints,
            fingertips: tips
                .then(|| fingertip_names.iter().map(|_| Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 0.2).collect()),
            object: object.then(|| rng.pose()),
        });
        t += 0.0123 + (rng.next_u64() % 1000) as f64 * 1.7e-5;
    }
    Trajectory { joint_names, fingertip_names, frames, object_name: None }
}

fn pose_msg(x: f32, y: f32, z: f32, q: Quat) -> String {
    format!(r#"{{"x":{x},"y":{y},"z":{z},"qx":{},"qy":{},"qz":{},"qw":{}}}"#, q.x, q.y, q.z, q.w)
}

const W: &str = r#"{"x":0,"y":0,"z":0,"qx":0,"qy":0,"qz":0,"qw":1}"#;

/// A valid message at time `t` with the given joints JSON object text.
fn msg(t: &str, joints: &str) -> String {
    format!(r#"{{"t":{t},"wrist":{W},"joints":{joints}}}"#)
}

/// Options for [`write_mcap`], so tests can imitate other writers.
struct McapSpec<'a> {
    compression: Option<mcap::Compression>,
    chunk_size: Option<u64>,
    library: &'a str,
    metadata: Option<BTreeMap<String, String>>,
    encoding: &'a str,
    /// (log time in ns, message) on the reference topic.
    messages: Vec<(u64, String)>,
    /// Messages on another topic, interleaved before each reference message.
    noise_topic: bool,
    chunked: bool,
}

impl Default for McapSpec<'_> {
    fn default() -> Self {
        McapSpec {
            compression: Some(mcap::Compression::Zstd),
            chunk_size: None,
            library: "python mcap 1.2.1",
            metadata: Some(BTreeMap::from([("format_version".to_string(), "1".to_string())])),
            encoding: "json",
            messages: Vec::new(),
            noise_topic: false,
            chunked: true,
        }
    }
}

fn write_mcap(spec: &McapSpec) -> Vec<u8> {
    let mut w = mcap::WriteOptions::new()
        .compression(spec.compression)
        .chunk_size(spec.chunk_size)
        .use_chunks(spec.chunked)
        .profile("")
        .library(spec.library)
        .create(Cursor::new(Vec::new()))
        .unwrap();
    if let Some(m) = &spec.metadata {
        w.write_metadata(&mcap::records::Metadata { name: REFERENCE_METADATA_NAME.into(), metadata: m.clone() })
            .unwrap();
    }
    let schema = w.add_schema(REFERENCE_SCHEMA_NAME, "jsonschema", REFERENCE_JSON_SCHEMA.as_bytes()).unwrap();
    let ch = w.add_channel(schema, REFERENCE_TOPIC, spec.encoding, &BTreeMap::new()).unwrap();
    let noise = w.add_channel(0, "/camera/info", "json", &BTreeMap::new()).unwrap();
    for (log_time, m) in &spec.messages {
        if spec.noise_topic {
            let header =
                mcap::records::MessageHeader { channel_id: noise, sequence: 0, log_time: *log_time, publish_time: 0 };
            w.write_to_known_channel(&header, br#"{"fps": 30}"#).unwrap();
        }
        // Python's writer leaves the sequence at 0.
        let header = mcap::records::MessageHeader { channel_id: ch, sequence: 0, log_time: *log_time, publish_time: 0 };
        w.write_to_known_channel(&header, m.as_bytes()).unwrap();
    }
    w.finish().unwrap();
    w.into_inner().into_inner()
}

fn mcap_of(messages: &[String]) -> Vec<u8> {
    write_mcap(&McapSpec { messages: messages.iter().map(|m| (0, m.clone())).collect(), ..Default::default() })
}

/// Writes `bytes` as `dir/name` and loads it, expecting an error; checks the error is one line
/// and names the file and everything in `needles`. Returns the message.
fn load_err(dir: &Path, name: &str, bytes: &[u8], needles: &[&str]) -> String {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    let msg = match Trajectory::load(&path) {
        Ok(t) => panic!("{name}: expected an error, got a trajectory of {} frames", t.frames.len()),
        Err(e) => format!("{e:#}"),
    };
    assert!(!msg.contains('\n') && !msg.contains('\r'), "{name}: error is not one line: {msg:?}");
    assert!(msg.contains(name), "{name}: error does not name the file: {msg}");
    assert!(msg.contains("expected"), "{name}: error does not say what was expected: {msg}");
    for n in needles {
        assert!(msg.contains(n), "{name}: error does not contain {n:?}: {msg}");
    }
    msg
}

fn assert_quat_close(a: Quat, b: Quat, tol: f32) {
    // q and -q are the same rotation
    let d = (a - b).length().min((a + b).length());
    assert!(d < tol, "quaternions differ: {a} vs {b}");
}

// The literals are those of the example files, digit for digit.
#[allow(clippy::excessive_precision)]
fn example_expected() -> Trajectory {
    let q45 = Quat::from_xyzw(0.0, 0.0, 0.38268343, 0.92387953);
    let q90 = Quat::from_xyzw(0.0, 0.0, 0.70710677, 0.70710677);
    let f = |t: f64, x: f32, z: f32, rot: Quat, j: [f32; 2]| Keyframe {
        t,
        wrist: Pose::new(Vec3::new(x, 0.0, z), rot),
        joints: j.to_vec(),
        fingertips: None,
        object: None,
    };
    Trajectory {
        joint_names: vec!["if_j0".into(), "th_j0".into()],
        fingertip_names: vec![],
        frames: vec![
            f(0.0, 0.0, 0.3, Quat::IDENTITY, [0.0, 0.0]),
            f(0.5, 0.05, 0.2, q45, [0.4, 0.2]),
            f(1.0, 0.1, 0.15, q90, [0.8, 0.6]),
        ],
        object_name: None,
    }
}

// ---------------------------------------------------------------------------------------------
// Round trips
// ---------------------------------------------------------------------------------------------

#[test]
fn mcap_round_trip_is_exact() {
    for (tips, object) in [(true, true), (false, false), (true, false), (false, true)] {
        let traj = awkward_trajectory(tips, object);
        let bytes = traj.to_mcap_bytes().unwrap();
        let back = Trajectory::from_mcap_bytes(&bytes, "mem.mcap").unwrap();
        assert_eq!(back, traj, "tips {tips} object {object}");
        // bit-exact, including the sign of zero
        assert_eq!(back.frames[3].joints[0].to_bits(), (-0.0f32).to_bits());
        for (a, b) in back.frames.iter().zip(&traj.frames) {
            assert_eq!(a.t.to_bits(), b.t.to_bits());
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ref.mcap");
    let traj = awkward_trajectory(true, true);
    traj.save_mcap(&path).unwrap();
    assert_eq!(Trajectory::load(&path).unwrap(), traj);
    // `save` dispatches on the extension too (any case)
    let upper = dir.path().join("REF.MCAP");
    traj.save(&upper).unwrap();
    assert_eq!(Trajectory::load(&upper).unwrap(), traj);
}

#[test]
fn csv_round_trip_is_exact() {
    for (tips, object) in [(true, true), (false, false), (true, false), (false, true)] {
        let traj = awkward_trajectory(tips, object);
        let text = traj.to_csv_string().unwrap();
        let back = Trajectory::from_csv_str(&text, "mem.csv").unwrap();
        assert_eq!(back, traj, "tips {tips} object {object}");
        assert_eq!(back.frames[3].joints[0].to_bits(), (-0.0f32).to_bits());
        for (a, b) in back.frames.iter().zip(&traj.frames) {
            assert_eq!(a.t.to_bits(), b.t.to_bits());
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ref.csv");
    let traj = awkward_trajectory(true, true);
    traj.save_csv(&path).unwrap();
    assert_eq!(Trajectory::load(&path).unwrap(), traj);
    // MCAP -> CSV -> MCAP is lossless as well
    let via = Trajectory::from_csv_str(&traj.to_csv_string().unwrap(), "x.csv").unwrap();
    assert_eq!(Trajectory::from_mcap_bytes(&via.to_mcap_bytes().unwrap(), "x.mcap").unwrap(), traj);
}

#[test]
fn csv_header_names_columns() {
    let traj = awkward_trajectory(true, true);
    let text = traj.to_csv_string().unwrap();
    let header = text.lines().next().unwrap();
    let cols: Vec<&str> = header.split(',').collect();
    assert_eq!(&cols[..8], ["t", "wrist_x", "wrist_y", "wrist_z", "wrist_qx", "wrist_qy", "wrist_qz", "wrist_qw"]);
    assert_eq!(&cols[8..14], ["joint:th_j0", "joint:if_j1", "joint:if_j0", "joint:mf:j0", "joint:zz", "joint:a"]);
    assert_eq!(&cols[14..17], ["tip:th_tip:x", "tip:th_tip:y", "tip:th_tip:z"]);
    assert_eq!(
        cols[cols.len() - 7..],
        ["object_x", "object_y", "object_z", "object_qx", "object_qy", "object_qz", "object_qw"]
    );
    assert_eq!(text.lines().count(), 1 + traj.frames.len());
}

#[test]
fn written_mcap_has_topic_schema_metadata_and_log_times() {
    let traj = awkward_trajectory(true, true);
    let bytes = traj.to_mcap_bytes().unwrap();
    let msgs: Vec<_> = mcap::MessageStream::new(&bytes).unwrap().map(|m| m.unwrap()).collect();
    assert_eq!(msgs.len(), traj.frames.len());
    for (m, f) in msgs.iter().zip(&traj.frames) {
        assert_eq!(m.channel.topic, "/dextrain/reference");
        assert_eq!(m.channel.message_encoding, "json");
        let schema = m.channel.schema.as_ref().unwrap();
        assert_eq!(schema.name, "dextrain.ReferenceFrame");
        assert_eq!(schema.encoding, "jsonschema");
        assert_eq!(m.log_time, (f.t * 1e9).round() as u64);
        // named quaternion fields, in the documented key order
        let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        let keys: Vec<&str> = v.as_object().unwrap().keys().map(String::as_str).collect();
        assert_eq!(keys.len(), 5);
        for k in ["x", "y", "z", "qx", "qy", "qz", "qw"] {
            assert!(v["wrist"][k].is_number() && v["object"][k].is_number(), "{k}");
        }
        assert_eq!(v["wrist"]["qw"].as_f64().unwrap() as f32, f.wrist.rot.w);
        assert!(v["fingertips"]["th_tip"]["z"].is_number());
    }
    let schema: serde_json::Value = serde_json::from_slice(&msgs[0].channel.schema.as_ref().unwrap().data).unwrap();
    assert_eq!(schema["$schema"], "https://json-schema.org/draft/2020-12/schema");
    assert_eq!(schema["required"], serde_json::json!(["t", "wrist", "joints"]));
    assert_eq!(schema["additionalProperties"], false);

    let mut found = 0;
    for rec in mcap::read::LinearReader::new(&bytes).unwrap() {
        if let mcap::records::Record::Metadata(m) = rec.unwrap() {
            assert_eq!(m.name, "dextrain.reference");
            assert_eq!(m.metadata["format_version"], FORMAT_VERSION);
            assert_eq!(FORMAT_VERSION, "1");
            found += 1;
        }
    }
    assert_eq!(found, 1);
}

// ---------------------------------------------------------------------------------------------
// Files from other writers
// ---------------------------------------------------------------------------------------------

/// What Python's `mcap` + `json.dumps` produce: spaces after separators, keys in another order,
/// ints for whole numbers, f64 digits, sequence 0, small zstd chunks, messages out of time order,
/// other topics in between, log times that are not t.
#[test]
fn python_style_zstd_mcap_reads_back() {
    let q = Quat::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 0.7);
    let py = |t: &str, a: f64, b: i64| {
        format!(
            r#"{{"joints": {{"th_j0": {b}, "if_j0": {a}}}, "t": {t}, "wrist": {{"qw": {}, "qx": {}, "qy": {}, "qz": {}, "x": 0.1, "y": -0.25, "z": 1}}, "object": {{"x": 0, "y": 0, "z": 0.05, "qx": 0.0, "qy": 0.0, "qz": 0.0, "qw": 1.0}}, "fingertips": {{"if_tip": {{"x": 0.1, "y": 0.2, "z": 0.30000000000000004}}}}}}"#,
            q.w as f64, q.x as f64, q.y as f64, q.z as f64
        )
    };
    let messages = vec![
        (7, py("0.2", 0.30000000000000004, 1)),
        (3, py("0", 0.1, 0)),
        (1, py("0.1", 0.2, -1)),
        (0, py("1e-1", 0.5, 2).replace(r#""t": 1e-1"#, r#""t": 0.4"#)),
    ];
    for compression in [Some(mcap::Compression::Zstd), Some(mcap::Compression::Lz4), None] {
        let bytes = write_mcap(&McapSpec {
            compression,
            chunk_size: Some(300),
            metadata: None,
            messages: messages.clone(),
            noise_topic: true,
            ..Default::default()
        });
        let traj = Trajectory::from_mcap_bytes(&bytes, "py.mcap").unwrap();
        // joint order is the order of the earliest frame's keys
        assert_eq!(traj.joint_names, ["th_j0", "if_j0"]);
        assert_eq!(traj.fingertip_names, ["if_tip"]);
        let ts: Vec<f64> = traj.frames.iter().map(|f| f.t).collect();
        assert_eq!(ts, [0.0, 0.1, 0.2, 0.4]);
        assert_eq!(traj.frames[0].joints, [0.0, 0.1f64 as f32]);
        assert_eq!(traj.frames[1].joints, [-1.0, 0.2]);
        assert_eq!(traj.frames[2].joints, [1.0, 0.30000000000000004f64 as f32]);
        assert_eq!(traj.frames[0].wrist.pos, Vec3::new(0.1, -0.25, 1.0));
        assert_quat_close(traj.frames[0].wrist.rot, q, 1e-7);
        assert_eq!(traj.frames[0].object.unwrap().pos, Vec3::new(0.0, 0.0, 0.05));
        assert_eq!(traj.frames[2].fingertips.as_ref().unwrap()[0], Vec3::new(0.1, 0.2, 0.3));
    }
}

/// `tests/data/traj/example.mcap` was written by `write_example.py` (Python `mcap` 1.6.0, zstd).
#[test]
fn real_python_written_mcap_matches_the_csv_example() {
    let dir = data_dir();
    let from_py = Trajectory::load(dir.join("example.mcap")).unwrap();
    let from_csv = Trajectory::load(dir.join("example.csv")).unwrap();
    assert_eq!(from_py, from_csv);
    assert_eq!(from_csv, example_expected());
    // the docs' JSON messages, written by the Rust mcap writer, agree too
    let jsonl = std::fs::read_to_string(dir.join("example_messages.jsonl")).unwrap();
    let messages: Vec<String> = jsonl.lines().map(String::from).collect();
    assert_eq!(messages.len(), 3);
    assert_eq!(Trajectory::from_mcap_bytes(&mcap_of(&messages), "x.mcap").unwrap(), from_csv);
    // and the file really is zstd-compressed and from Python
    let bytes = std::fs::read(dir.join("example.mcap")).unwrap();
    let mut zstd = false;
    let mut library = String::new();
    for rec in mcap::read::LinearReader::new(&bytes).unwrap() {
        match rec.unwrap() {
            mcap::records::Record::Chunk { header, .. } => zstd |= header.compression == "zstd",
            mcap::records::Record::Header(h) => library = h.library,
            _ => {}
        }
    }
    assert!(zstd);
    assert_eq!(library, "my-retargeting-script");
}

#[test]
fn slightly_off_unit_quaternions_are_normalised() {
    let q = Quat::from_xyzw(0.0, 0.0, 0.0, 1.0004);
    let m = format!(r#"{{"t":0,"wrist":{},"joints":{{}}}}"#, pose_msg(0.0, 0.0, 0.0, q));
    let traj = Trajectory::from_mcap_bytes(&mcap_of(&[m]), "n.mcap").unwrap();
    assert_eq!(traj.frames[0].wrist.rot, Quat::IDENTITY);
    let csv = "t,wrist_x,wrist_y,wrist_z,wrist_qx,wrist_qy,wrist_qz,wrist_qw\n0,0,0,0,0.6,0,0,0.8003\n";
    let traj = Trajectory::from_csv_str(csv, "n.csv").unwrap();
    assert!((traj.frames[0].wrist.rot.length() - 1.0).abs() < 1e-6);
    assert_quat_close(traj.frames[0].wrist.rot, Quat::from_xyzw(0.6, 0.0, 0.0, 0.8), 1e-3);
}

#[test]
fn csv_is_forgiving_about_layout() {
    // any column order, spaces, CRLF, BOM, comments and blank lines, rows out of order
    let csv = "\u{feff}# exported by a spreadsheet\r\n joint:b , wrist_qw,wrist_qx,wrist_qy,wrist_qz, t ,wrist_x,wrist_y,wrist_z,joint:a\r\n\r\n2, 1,0,0,0, 0.5, 1,2,3, 4\r\n1,1,0,0,0,0,0,0,0,3\r\n";
    let traj = Trajectory::from_csv_str(csv, "x.csv").unwrap();
    assert_eq!(traj.joint_names, ["b", "a"]);
    assert_eq!(traj.frames.len(), 2);
    assert_eq!(traj.frames[0].t, 0.0);
    assert_eq!(traj.frames[0].joints, [1.0, 3.0]);
    assert_eq!(traj.frames[1].wrist.pos, Vec3::new(1.0, 2.0, 3.0));
    assert_eq!(traj.frames[1].joints, [2.0, 4.0]);
    // a hand-less reference (wrist only) is fine
    let t = Trajectory::from_csv_str(
        "t,wrist_x,wrist_y,wrist_z,wrist_qx,wrist_qy,wrist_qz,wrist_qw\n0,0,0,0,0,0,0,1\n",
        "w.csv",
    )
    .unwrap();
    assert!(t.joint_names.is_empty() && t.frames[0].joints.is_empty());
}

// ---------------------------------------------------------------------------------------------
// Bad input
// ---------------------------------------------------------------------------------------------

#[test]
fn bad_mcap_inputs_give_one_line_errors_naming_file_frame_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let ok0 = msg("0", r#"{"if_j0":0.1}"#);
    let two = |second: String| mcap_of(&[ok0.clone(), second]);
    let unit = |qw: &str| format!(r#"{{"x":0,"y":0,"z":0,"qx":0,"qy":0,"qz":0,"qw":{qw}}}"#);

    let cases: Vec<(&str, Vec<u8>, Vec<&str>)> = vec![
        (
            "missing_t.mcap",
            two(format!(r#"{{"wrist":{W},"joints":{{"if_j0":1}}}}"#)),
            vec!["frame 1", "`t`", "missing"],
        ),
        (
            "missing_wrist.mcap",
            two(r#"{"t":1,"joints":{"if_j0":1}}"#.to_string()),
            vec!["frame 1", "`wrist`", "missing"],
        ),
        (
            "missing_qw.mcap",
            two(format!(r#"{{"t":1,"wrist":{},"joints":{{"if_j0":1}}}}"#, W.replace(r#","qw":1"#, ""))),
            vec!["frame 1", "`wrist.qw`", "missing"],
        ),
        ("missing_joints.mcap", two(format!(r#"{{"t":1,"wrist":{W}}}"#)), vec!["frame 1", "`joints`", "missing"]),
        ("string_t.mcap", two(msg(r#""1.0""#, r#"{"if_j0":1}"#)), vec!["frame 1", "`t`", "a number", "string"]),
        (
            "string_wrist.mcap",
            two(format!(r#"{{"t":1,"wrist":{},"joints":{{"if_j0":1}}}}"#, W.replace(r#""x":0"#, r#""x":"0""#))),
            vec!["frame 1", "`wrist.x`", "a number", "string"],
        ),
        ("string_joint.mcap", two(msg("1", r#"{"if_j0":"0.5"}"#)), vec!["frame 1", "`joints.if_j0`", "a number"]),
        ("bool_joint.mcap", two(msg("1", r#"{"if_j0":true}"#)), vec!["frame 1", "`joints.if_j0`", "boolean"]),
        ("array_joints.mcap", two(msg("1", "[1]")), vec!["frame 1", "`joints`", "array"]),
        ("nan_joint.mcap", two(msg("1", r#"{"if_j0":NaN}"#)), vec!["frame 1", "`joints.if_j0`", "finite"]),
        (
            "inf_wrist.mcap",
            two(format!(r#"{{"t":1,"wrist":{},"joints":{{"if_j0":1}}}}"#, W.replace(r#""z":0"#, r#""z":-Infinity"#))),
            vec!["frame 1", "`wrist.z`", "finite"],
        ),
        ("huge_t.mcap", two(msg("1e999", r#"{"if_j0":1}"#)), vec!["frame 1", "`t`", "finite"]),
        ("f32_overflow.mcap", two(msg("1", r#"{"if_j0":1e39}"#)), vec!["frame 1", "`joints.if_j0`", "f32"]),
        ("negative_t.mcap", two(msg("-0.5", r#"{"if_j0":1}"#)), vec!["frame 1", "`t`", "≥ 0"]),
        (
            "non_unit_quat.mcap",
            two(format!(r#"{{"t":1,"wrist":{},"joints":{{"if_j0":1}}}}"#, unit("0.9"))),
            vec!["frame 1", "`wrist`", "unit quaternion"],
        ),
        (
            "zero_quat.mcap",
            two(format!(r#"{{"t":1,"wrist":{},"joints":{{"if_j0":1}}}}"#, unit("0"))),
            vec!["frame 1", "`wrist`", "unit quaternion"],
        ),
        (
            "non_unit_object.mcap",
            mcap_of(&[
                format!(r#"{{"t":0,"wrist":{W},"joints":{{}},"object":{W}}}"#),
                format!(r#"{{"t":1,"wrist":{W},"joints":{{}},"object":{}}}"#, unit("1.5")),
            ]),
            vec!["frame 1", "`object`", "unit quaternion"],
        ),
        (
            "duplicate_t.mcap",
            two(msg("0.0", r#"{"if_j0":1}"#)),
            vec!["frame 1", "frame 0", "`t`", "strictly increasing"],
        ),
        (
            "no_frames.mcap",
            write_mcap(&McapSpec { noise_topic: false, ..Default::default() }),
            vec!["/dextrain/reference", "at least 1 frame"],
        ),
        (
            "joint_sets_differ.mcap",
            two(msg("1", r#"{"if_j1":1}"#)),
            vec!["frame 1", "`joints`", "\"if_j0\"", "\"if_j1\""],
        ),
        (
            "tips_in_some.mcap",
            two(format!(
                r#"{{"t":1,"wrist":{W},"joints":{{"if_j0":1}},"fingertips":{{"tip":{{"x":0,"y":0,"z":0}}}}}}"#
            )),
            vec!["frame 1", "`fingertips`", "every frame or in none"],
        ),
        (
            "tip_missing_z.mcap",
            two(format!(r#"{{"t":1,"wrist":{W},"joints":{{"if_j0":1}},"fingertips":{{"tip":{{"x":0,"y":0}}}}}}"#)),
            vec!["frame 1", "`fingertips.tip.z`", "missing"],
        ),
        (
            "object_in_some.mcap",
            two(format!(r#"{{"t":1,"wrist":{W},"joints":{{"if_j0":1}},"object":{W}}}"#)),
            vec!["frame 1", "`object`", "every frame or in none"],
        ),
        (
            "null_object.mcap",
            two(format!(r#"{{"t":1,"wrist":{W},"joints":{{"if_j0":1}},"object":null}}"#)),
            vec!["frame 1", "`object`", "null"],
        ),
        (
            "unknown_key.mcap",
            two(format!(r#"{{"t":1,"wrist":{W},"joints":{{"if_j0":1}},"wirst":{W}}}"#)),
            vec!["frame 1", "`wirst`", "unknown key"],
        ),
        (
            "unknown_pose_key.mcap",
            two(format!(r#"{{"t":1,"wrist":{},"joints":{{"if_j0":1}}}}"#, W.replace("qw", "w"))),
            vec!["frame 1", "`wrist.w`", "unknown key"],
        ),
        ("duplicate_key.mcap", two(msg("1", r#"{"if_j0":1,"if_j0":2}"#)), vec!["frame 1", "duplicate key", "if_j0"]),
        ("bad_name.mcap", two(msg("1", r#"{"if j0":1}"#)), vec!["frame 1", "`joints`", "\"if j0\""]),
        ("not_json.mcap", two("{\"t\": 1,".to_string()), vec!["frame 1", "invalid JSON"]),
        ("not_object.mcap", two("[1, 2]".to_string()), vec!["frame 1", "message", "array"]),
        (
            "version_2.mcap",
            write_mcap(&McapSpec {
                metadata: Some(BTreeMap::from([("format_version".into(), "2".into())])),
                messages: vec![(0, ok0.clone())],
                ..Default::default()
            }),
            vec!["format_version", "\"2\""],
        ),
        (
            "cbor.mcap",
            write_mcap(&McapSpec { encoding: "cbor", messages: vec![(0, ok0.clone())], ..Default::default() }),
            vec!["frame 0", "message encoding", "\"cbor\""],
        ),
        ("empty.mcap", Vec::new(), vec!["empty file"]),
        ("garbage.mcap", b"this is not an mcap file at all".to_vec(), vec!["MCAP"]),
    ];
    for (name, bytes, needles) in &cases {
        load_err(d, name, bytes, needles);
    }

    // invalid UTF-8 inside a message (uncompressed, so the text can be found and broken)
    let mut bad = write_mcap(&McapSpec { compression: None, messages: vec![(0, ok0.clone())], ..Default::default() });
    let at = bad.windows(5).position(|w| w == b"if_j0").unwrap();
    bad[at] = 0xff;
    load_err(d, "bad_utf8.mcap", &bad, &["frame 0", "UTF-8"]);
}

#[test]
fn bad_csv_inputs_give_one_line_errors_naming_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let h = "t,wrist_x,wrist_y,wrist_z,wrist_qx,wrist_qy,wrist_qz,wrist_qw,joint:if_j0";
    let row0 = "0,0,0,0,0,0,0,1,0.1";
    let csv = |rows: &[&str]| format!("{h}\n{row0}\n{}\n", rows.join("\n")).into_bytes();
    let cases: Vec<(&str, Vec<u8>, Vec<&str>)> = vec![
        ("empty.csv", Vec::new(), vec!["empty file"]),
        ("blank.csv", b"\n\n# only a comment\n".to_vec(), vec!["empty file"]),
        ("header_only.csv", format!("{h}\n").into_bytes(), vec!["at least 1 frame"]),
        ("short_row.csv", csv(&["1,0,0,0,0,0,0,1"]), vec!["line 3", "9 columns", "got 8"]),
        ("long_row.csv", csv(&["1,0,0,0,0,0,0,1,0,7"]), vec!["line 3", "9 columns", "got 10"]),
        (
            "unknown_column.csv",
            format!("{h},elbow\n{row0},1\n").into_bytes(),
            vec!["line 1", "\"elbow\"", "unknown column"],
        ),
        (
            "missing_wrist.csv",
            format!("{}\n0,0,0,0,0,0,0.1\n", h.replace("wrist_qw,", "")).into_bytes(),
            vec!["line 1", "`wrist_qw`", "missing column"],
        ),
        ("missing_t.csv", format!("{}\n0,0,0,0,0,0,1,0.1\n", &h[2..]).into_bytes(), vec!["`t`", "missing column"]),
        (
            "partial_object.csv",
            format!("{h},object_x,object_y,object_z\n{row0},0,0,0\n").into_bytes(),
            vec!["line 1", "`object_qx`", "all 7"],
        ),
        (
            "partial_tip.csv",
            format!("{h},tip:th:x,tip:th:y\n{row0},0,0\n").into_bytes(),
            vec!["line 1", "`tip:th:z`", "missing column"],
        ),
        ("bad_tip_axis.csv", format!("{h},tip:th:w\n{row0},0\n").into_bytes(), vec!["line 1", "tip:th:w", "x, y or z"]),
        (
            "duplicate_column.csv",
            format!("{h},joint:if_j0\n{row0},1\n").into_bytes(),
            vec!["line 1", "joint:if_j0", "duplicate"],
        ),
        (
            "empty_column.csv",
            format!("{h},\n{row0},1\n").into_bytes(),
            vec!["line 1", "column 10", "empty column name"],
        ),
        ("text_cell.csv", csv(&["1,0,0,0,0,0,0,1,abc"]), vec!["line 3", "`joint:if_j0`", "a number", "\"abc\""]),
        ("empty_cell.csv", csv(&["1,,0,0,0,0,0,1,0"]), vec!["line 3", "`wrist_x`", "empty cell"]),
        ("nan_cell.csv", csv(&["1,0,0,0,0,0,0,1,NaN"]), vec!["line 3", "`joint:if_j0`", "finite"]),
        ("inf_t.csv", csv(&["inf,0,0,0,0,0,0,1,0"]), vec!["line 3", "`t`", "finite"]),
        ("negative_t.csv", csv(&["-1,0,0,0,0,0,0,1,0"]), vec!["line 3", "`t`", "≥ 0"]),
        ("non_unit_quat.csv", csv(&["1,0,0,0,0,0,0,2,0"]), vec!["line 3", "`wrist_qw`", "unit quaternion"]),
        ("duplicate_t.csv", csv(&["0.5,0,0,0,0,0,0,1,0", "0,0,0,0,0,0,0,1,0"]), vec!["line 4", "line 2", "column `t`"]),
        (
            "object_bad_quat.csv",
            format!("{h},object_x,object_y,object_z,object_qx,object_qy,object_qz,object_qw\n{row0},0,0,0,0,0,0,0\n")
                .into_bytes(),
            vec!["line 2", "`object_qw`", "unit quaternion"],
        ),
        ("not_utf8.csv", vec![b't', 0xff, b'\n'], vec!["UTF-8"]),
        ("bad_joint_name.csv", format!("{h},joint:\n{row0},1\n").into_bytes(), vec!["line 1", "\"joint:\""]),
    ];
    for (name, bytes, needles) in &cases {
        load_err(d, name, bytes, needles);
    }
    let msg = load_err(d, "reference.txt", b"whatever", &["`.mcap` or `.csv`", "`.txt`"]);
    assert!(msg.starts_with(&d.join("reference.txt").display().to_string()));
    load_err(d, "reference", b"whatever", &["`.mcap` or `.csv`"]);
    let missing = format!("{:#}", Trajectory::load(d.join("nope.csv")).unwrap_err());
    assert!(missing.contains("nope.csv") && !missing.contains('\n'), "{missing}");
}

#[test]
fn saving_an_invalid_trajectory_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let mut traj = example_expected();
    traj.frames[2].t = 0.5;
    for name in ["bad.mcap", "bad.csv"] {
        let e = format!("{:#}", traj.save(dir.path().join(name)).unwrap_err());
        assert!(e.contains(name) && e.contains("frame 2") && e.contains("`t`") && !e.contains('\n'), "{e}");
    }
    let mut traj = example_expected();
    traj.frames[1].joints.pop();
    assert!(format!("{:#}", traj.to_csv_string().unwrap_err()).contains("`joints`"));
    let mut traj = example_expected();
    traj.joint_names[0] = "if j0".into();
    assert!(format!("{:#}", traj.to_mcap_bytes().unwrap_err()).contains("\"if j0\""));
    let mut traj = example_expected();
    traj.frames[0].object = Some(Pose::IDENTITY);
    assert!(format!("{:#}", traj.to_mcap_bytes().unwrap_err()).contains("`object`"));
    assert!(Trajectory::default().to_mcap_bytes().is_err());
}

/// Finding 1 (fuzzing review): a huge last time made `replay` allocate terabytes (1e9), run for
/// days (1e6) or wrap to "no frames" (1e18). A time beyond an hour is an error at load, naming the
/// file and the frame (MCAP) or line (CSV) and the field, in both formats and in memory.
#[test]
fn a_time_beyond_an_hour_is_an_error_naming_file_and_frame() {
    use dextrain::traj::MAX_DURATION_S;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let ok0 = msg("0", r#"{"if_j0":0.1}"#);
    for t in ["1e6", "1e9", "1e18", "3600.001"] {
        let bytes = mcap_of(&[ok0.clone(), msg(t, r#"{"if_j0":0.2}"#)]);
        load_err(d, "long.mcap", &bytes, &["frame 1", "`t`", "≤ 3600 s", t]);
        let csv = format!("t,wrist_x,wrist_y,wrist_z,wrist_qx,wrist_qy,wrist_qz,wrist_qw,joint:if_j0
0,0,0,0,0,0,0,1,0
{t},0,0,0,0,0,0,1,0
");
        load_err(d, "long.csv", csv.as_bytes(), &["line 3", "column `t`", "≤ 3600 s", t]);
    }
    // exactly an hour still loads
    let bytes = mcap_of(&[ok0.clone(), msg("3600", r#"{"if_j0":0.2}"#)]);
    std::fs::write(d.join("hour.mcap"), bytes).unwrap();
    assert_eq!(Trajectory::load(d.join("hour.mcap")).unwrap().duration(), MAX_DURATION_S);
    // in memory: validate (savers, replay, the bank) says the same
    let mut traj = example_expected();
    traj.frames[2].t = 1e9;
    let e = format!("{:#}", traj.validate().unwrap_err());
    assert!(e.contains("frame 2") && e.contains("`t`") && e.contains("3600"), "{e}");
}

/// Finding 5 (fuzzing review): `object_y = 3.4e38` loaded and put `null` (a NaN) in replay's report.
/// Positions beyond ±100 m and joint values beyond ±100 rad are errors naming the file, the frame
/// or line and the field; values just inside the bounds load.
#[test]
fn values_a_simulation_cannot_hold_are_errors_naming_file_frame_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let h = "t,wrist_x,wrist_y,wrist_z,wrist_qx,wrist_qy,wrist_qz,wrist_qw,joint:if_j0,tip:th:x,tip:th:y,tip:th:z,object_x,object_y,object_z,object_qx,object_qy,object_qz,object_qw";
    let row0 = "0,0,0,0.3,0,0,0,1,0.1,0,0,0.2,0,0,0.03,0,0,0,1";
    let csv = |row: &str| format!("{h}
{row0}
{row}
").into_bytes();
    let cases: Vec<(&str, Vec<u8>, Vec<&str>)> = vec![
        ("object_y.csv", csv("1,0,0,0.3,0,0,0,1,0.1,0,0,0.2,0,3.4e38,0.03,0,0,0,1"), vec!["line 3", "`object_y`", "±100 m", "3.4e38"]),
        ("wrist_x.csv", csv("1,-100.5,0,0.3,0,0,0,1,0.1,0,0,0.2,0,0,0.03,0,0,0,1"), vec!["line 3", "`wrist_x`", "±100 m"]),
        ("tip.csv", csv("1,0,0,0.3,0,0,0,1,0.1,0,0,1e30,0,0,0.03,0,0,0,1"), vec!["line 3", "`tip:th:z`", "±100 m"]),
        ("joint.csv", csv("1,0,0,0.3,0,0,0,1,1e5,0,0,0.2,0,0,0.03,0,0,0,1"), vec!["line 3", "`joint:if_j0`", "±100 rad"]),
    ];
    for (name, bytes, needles) in &cases {
        load_err(d, name, bytes, needles);
    }
    let ok0 = msg("0", r#"{"if_j0":0.1}"#);
    let obj = |y: &str| format!(r#"{{"t":1,"wrist":{W},"joints":{{"if_j0":0.1}},"object":{{"x":0,"y":{y},"z":0,"qx":0,"qy":0,"qz":0,"qw":1}}}}"#);
    let ok_obj = format!(r#"{{"t":0,"wrist":{W},"joints":{{"if_j0":0.1}},"object":{{"x":0,"y":0,"z":0,"qx":0,"qy":0,"qz":0,"qw":1}}}}"#);
    load_err(d, "object.mcap", &mcap_of(&[ok_obj.clone(), obj("3.4e38")]), &["frame 1", "`object.y`", "±100 m"]);
    load_err(d, "joint.mcap", &mcap_of(&[ok0.clone(), msg("1", r#"{"if_j0":-250}"#)]), &["frame 1", "`joints.if_j0`", "±100 rad"]);
    let tips = format!(r#"{{"t":1,"wrist":{W},"joints":{{"if_j0":0.1}},"fingertips":{{"th":{{"x":0,"y":0,"z":-1e3}}}}}}"#);
    let tips0 = format!(r#"{{"t":0,"wrist":{W},"joints":{{"if_j0":0.1}},"fingertips":{{"th":{{"x":0,"y":0,"z":0}}}}}}"#);
    load_err(d, "tips.mcap", &mcap_of(&[tips0, tips]), &["frame 1", "`fingertips.th.z`", "±100 m"]);
    // just inside the bounds loads
    std::fs::write(d.join("edge.mcap"), mcap_of(&[ok_obj, obj("99.5")])).unwrap();
    assert_eq!(Trajectory::load(d.join("edge.mcap")).unwrap().frames[1].object.unwrap().pos.y, 99.5);
    // in memory too
    let mut traj = example_expected();
    traj.frames[1].wrist.pos.z = 3.4e38;
    let e = format!("{:#}", traj.validate().unwrap_err());
    assert!(e.contains("frame 1") && e.contains("`wrist.z`") && e.contains("±100 m"), "{e}");
    let mut traj = example_expected();
    traj.frames[0].joints[1] = 1e4;
    let e = format!("{:#}", traj.validate().unwrap_err());
    assert!(e.contains("frame 0") && e.contains("`joints.th_j0`") && e.contains("±100 rad"), "{e}");
}

/// Truncations, bit flips and random edits of valid files give errors or trajectories, never panics.
#[test]
fn mangled_files_never_panic() {
    let traj = awkward_trajectory(true, true);
    let mut rng = Rng(99);
    for compression in [None, Some(mcap::Compression::Zstd), Some(mcap::Compression::Lz4)] {
        let messages: Vec<(u64, String)> = traj
            .to_mcap_bytes()
            .ok()
            .and_then(|b| {
                mcap::MessageStream::new(&b).ok().map(|s| {
                    s.map(|m| m.unwrap())
                        .map(|m| (m.log_time, String::from_utf8(m.data.into_owned()).unwrap()))
                        .collect()
                })
            })
            .unwrap();
        let bytes = write_mcap(&McapSpec {
            compression,
            chunk_size: Some(1000),
            messages: messages.clone(),
            ..Default::default()
        });
        assert_eq!(Trajectory::from_mcap_bytes(&bytes, "f.mcap").unwrap(), traj);
        for cut in (0..bytes.len()).step_by(7) {
            let _ = Trajectory::from_mcap_bytes(&bytes[..cut], "f.mcap");
        }
        // Unchunked (so compression does not apply), a cut can fall between two messages: that
        // must not pass for a shorter reference. Every cut gives an error or (in the summary,
        // after the data) the whole thing.
        if compression.is_none() {
            let unchunked = write_mcap(&McapSpec { chunked: false, messages: messages.clone(), ..Default::default() });
            for cut in 0..unchunked.len() {
                if let Ok(t) = Trajectory::from_mcap_bytes(&unchunked[..cut], "f.mcap") {
                    assert_eq!(t, traj, "cut at {cut} of {}", unchunked.len());
                }
            }
        }
        for _ in 0..300 {
            let mut b = bytes.clone();
            for _ in 0..1 + rng.next_u64() % 3 {
                let i = (rng.next_u64() % b.len() as u64) as usize;
                b[i] ^= 1 << (rng.next_u64() % 8);
            }
            let _ = Trajectory::from_mcap_bytes(&b, "f.mcap");
        }
    }
    // JSON messages: every truncation and some byte substitutions
    let m = traj.to_mcap_bytes().unwrap();
    let first = mcap::MessageStream::new(&m).unwrap().next().unwrap().unwrap();
    let text = String::from_utf8(first.data.into_owned()).unwrap();
    let mut msgs = Vec::new();
    for cut in 0..text.len() {
        msgs.push(text[..cut].to_string());
    }
    let specials = b"{}[]\":,\\ -+.eE0u\xc3";
    for _ in 0..400 {
        let mut b = text.clone().into_bytes();
        let i = (rng.next_u64() % b.len() as u64) as usize;
        b[i] = specials[(rng.next_u64() % specials.len() as u64) as usize];
        msgs.push(String::from_utf8_lossy(&b).into_owned());
    }
    for chunk in msgs.chunks(50) {
        let _ = Trajectory::from_mcap_bytes(&mcap_of(chunk), "j.mcap");
        for one in chunk {
            let _ = Trajectory::from_mcap_bytes(&mcap_of(std::slice::from_ref(one)), "j.mcap");
        }
    }
    // CSV: truncations and substitutions
    let csv = traj.to_csv_string().unwrap();
    for cut in (0..csv.len()).step_by(3) {
        let _ = Trajectory::from_csv_str(&csv[..cut], "c.csv");
    }
    for _ in 0..500 {
        let mut b = csv.clone().into_bytes();
        let i = (rng.next_u64() % b.len() as u64) as usize;
        let subst = b",:\n\r-e.0 #x";
        b[i] = subst[(rng.next_u64() % subst.len() as u64) as usize];
        let _ = Trajectory::from_csv_str(&String::from_utf8_lossy(&b), "c.csv");
    }
    // deep nesting
    let deep = format!(r#"{{"t":0,"wrist":{W},"joints":{}}}"#, "[".repeat(100_000));
    let e = Trajectory::from_mcap_bytes(&mcap_of(&[deep]), "d.mcap").unwrap_err();
    assert!(format!("{e}").contains("nesting"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// Interpolation
// ---------------------------------------------------------------------------------------------

fn two_frame(rot0: Quat, rot1: Quat) -> Trajectory {
    Trajectory {
        joint_names: vec!["a".into(), "b".into()],
        fingertip_names: vec!["tip".into()],
        frames: vec![
            Keyframe {
                t: 1.0,
                wrist: Pose::new(Vec3::new(0.0, 0.0, 0.0), rot0),
                joints: vec![0.0, -1.0],
                fingertips: Some(vec![Vec3::new(1.0, 1.0, 1.0)]),
                object: Some(Pose::new(Vec3::new(0.0, 0.0, 0.1), rot1)),
            },
            Keyframe {
                t: 3.0,
                wrist: Pose::new(Vec3::new(1.0, 2.0, -4.0), rot1),
                joints: vec![1.0, 1.0],
                fingertips: Some(vec![Vec3::new(3.0, 1.0, -1.0)]),
                object: Some(Pose::new(Vec3::new(1.0, 0.0, 0.1), rot0)),
            },
        ],
        object_name: None,
    }
}

#[test]
fn sample_at_keyframes_returns_them_exactly() {
    let traj = awkward_trajectory(true, true);
    for f in &traj.frames {
        assert_eq!(&traj.sample(f.t), f);
    }
}

#[test]
fn sample_midpoint_is_linear_and_slerp() {
    let axis = Vec3::new(1.0, -2.0, 0.5).normalize();
    let r0 = Quat::from_axis_angle(axis, 0.3);
    let r1 = Quat::from_axis_angle(axis, 0.3 + FRAC_PI_2);
    let traj = two_frame(r0, r1);
    let mid = traj.sample(2.0);
    assert_eq!(mid.t, 2.0);
    assert!(mid.wrist.pos.abs_diff_eq(Vec3::new(0.5, 1.0, -2.0), 1e-6));
    assert_eq!(mid.joints, [0.5, 0.0]);
    assert!(mid.fingertips.unwrap()[0].abs_diff_eq(Vec3::new(2.0, 1.0, 0.0), 1e-6));
    // 90° apart: the midpoint is 45° past r0 about the same axis
    let expected = Quat::from_axis_angle(axis, 0.3 + FRAC_PI_2 / 2.0);
    assert_quat_close(mid.wrist.rot, expected, 1e-6);
    let (ax, angle) = (r0.inverse() * mid.wrist.rot).to_axis_angle();
    assert!((angle - FRAC_PI_2 / 2.0).abs() < 1e-5, "angle {angle}");
    assert!(ax.abs_diff_eq(axis, 1e-5), "axis {ax}");
    assert!((mid.wrist.rot.length() - 1.0).abs() < 1e-6);
    let obj = mid.object.unwrap();
    assert!(obj.pos.abs_diff_eq(Vec3::new(0.5, 0.0, 0.1), 1e-6));
    assert_quat_close(obj.rot, expected, 1e-6);
    // a quarter of the way: linear in time
    let q = traj.sample(1.5);
    assert_eq!(q.joints, [0.25, -0.5]);
    assert_quat_close(q.wrist.rot, Quat::from_axis_angle(axis, 0.3 + FRAC_PI_2 / 4.0), 1e-6);
}

#[test]
fn slerp_takes_the_shortest_arc() {
    let axis = Vec3::Z;
    let r0 = Quat::from_axis_angle(axis, 0.0);
    // the same rotation as +90°, stored with the opposite sign
    let r1 = -Quat::from_axis_angle(axis, FRAC_PI_2);
    let mid = two_frame(r0, r1).sample(2.0);
    let v = mid.wrist.rot * Vec3::X;
    let e = Quat::from_axis_angle(axis, FRAC_PI_2 / 2.0) * Vec3::X;
    assert!(v.abs_diff_eq(e, 1e-6), "{v} vs {e}");
}

#[test]
fn sample_clamps_outside_the_range() {
    let traj = two_frame(Quat::IDENTITY, Quat::from_rotation_z(1.0));
    for t in [-5.0, 0.0, 0.999, f64::NEG_INFINITY, f64::NAN] {
        let f = traj.sample(t);
        assert_eq!(Keyframe { t: 1.0, ..f }, traj.frames[0], "t {t}");
    }
    for t in [3.0, 3.5, 1e9, f64::INFINITY] {
        let f = traj.sample(t);
        assert_eq!(f.t, t);
        assert_eq!(Keyframe { t: 3.0, ..f }, traj.frames[1], "t {t}");
    }
    let empty = Trajectory { joint_names: vec!["a".into()], ..Default::default() };
    let f = empty.sample(1.0);
    assert_eq!(f.joints, [0.0]);
    assert_eq!(f.wrist, Pose::IDENTITY);
}

#[test]
fn resample_lengths_and_endpoints() {
    let mut traj = example_expected(); // keyframes at 0, 0.5, 1
    let cases: [(f64, &[f64]); 5] = [
        (0.25, &[0.0, 0.25, 0.5, 0.75, 1.0]),
        (0.3, &[0.0, 0.3, 0.6, 0.8999999999999999, 1.0]),
        (0.5, &[0.0, 0.5, 1.0]),
        (2.0, &[0.0, 1.0]),
        (1.0 / 3.0, &[0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0]),
    ];
    for (dt, times) in cases {
        let r = traj.resample(dt);
        let got: Vec<f64> = r.frames.iter().map(|f| f.t).collect();
        assert_eq!(got, times, "dt {dt}");
        assert_eq!(r.joint_names, traj.joint_names);
        assert_eq!(r.frames.first().unwrap().joints, traj.frames[0].joints);
        assert_eq!(r.frames.last().unwrap(), traj.frames.last().unwrap());
        r.validate().unwrap();
    }
    let r = traj.resample(0.01);
    assert_eq!(r.frames.len(), 101);
    assert_eq!(r.frames[50], traj.frames[1]);
    assert!((r.frames[25].joints[0] - 0.2).abs() < 1e-6);
    // 0.1 * 3 overshoots 0.3 in floating point: no near-duplicate last frame
    traj.frames.truncate(1);
    traj.frames[0].t = 0.3;
    let got: Vec<f64> = traj.resample(0.1).frames.iter().map(|f| f.t).collect();
    assert_eq!(got, [0.0, 0.1, 0.2, 0.3]);
    assert_eq!(Trajectory::default().resample(0.1).frames.len(), 0);
}

#[test]
fn joint_map_maps_names_and_rejects_unknown_joints() {
    let traj = example_expected(); // if_j0, th_j0
    let hand: Vec<String> = ["wrist_roll", "th_j0", "mf_j0", "if_j0"].map(String::from).to_vec();
    assert_eq!(traj.joint_map(&hand).unwrap(), [None, Some(1), None, Some(0)]);
    let hand: Vec<String> = ["if_j0", "mf_j0"].map(String::from).to_vec();
    let e = format!("{:#}", traj.joint_map(&hand).unwrap_err());
    assert!(e.contains("\"th_j0\"") && !e.contains("\"if_j0\" not") && !e.contains('\n'), "{e}");
}

#[test]
fn docs_worked_example_midpoint_is_as_described() {
    let traj = Trajectory::load(data_dir().join("example.csv")).unwrap();
    let f = traj.sample(0.25);
    assert!(f.wrist.pos.abs_diff_eq(Vec3::new(0.025, 0.0, 0.25), 1e-6), "{}", f.wrist.pos);
    assert_quat_close(f.wrist.rot, Quat::from_rotation_z(22.5f32.to_radians()), 1e-6);
    assert!((f.joints[0] - 0.2).abs() < 1e-6 && (f.joints[1] - 0.1).abs() < 1e-6, "{:?}", f.joints);
}

// ---------------------------------------------------------------------------------------------
// Docs
// ---------------------------------------------------------------------------------------------

/// docs/references.md (section "Reference trajectory format") shows the schema, the example files and the Python
/// writer verbatim; this keeps them true.
#[test]
fn docs_match_the_code_and_the_fixtures() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let doc = std::fs::read_to_string(root.join("docs/references.md")).unwrap();
    let dir = data_dir();
    let schema_file = std::fs::read_to_string(dir.join("reference_frame.schema.json")).unwrap();
    assert_eq!(schema_file, REFERENCE_JSON_SCHEMA);
    for file in ["reference_frame.schema.json", "example.csv", "example_messages.jsonl", "write_example.py"] {
        let text = std::fs::read_to_string(dir.join(file)).unwrap();
        assert!(doc.contains(&text), "docs/references.md (Reference trajectory format) does not show tests/data/traj/{file} verbatim");
    }
    for s in [REFERENCE_TOPIC, REFERENCE_SCHEMA_NAME, REFERENCE_METADATA_NAME] {
        assert!(doc.contains(s), "{s}");
    }
    // the full example message in the docs reads
    let start = doc.find("```json\n{\n  \"t\": 0.5").expect("example message block") + "```json\n".len();
    let block = &doc[start..start + doc[start..].find("```").unwrap()];
    let traj = Trajectory::from_mcap_bytes(&mcap_of(&[block.to_string()]), "doc.mcap").unwrap();
    assert_eq!(traj.fingertip_names, ["if_tip", "th_tip"]);
    assert!(traj.has_object());
    // the schema is valid JSON with the draft named
    let v: serde_json::Value = serde_json::from_str(REFERENCE_JSON_SCHEMA).unwrap();
    assert_eq!(v["$schema"], "https://json-schema.org/draft/2020-12/schema");
    assert_eq!(v["title"], REFERENCE_SCHEMA_NAME);
}
