//! Rollout recordings (src/record.rs): write a small rollout, read it back with the `mcap` crate, and
//! with an independent reader (the Python `mcap` package, tests/read_rollout.py).

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;

use glam::{Quat, Vec3};
use serde_json::Value;

use dextrain::geom::{ObjectShape, Pose};
use dextrain::hand::HandModel;
use dextrain::record::{
    ContactKind, ObjectPart, ContactRecord, RolloutFrame, RolloutMeta, RolloutWriter, TOPIC_CONTACTS, TOPIC_HAND_STATE,
    TOPIC_POSES, TOPIC_SCENE, TOPIC_TF,
};

const N_FRAMES: usize = 20;
const DT: f32 = 0.02;

/// A palm (box) and one finger (capsule) on a revolute joint, with a fingertip.
fn small_hand() -> HandModel {
    super::common::tiny_hand()
}

fn meta(object: ObjectShape) -> RolloutMeta {
    parts_meta(vec![ObjectPart { shape: object, pose: Pose::IDENTITY, triangles: Vec::new() }])
}

fn parts_meta(object: Vec<ObjectPart>) -> RolloutMeta {
    RolloutMeta {
        hand: small_hand(),
        object,
        dt: DT,
        info: serde_json::json!({ "command": "dextrain test", "seed": 7 }),
    }
}

fn box_meta() -> RolloutMeta {
    meta(ObjectShape::Box { half_extents: [0.03, 0.02, 0.025] })
}

/// Frame k: the finger bends, the object slides and turns; a hand–object contact with force
/// (0, 0, k) on every third frame; an object–table contact on every frame (zero force on frame 0);
/// a reference pose on even frames.
fn frame(hand: &HandModel, k: usize) -> RolloutFrame {
    let q = 0.05 * k as f32;
    let wrist = Pose::new(Vec3::new(0.0, -0.1, 0.2 + 0.001 * k as f32), Quat::from_rotation_x(0.3));
    let links = hand.forward_kinematics(&[q]).iter().map(|p| wrist.mul(p)).collect();
    let object = Pose::new(Vec3::new(0.01 * k as f32, 0.0, 0.025), Quat::from_rotation_z(0.1 * k as f32));
    let mut contacts = Vec::new();
    if k.is_multiple_of(3) {
        contacts.push(ContactRecord {
            kind: ContactKind::HandObject,
            index: 1,
            pos: object.pos + Vec3::new(0.0, 0.0, 0.025),
            normal: Vec3::Z,
            depth: 0.001,
            force: Vec3::new(0.0, 0.0, k as f32),
        });
    }
    contacts.push(ContactRecord {
        kind: ContactKind::ObjectTable,
        index: 2,
        pos: Vec3::new(object.pos.x, 0.0, 0.0),
        normal: Vec3::Z,
        depth: 0.0005,
        force: if k == 0 { Vec3::ZERO } else { Vec3::new(0.1, 0.0, 2.5) },
    });
    RolloutFrame {
        t: k as f64 * DT as f64,
        joint_pos: vec![q],
        joint_vel: vec![0.05 / DT],
        joint_target: vec![q + 0.1],
        wrist,
        object,
        links,
        contacts,
        object_ref: k.is_multiple_of(2).then(|| Pose::new(Vec3::new(0.1, 0.0, 0.025), Quat::IDENTITY)),
        // an overlay of two polylines (three and two points) on odd frames
        overlay: if k % 2 == 1 { vec![vec![Vec3::ZERO, Vec3::X * 0.1, Vec3::new(0.1, 0.1, 0.0)], vec![Vec3::Z * 0.2, Vec3::new(0.0, 0.0, 0.3)]] } else { Vec::new() },
    }
}

fn frames(hand: &HandModel) -> Vec<RolloutFrame> {
    (0..N_FRAMES).map(|k| frame(hand, k)).collect()
}

fn write_file(path: &Path, meta: &RolloutMeta, frames: &[RolloutFrame]) {
    let mut w = RolloutWriter::create(path, meta).unwrap();
    for f in frames {
        w.write_frame(f).unwrap();
    }
    assert_eq!(w.frames_written(), frames.len() as u64);
    w.finish().unwrap();
}

struct Msg {
    sequence: u32,
    log_time: u64,
    json: Value,
}

struct Read {
    /// topic -> (schema name, schema encoding, message encoding, schema JSON)
    channels: BTreeMap<String, (String, String, String, Value)>,
    messages: BTreeMap<String, Vec<Msg>>,
    /// name -> key/values
    metadata: BTreeMap<String, BTreeMap<String, String>>,
}

fn read(bytes: &[u8]) -> Read {
    let mut channels = BTreeMap::new();
    let mut messages: BTreeMap<String, Vec<Msg>> = BTreeMap::new();
    for m in mcap::MessageStream::new(bytes).unwrap() {
        let m = m.unwrap();
        let ch = &m.channel;
        let schema = ch.schema.as_ref().expect("every channel has a schema");
        let schema_json: Value = serde_json::from_slice(&schema.data).expect("schema is JSON");
        channels.entry(ch.topic.clone()).or_insert_with(|| {
            (schema.name.clone(), schema.encoding.clone(), ch.message_encoding.clone(), schema_json)
        });
        assert_eq!(m.log_time, m.publish_time);
        messages.entry(ch.topic.clone()).or_default().push(Msg {
            sequence: m.sequence,
            log_time: m.log_time,
            json: serde_json::from_slice(&m.data).expect("message is JSON"),
        });
    }
    let summary = mcap::read::Summary::read(bytes).unwrap().expect("file has a summary");
    let mut metadata = BTreeMap::new();
    for idx in &summary.metadata_indexes {
        let md = mcap::read::metadata(bytes, idx).unwrap();
        metadata.insert(md.name, md.metadata);
    }
    Read { channels, messages, metadata }
}

fn f32_of(v: &Value) -> f32 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}")) as f32
}

fn entity<'a>(scene: &'a Value, id: &str) -> &'a Value {
    scene["entities"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["id"] == id)
        .unwrap_or_else(|| panic!("no scene entity {id} in {scene}"))
}

fn prim_count(e: &Value, kind: &str) -> usize {
    e[kind].as_array().unwrap_or_else(|| panic!("entity has no {kind} array")).len()
}

fn dir_entries(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

#[test]
fn rollout_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rollout.mcap");
    let meta = box_meta();
    let frames = frames(&meta.hand);
    write_file(&path, &meta, &frames);

    assert_eq!(dir_entries(dir.path()), vec!["rollout.mcap".to_string()], "no temporary file may remain");
    let bytes = std::fs::read(&path).unwrap();
    let r = read(&bytes);

    // Topics, schemas and encodings.
    let expected = [
        (TOPIC_HAND_STATE, "dextrain.HandState"),
        (TOPIC_POSES, "dextrain.Poses"),
        (TOPIC_CONTACTS, "dextrain.Contacts"),
        (TOPIC_TF, "foxglove.FrameTransforms"),
        (TOPIC_SCENE, "foxglove.SceneUpdate"),
    ];
    assert_eq!(
        r.channels.keys().cloned().collect::<BTreeSet<_>>(),
        expected.iter().map(|(t, _)| t.to_string()).collect::<BTreeSet<_>>()
    );
    for (topic, schema) in expected {
        let (name, enc, msg_enc, schema_json) = &r.channels[topic];
        assert_eq!(name, schema, "{topic}");
        assert_eq!(enc, "jsonschema", "{topic}");
        assert_eq!(msg_enc, "json", "{topic}");
        assert_eq!(schema_json["title"], schema, "{topic}");
        assert_eq!(schema_json["type"], "object", "{topic}");
        assert!(schema_json["properties"].is_object(), "{topic}");
    }

    // Counts, sequences, times.
    for (topic, _) in expected {
        let msgs = &r.messages[topic];
        assert_eq!(msgs.len(), N_FRAMES, "{topic}");
        for (k, m) in msgs.iter().enumerate() {
            assert_eq!(m.sequence, k as u32, "{topic}");
            assert_eq!(m.log_time, (frames[k].t * 1e9).round() as u64, "{topic} frame {k}");
            if k > 0 {
                assert!(m.log_time > msgs[k - 1].log_time, "{topic}: log times increase");
            }
        }
    }

    // Values of frame 7 (and contacts of frame 6).
    let k = 7;
    let hs = &r.messages[TOPIC_HAND_STATE][k].json;
    assert_eq!(hs["joint_names"], serde_json::json!(["finger_joint"]));
    assert_eq!(f32_of(&hs["position"][0]), frames[k].joint_pos[0]);
    assert_eq!(f32_of(&hs["velocity"][0]), frames[k].joint_vel[0]);
    assert_eq!(f32_of(&hs["target"][0]), frames[k].joint_target[0]);
    assert_eq!(hs["t"].as_f64().unwrap(), frames[k].t);
    assert_eq!(hs["timestamp"]["sec"], 0);
    assert_eq!(hs["timestamp"]["nsec"].as_u64().unwrap(), (frames[k].t * 1e9).round() as u64);

    let poses = &r.messages[TOPIC_POSES][k].json;
    let o = &frames[k].object;
    for (key, want) in [
        ("x", o.pos.x),
        ("y", o.pos.y),
        ("z", o.pos.z),
        ("qx", o.rot.x),
        ("qy", o.rot.y),
        ("qz", o.rot.z),
        ("qw", o.rot.w),
    ] {
        assert_eq!(f32_of(&poses["object"][key]), want, "object.{key}");
    }
    assert_eq!(f32_of(&poses["wrist"]["z"]), frames[k].wrist.pos.z);
    assert!(poses["object_ref"].is_null(), "odd frames have no reference");
    assert_eq!(f32_of(&r.messages[TOPIC_POSES][6].json["object_ref"]["x"]), 0.1);

    let contacts = r.messages[TOPIC_CONTACTS][6].json["contacts"].as_array().unwrap().clone();
    assert_eq!(contacts.len(), 2);
    assert_eq!(contacts[0]["kind"], "hand_object");
    assert_eq!(contacts[0]["index"], 1);
    assert_eq!(contacts[0]["link"], "finger");
    assert_eq!(f32_of(&contacts[0]["force"]["z"]), 6.0);
    assert_eq!(f32_of(&contacts[0]["depth"]), 0.001);
    assert_eq!(f32_of(&contacts[0]["pos"]["x"]), frames[6].contacts[0].pos.x);
    assert_eq!(contacts[1]["kind"], "object_table");
    assert!(contacts[1]["link"].is_null());
    assert_eq!(f32_of(&contacts[1]["force"]["z"]), 2.5);
    assert_eq!(r.messages[TOPIC_CONTACTS][7].json["contacts"].as_array().unwrap().len(), 1);

    // TF: world -> palm, finger, object (+ object_ref on even frames).
    for (k, m) in r.messages[TOPIC_TF].iter().enumerate() {
        let tf = m.json["transforms"].as_array().unwrap();
        let children: Vec<&str> = tf.iter().map(|t| t["child_frame_id"].as_str().unwrap()).collect();
        let mut want = vec!["palm", "finger", "object"];
        if k % 2 == 0 {
            want.push("object_ref");
        }
        assert_eq!(children, want, "frame {k}");
        for t in tf {
            assert_eq!(t["parent_frame_id"], "world");
            assert_eq!(t["timestamp"], r.messages[TOPIC_HAND_STATE][k].json["timestamp"]);
        }
        let finger = &tf[1];
        assert_eq!(f32_of(&finger["translation"]["z"]), frames[k].links[1].pos.z);
        assert_eq!(f32_of(&finger["rotation"]["w"]), frames[k].links[1].rot.normalize().w);
    }

    // Scene: primitive counts per entity.
    for (k, m) in r.messages[TOPIC_SCENE].iter().enumerate() {
        let scene = &m.json;
        let palm = entity(scene, "hand/palm");
        assert_eq!(palm["frame_id"], "palm");
        assert_eq!((prim_count(palm, "cubes"), prim_count(palm, "spheres"), prim_count(palm, "cylinders")), (1, 0, 0));
        assert_eq!(f32_of(&palm["cubes"][0]["size"]["x"]), 0.08);
        let finger = entity(scene, "hand/finger");
        assert_eq!(finger["frame_id"], "finger");
        assert_eq!(
            (prim_count(finger, "cubes"), prim_count(finger, "spheres"), prim_count(finger, "cylinders")),
            (0, 2, 1),
            "capsule = 1 cylinder + 2 spheres"
        );
        let cyl = &finger["cylinders"][0];
        assert_eq!(f32_of(&cyl["size"]["z"]), 0.04);
        assert_eq!(f32_of(&cyl["size"]["x"]), 0.02);
        assert_eq!(f32_of(&cyl["bottom_scale"]), 1.0);
        let sphere_z: Vec<f32> =
            finger["spheres"].as_array().unwrap().iter().map(|s| f32_of(&s["pose"]["position"]["z"])).collect();
        assert!((sphere_z[0] - 0.0).abs() < 1e-6 && (sphere_z[1] - 0.04).abs() < 1e-6, "{sphere_z:?}");
        let obj = entity(scene, "object");
        assert_eq!(obj["frame_id"], "object");
        assert_eq!(prim_count(obj, "cubes"), 1);
        assert_eq!(f32_of(&obj["cubes"][0]["size"]["z"]), 0.05);
        let table = entity(scene, "table");
        assert_eq!(table["frame_id"], "world");
        assert_eq!(prim_count(table, "cubes"), 1);
        assert!((f32_of(&table["cubes"][0]["pose"]["position"]["z"]) + 0.005).abs() < 1e-6);
        for e in scene["entities"].as_array().unwrap() {
            assert_eq!(e["frame_locked"], true);
            assert_eq!(e["lifetime"], serde_json::json!({ "sec": 0, "nsec": 0 }));
            for key in ["metadata", "arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models"]
            {
                assert!(e[key].is_array(), "entity {} lacks {key}", e["id"]);
            }
        }
        let has_ref = scene["entities"].as_array().unwrap().iter().any(|e| e["id"] == "object_ref");
        assert_eq!(has_ref, k % 2 == 0, "frame {k}");
        let deleted: Vec<&str> =
            scene["deletions"].as_array().unwrap().iter().map(|d| d["id"].as_str().unwrap()).collect();
        assert_eq!(deleted, if k % 2 == 0 { vec![] } else { vec!["object_ref"] }, "frame {k}");
        if has_ref {
            let ghost = entity(scene, "object_ref");
            assert_eq!(ghost["frame_id"], "object_ref");
            assert!(f32_of(&ghost["cubes"][0]["color"]["a"]) < 1.0);
        }
        // the overlay on odd frames: a line strip per polyline through its points, a dot at each
        let has_overlay = scene["entities"].as_array().unwrap().iter().any(|e| e["id"] == "overlay");
        assert_eq!(has_overlay, k % 2 == 1, "frame {k}");
        if has_overlay {
            let o = entity(scene, "overlay");
            assert_eq!((o["frame_id"].as_str(), prim_count(o, "lines"), prim_count(o, "spheres")), (Some("world"), 2, 5), "frame {k}");
            let strip = &o["lines"][0];
            assert_eq!((strip["type"].as_u64(), strip["points"].as_array().unwrap().len()), (Some(0), 3));
            assert_eq!(f32_of(&strip["points"][2]["y"]), 0.1);
            assert_eq!(f32_of(&o["lines"][1]["points"][1]["z"]), 0.3);
        }
        let c = entity(scene, "contacts");
        let n_contacts = frames[k].contacts.len();
        let n_forces = frames[k].contacts.iter().filter(|c| c.force.length() > 0.0).count();
        assert_eq!(prim_count(c, "spheres"), n_contacts, "frame {k}");
        assert_eq!(prim_count(c, "arrows"), n_forces, "frame {k}");
        if k == 6 {
            let a = &c["arrows"][0];
            // force (0, 0, 6): 0.12 m shaft, pointing up (+x rotated onto +z).
            assert!((f32_of(&a["shaft_length"]) - 0.12).abs() < 1e-6);
            let q = &a["pose"]["orientation"];
            let rot = Quat::from_xyzw(f32_of(&q["x"]), f32_of(&q["y"]), f32_of(&q["z"]), f32_of(&q["w"]));
            assert!((rot * Vec3::X - Vec3::Z).length() < 1e-5);
            assert_eq!(f32_of(&a["pose"]["position"]["x"]), frames[6].contacts[0].pos.x);
        }
    }

    // Metadata.
    let md = &r.metadata["dextrain"];
    assert_eq!(md["hand"], "tiny_hand");
    assert_eq!(serde_json::from_str::<Value>(&md["links"]).unwrap(), serde_json::json!(["palm", "finger"]));
    assert_eq!(serde_json::from_str::<Value>(&md["joints"]).unwrap(), serde_json::json!(["finger_joint"]));
    assert_eq!(serde_json::from_str::<Value>(&md["info"]).unwrap(), meta.info);
    let parts: Vec<ObjectPart> = serde_json::from_str(&md["object"]).unwrap();
    assert_eq!(parts, meta.object);
    assert_eq!(md["dt"].parse::<f32>().unwrap(), DT);
}

#[test]
fn object_shapes_primitives() {
    // (shape, cubes, spheres, cylinders)
    let cases = [
        (ObjectShape::Sphere { radius: 0.03 }, 0, 1, 0),
        (ObjectShape::Box { half_extents: [0.01, 0.02, 0.03] }, 1, 0, 0),
        (ObjectShape::Capsule { radius: 0.02, half_length: 0.04 }, 0, 2, 1),
        (ObjectShape::Cylinder { radius: 0.02, half_length: 0.04 }, 0, 0, 1),
    ];
    for (shape, cubes, spheres, cylinders) in cases {
        let meta = meta(shape);
        let mut w = RolloutWriter::create_in_memory(&meta).unwrap();
        w.write_frame(&frame(&meta.hand, 0)).unwrap();
        let bytes = w.into_bytes().unwrap();
        let r = read(&bytes);
        let scene = &r.messages[TOPIC_SCENE][0].json;
        for id in ["object", "object_ref"] {
            let e = entity(scene, id);
            assert_eq!(
                (prim_count(e, "cubes"), prim_count(e, "spheres"), prim_count(e, "cylinders")),
                (cubes, spheres, cylinders),
                "{shape:?} {id}"
            );
        }
        if let ObjectShape::Capsule { .. } | ObjectShape::Cylinder { .. } = shape {
            let cyl = &entity(scene, "object")["cylinders"][0];
            assert_eq!(f32_of(&cyl["size"]["z"]), 0.08);
            assert_eq!(f32_of(&cyl["size"]["x"]), 0.04);
        }
    }
}

#[test]
fn compound_object_draws_each_piece_at_its_pose() {
    let box_at = Pose::new(Vec3::new(0.05, 0.0, 0.01), Quat::from_rotation_z(0.3));
    let v = [[0.0, 0.0, 0.0], [0.02, 0.0, 0.0], [0.0, 0.02, 0.0], [0.0, 0.0, 0.02f32]];
    let tetra: Vec<[f32; 3]> = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]].iter().flat_map(|t: &[usize; 3]| t.map(|i| v[i])).collect();
    let meta = parts_meta(vec![
        ObjectPart { shape: ObjectShape::Box { half_extents: [0.01, 0.02, 0.03] }, pose: box_at, triangles: Vec::new() },
        ObjectPart { shape: ObjectShape::Sphere { radius: 0.02 }, pose: Pose::new(Vec3::new(-0.04, 0.0, 0.0), Quat::IDENTITY), triangles: Vec::new() },
        // a convex-hull piece (a tetrahedron's 4 triangles) is drawn as its triangles, not its shape
        ObjectPart { shape: ObjectShape::Sphere { radius: 0.5 }, pose: Pose::new(Vec3::new(0.0, 0.07, 0.0), Quat::IDENTITY), triangles: tetra.clone() },
    ]);
    let mut w = RolloutWriter::create_in_memory(&meta).unwrap();
    w.write_frame(&frame(&meta.hand, 0)).unwrap();
    let r = read(&w.into_bytes().unwrap());
    let e = entity(&r.messages[TOPIC_SCENE][0].json, "object");
    assert_eq!((prim_count(e, "cubes"), prim_count(e, "spheres"), prim_count(e, "cylinders")), (1, 1, 0));
    let cube = &e["cubes"][0]["pose"];
    assert_eq!(f32_of(&cube["position"]["x"]), 0.05);
    assert_eq!(f32_of(&cube["position"]["z"]), 0.01);
    assert!((f32_of(&cube["orientation"]["z"]) - (0.15f32).sin()).abs() < 1e-6);
    assert_eq!(f32_of(&e["spheres"][0]["pose"]["position"]["x"]), -0.04);
    let tri = &e["triangles"];
    assert_eq!(tri.as_array().unwrap().len(), 1);
    assert_eq!(f32_of(&tri[0]["pose"]["position"]["y"]), 0.07);
    let points = tri[0]["points"].as_array().unwrap();
    assert_eq!(points.len(), 12);
    assert_eq!(f32_of(&points[11]["z"]), 0.02);
    let parts: Vec<ObjectPart> = serde_json::from_str(&r.metadata["dextrain"]["object"]).unwrap();
    assert_eq!(parts, meta.object);
}

#[test]
fn dropped_writer_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("partial.mcap");
    let meta = box_meta();
    let mut w = RolloutWriter::create(&path, &meta).unwrap();
    w.write_frame(&frame(&meta.hand, 0)).unwrap();
    // While recording, only a temporary file exists, never the final name.
    let during = dir_entries(dir.path());
    assert_eq!(during.len(), 1);
    assert_ne!(during[0], "partial.mcap");
    assert!(during[0].starts_with(".partial.mcap"), "{during:?}");
    drop(w);
    assert!(dir_entries(dir.path()).is_empty(), "{:?}", dir_entries(dir.path()));
}

#[test]
fn finish_replaces_an_existing_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("again.mcap");
    std::fs::write(&path, b"old").unwrap();
    let meta = box_meta();
    write_file(&path, &meta, &frames(&meta.hand)[..3]);
    let r = read(&std::fs::read(&path).unwrap());
    assert_eq!(r.messages[TOPIC_HAND_STATE].len(), 3);
    assert_eq!(dir_entries(dir.path()), vec!["again.mcap".to_string()]);
}

#[test]
fn errors_name_the_path() {
    let dir = tempfile::tempdir().unwrap();
    // a folder that cannot be made (a file stands where it would be): the error names the path
    let blocker = dir.path().join("a_file");
    std::fs::write(&blocker, "x").unwrap();
    let blocked = blocker.join("x.mcap");
    let err = format!("{:#}", RolloutWriter::create(&blocked, &box_meta()).err().expect("a file in the way of the folder"));
    assert!(err.contains(&blocked.display().to_string()), "{err}");
    // a folder that does not exist yet is made (`eval --record runs/NAME/eval/x.mcap` on a fresh run)
    let fresh = dir.path().join("no_such_dir").join("x.mcap");
    let meta = box_meta();
    let mut w = RolloutWriter::create(&fresh, &meta).expect("the missing folder made");
    w.write_frame(&frame(&meta.hand, 0)).unwrap();
    w.finish().unwrap();
    assert!(fresh.is_file());

    let path = dir.path().join("bad.mcap");
    let mut w = RolloutWriter::create(&path, &meta).unwrap();
    let mut f = frame(&meta.hand, 0);
    f.joint_pos.push(0.0);
    let err = format!("{:#}", w.write_frame(&f).unwrap_err());
    assert!(err.contains(&path.display().to_string()) && err.contains("joint_pos"), "{err}");
    let mut f = frame(&meta.hand, 0);
    f.contacts[0].index = 9; // hand_object contact on a collider that does not exist
    let err = format!("{:#}", w.write_frame(&f).unwrap_err());
    assert!(err.contains("collider"), "{err}");
    let mut f = frame(&meta.hand, 0);
    f.links.pop();
    assert!(w.write_frame(&f).is_err());
    // Still usable after rejected frames.
    w.write_frame(&frame(&meta.hand, 0)).unwrap();
    w.finish().unwrap();
    assert_eq!(read(&std::fs::read(&path).unwrap()).messages[TOPIC_TF].len(), 1);
}

#[test]
fn non_finite_values_stay_readable() {
    let meta = box_meta();
    let mut f = frame(&meta.hand, 3);
    f.joint_pos[0] = f32::NAN;
    f.object.pos.x = f32::INFINITY;
    f.links[1].rot = Quat::from_xyzw(f32::NAN, 0.0, 0.0, 1.0);
    let mut w = RolloutWriter::create_in_memory(&meta).unwrap();
    w.write_frame(&f).unwrap();
    let r = read(&w.into_bytes().unwrap());
    assert!(r.messages[TOPIC_HAND_STATE][0].json["position"][0].is_null());
    assert!(r.messages[TOPIC_POSES][0].json["object"]["x"].is_null());
    let tf = &r.messages[TOPIC_TF][0].json["transforms"];
    assert_eq!(f32_of(&tf[1]["rotation"]["w"]), 1.0, "non-finite rotation -> identity");
    assert_eq!(f32_of(&tf[2]["translation"]["x"]), 0.0, "non-finite translation -> 0");
}

/// The independent reader: the Python `mcap` package (and `jsonschema` for validation).
#[test]
fn python_reader_agrees() {
    let required = std::env::var("REQUIRE_PYTHON_MCAP").is_ok_and(|v| v == "1");
    let probe = Command::new("python3").args(["-c", "import mcap.reader"]).output();
    match probe {
        Ok(o) if o.status.success() => {}
        other => {
            let why = match other {
                Ok(o) => format!("`import mcap.reader` failed: {}", String::from_utf8_lossy(&o.stderr).trim()),
                Err(e) => format!("cannot run python3: {e}"),
            };
            if required {
                panic!("REQUIRE_PYTHON_MCAP=1 but {why} (pip install mcap jsonschema)");
            }
            eprintln!("python_reader_agrees: skipped: {why} (pip install mcap jsonschema to run it)");
            return;
        }
    }

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("py.mcap");
    let meta = box_meta();
    let frames = frames(&meta.hand);
    write_file(&path, &meta, &frames);

    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests").join("read_rollout.py");
    let out = Command::new("python3").arg(&script).arg(&path).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "read_rollout.py failed: {stderr}");
    let stdout = String::from_utf8(out.stdout).unwrap();
    let line = stdout.lines().last().unwrap_or_else(|| panic!("no output; stderr: {stderr}"));
    let s: Value = serde_json::from_str(line).unwrap();

    assert_eq!(s["ok"], true);
    if s["validated"] != true {
        assert!(!required, "REQUIRE_PYTHON_MCAP=1 but the jsonschema package is not importable");
        eprintln!("python_reader_agrees: jsonschema not importable, messages were not validated");
    } else {
        assert_eq!(s["validated_messages"].as_u64().unwrap(), 5 * N_FRAMES as u64);
    }
    let topics = [TOPIC_HAND_STATE, TOPIC_POSES, TOPIC_CONTACTS, TOPIC_TF, TOPIC_SCENE];
    for (topic, schema) in topics.iter().zip([
        "dextrain.HandState",
        "dextrain.Poses",
        "dextrain.Contacts",
        "foxglove.FrameTransforms",
        "foxglove.SceneUpdate",
    ]) {
        assert_eq!(s["counts"][topic], N_FRAMES, "{topic}");
        assert_eq!(s["summary_counts"][topic], N_FRAMES, "{topic}");
        assert_eq!(s["schemas"][topic]["name"], schema, "{topic}");
        assert_eq!(s["schemas"][topic]["encoding"], "jsonschema", "{topic}");
        assert_eq!(s["schemas"][topic]["message_encoding"], "json", "{topic}");
        assert_eq!(s["first_log_time"][topic], 0, "{topic}");
        assert_eq!(
            s["last_log_time"][topic].as_u64().unwrap(),
            (frames[N_FRAMES - 1].t * 1e9).round() as u64,
            "{topic}"
        );
    }
    assert_eq!(s["counts"].as_object().unwrap().len(), 5);
    assert_eq!(s["metadata_names"], serde_json::json!(["dextrain"]));
    assert_eq!(s["metadata"]["dextrain"]["hand"], "tiny_hand");
    let pos: Vec<f32> = s["first_hand_state_position"].as_array().unwrap().iter().map(f32_of).collect();
    assert_eq!(pos, frames[0].joint_pos);
    assert_eq!(s["first_hand_state_joint_names"], serde_json::json!(["finger_joint"]));
    assert_eq!(f32_of(&s["first_object_pose"]["z"]), frames[0].object.pos.z);
    assert_eq!(f32_of(&s["first_contacts"][0]["force"]["z"]), frames[0].contacts[0].force.z);
    assert_eq!(s["first_tf_children"], serde_json::json!(["palm", "finger", "object", "object_ref"]));
    let finger = &s["first_scene"]["entities"]["hand/finger"];
    assert_eq!((finger["cylinders"].as_u64(), finger["spheres"].as_u64()), (Some(1), Some(2)));
    // Frame 0: hand-object contact with force 0 (no arrow), object-table contact with force 0.
    assert_eq!(s["first_scene"]["entities"]["contacts"]["arrows"], 0);
    assert_eq!(s["first_scene"]["entities"]["contacts"]["spheres"], 2);
}
