//! Recorded rollouts as MCAP: hand joint states, wrist and object poses, contacts and forces, plus
//! Foxglove `foxglove.FrameTransforms` and `foxglove.SceneUpdate` messages for 3-D viewing.
//!
//! CONTRACT (used by `dextrain replay --out` and later `dextrain eval --record`):
//! `RolloutWriter::create(path, &meta)`, then `write_frame(&frame)` once per recorded env step, then
//! `finish()`. Everything is in the world frame unless said otherwise.
//!
//! File layout (zstd-compressed chunks; every message is JSON, every schema a JSON Schema; log time =
//! publish time = `frame.t` in nanoseconds; each channel gets exactly one message per frame, with a
//! per-channel sequence number 0, 1, 2, ...):
//!
//! | topic                  | schema                     | content                                        |
//! |------------------------|----------------------------|------------------------------------------------|
//! | `/dextrain/hand_state` | `dextrain.HandState`       | `timestamp, t, joint_names, position, velocity, target` |
//! | `/dextrain/poses`      | `dextrain.Poses`           | `timestamp, t, wrist, object, object_ref` (`{x,y,z,qx,qy,qz,qw}`, `object_ref` may be null) |
//! | `/dextrain/contacts`   | `dextrain.Contacts`        | `timestamp, t, contacts: [{kind, index, link, pos, normal, depth, force}]` |
//! | `/tf`                  | `foxglove.FrameTransforms` | `world` → every link (frame id = link name), `world` → `object`, `world` → `object_ref` |
//! | `/scene`               | `foxglove.SceneUpdate`     | hand links, object, table, reference ghost, contact points and force arrows |
//!
//! Non-finite numbers in the `dextrain.*` messages are written as JSON `null` (the schemas allow it);
//! in the Foxglove messages they are replaced by 0 (and non-finite rotations by the identity).
//! A metadata record named `dextrain` holds `info` (JSON), `hand`, `hand_source`, `links`,
//! `link_frames`, `joints` (JSON arrays of strings), `object` (JSON of [`ObjectShape`]), `dt`,
//! `format` and `version`.
//!
//! A link named `world`, `object` or `object_ref` gets the TF frame id `hand/<name>` instead of its
//! name, so that the frame tree stays a tree.

use std::collections::BTreeMap;
use std::fs::{self, File, OpenOptions};
use std::io::{BufWriter, Cursor, Seek, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use anyhow::{Context, Result, bail};
use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use crate::geom::{ObjectShape, Pose};
use crate::hand::{ColliderShape, HandModel};

/// What kind of pair a contact is between.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ContactKind {
    HandObject,
    HandTable,
    ObjectTable,
}

/// One contact at the time of a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactRecord {
    pub kind: ContactKind,
    /// Hand collider index (into `HandModel::colliders`) for hand contacts, object support-point
    /// index for object–table contacts.
    pub index: u32,
    /// Contact point (world).
    pub pos: Vec3,
    /// Unit normal, pointing from the second body (object or table) to the first (hand or object).
    pub normal: Vec3,
    /// Penetration depth (m, ≥ 0).
    pub depth: f32,
    /// Total contact force on the first body (normal + friction), N.
    pub force: Vec3,
}

/// One collision piece of the recorded object: a primitive (scaled) at a pose in the object frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectPart {
    pub shape: ObjectShape,
    pub pose: Pose,
    /// A convex-hull piece: its triangles (three points each, in the part's frame), drawn instead
    /// of `shape`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub triangles: Vec<[f32; 3]>,
}

/// Static description of a recorded rollout.
#[derive(Clone, Debug)]
pub struct RolloutMeta {
    pub hand: HandModel,
    /// The object's pieces with the env's object scale already applied.
    pub object: Vec<ObjectPart>,
    /// Time between recorded frames (s).
    pub dt: f32,
    /// Free-form JSON (config summary, command line) stored as MCAP metadata "dextrain".
    pub info: serde_json::Value,
}

/// State of one env at one recorded time.
#[derive(Clone, Debug, PartialEq)]
pub struct RolloutFrame {
    /// Simulated time (s).
    pub t: f64,
    /// Joint positions and velocities in `HandModel::joints` order (mimic followers included).
    pub joint_pos: Vec<f32>,
    pub joint_vel: Vec<f32>,
    /// Joint position targets, same order.
    pub joint_target: Vec<f32>,
    pub wrist: Pose,
    pub object: Pose,
    /// World pose of every link, in `HandModel::links` order (links[0] is the wrist).
    pub links: Vec<Pose>,
    pub contacts: Vec<ContactRecord>,
    /// Optional reference object pose at this time (drawn as a ghost).
    pub object_ref: Option<Pose>,
}

impl ContactKind {
    /// The name used in recordings: `hand_object`, `hand_table` or `object_table`.
    pub fn as_str(self) -> &'static str {
        match self {
            ContactKind::HandObject => "hand_object",
            ContactKind::HandTable => "hand_table",
            ContactKind::ObjectTable => "object_table",
        }
    }

    /// True when the first body is the hand (`index` is then a collider index).
    pub fn is_hand(self) -> bool {
        matches!(self, ContactKind::HandObject | ContactKind::HandTable)
    }
}

/// Topic of the `dextrain.HandState` messages.
pub const TOPIC_HAND_STATE: &str = "/dextrain/hand_state";
/// Topic of the `dextrain.Poses` messages.
pub const TOPIC_POSES: &str = "/dextrain/poses";
/// Topic of the `dextrain.Contacts` messages.
pub const TOPIC_CONTACTS: &str = "/dextrain/contacts";
/// Topic of the `foxglove.FrameTransforms` messages.
pub const TOPIC_TF: &str = "/tf";
/// Topic of the `foxglove.SceneUpdate` messages.
pub const TOPIC_SCENE: &str = "/scene";

pub const SCHEMA_HAND_STATE: &str = "dextrain.HandState";
pub const SCHEMA_POSES: &str = "dextrain.Poses";
pub const SCHEMA_CONTACTS: &str = "dextrain.Contacts";
pub const SCHEMA_FRAME_TRANSFORMS: &str = "foxglove.FrameTransforms";
pub const SCHEMA_SCENE_UPDATE: &str = "foxglove.SceneUpdate";

/// Name of the MCAP metadata record describing the rollout.
pub const METADATA_NAME: &str = "dextrain";
/// Value of the metadata's `format` key, and its `version`.
pub const FORMAT_NAME: &str = "dextrain.rollout";
pub const FORMAT_VERSION: &str = "1";

/// TF frame ids of the world, the object and the reference object.
pub const WORLD_FRAME: &str = "world";
pub const OBJECT_FRAME: &str = "object";
pub const OBJECT_REF_FRAME: &str = "object_ref";

/// Scene entity ids (hand links are `hand/<link name>`).
pub const ENTITY_OBJECT: &str = "object";
pub const ENTITY_OBJECT_REF: &str = "object_ref";
pub const ENTITY_TABLE: &str = "table";
pub const ENTITY_CONTACTS: &str = "contacts";

/// Force arrows: shaft length per newton (m/N) and the longest shaft drawn (m).
pub const FORCE_ARROW_M_PER_N: f32 = 0.02;
pub const FORCE_ARROW_MAX_SHAFT: f32 = 0.3;
/// Table drawn as a cube of this size (m), its top face at z = 0.
pub const TABLE_SIZE: [f32; 3] = [1.2, 1.2, 0.01];

const MESSAGE_ENCODING: &str = "json";
const SCHEMA_ENCODING: &str = "jsonschema";

/// Channels, in the order of `init`'s table and of a frame's messages: hand_state, poses, contacts,
/// tf, scene.
const NUM_CHANNELS: usize = 5;

/// Writes a rollout as an MCAP file (see the module docs for the layout).
///
/// With [`RolloutWriter::create`] the data goes to a hidden temporary file next to the target, which
/// [`RolloutWriter::finish`] renames to the target: an interrupted run never leaves a truncated file
/// under the final name. Dropping a file writer without finishing it removes the temporary file.
pub struct RolloutWriter<W: Write + Seek = BufWriter<File>> {
    mcap: Option<mcap::Writer<W>>,
    /// Name used in error messages (the target path, or `<stream>`).
    label: PathBuf,
    /// (temporary path, final path) of a file writer that is not finished yet.
    files: Option<(PathBuf, PathBuf)>,
    channel_ids: [u16; NUM_CHANNELS],
    sequences: [u32; NUM_CHANNELS],
    joint_names: Vec<String>,
    link_names: Vec<String>,
    link_frames: Vec<String>,
    /// Link index of every collider.
    collider_links: Vec<usize>,
    /// Scene entities that only change by timestamp: hand links, object, table.
    static_entities: Vec<FgEntity>,
    /// The reference ghost (sent when the frame has an `object_ref`).
    ghost_entity: FgEntity,
    frames: u64,
}

impl RolloutWriter<BufWriter<File>> {
    /// Starts a recording that [`finish`](Self::finish) will leave at `path`. Writes go to a
    /// temporary file in the same directory. Errors name `path`.
    pub fn create(path: &Path, meta: &RolloutMeta) -> Result<Self> {
        let tmp = temp_path_for(path).with_context(|| format!("creating rollout {}", path.display()))?;
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)
            .with_context(|| format!("creating rollout {} (temporary file {})", path.display(), tmp.display()))?;
        let mut w = Self::init(BufWriter::new(file), path.to_path_buf(), meta);
        match &mut w {
            Ok(w) => w.files = Some((tmp, path.to_path_buf())),
            Err(_) => {
                let _ = fs::remove_file(&tmp);
            }
        }
        w
    }

    /// Completes the file (summary, indexes), syncs it and renames it to its final path.
    pub fn finish(mut self) -> Result<()> {
        let (tmp, dest) = self.files.clone().expect("a file RolloutWriter always has its paths");
        let mut mcap = self.mcap.take().expect("the MCAP writer is only taken by finish");
        let result = (|| -> Result<()> {
            mcap.finish()?;
            let file = mcap.into_inner().into_inner().map_err(|e| e.into_error())?;
            file.sync_all()?;
            drop(file);
            fs::rename(&tmp, &dest).with_context(|| format!("renaming {} to {}", tmp.display(), dest.display()))?;
            Ok(())
        })()
        .with_context(|| format!("finishing rollout {}", dest.display()));
        if result.is_ok() {
            self.files = None;
        }
        // On error, Drop removes the temporary file.
        result
    }

    /// The final path of the recording.
    pub fn path(&self) -> &Path {
        &self.label
    }
}

impl RolloutWriter<Cursor<Vec<u8>>> {
    /// A recording kept in memory (for tests and tools); get it with [`into_bytes`](Self::into_bytes).
    pub fn create_in_memory(meta: &RolloutMeta) -> Result<Self> {
        Self::init(Cursor::new(Vec::new()), PathBuf::from("<memory>"), meta)
    }

    /// Completes the recording and returns the MCAP bytes.
    pub fn into_bytes(self) -> Result<Vec<u8>> {
        Ok(self.finish_into_inner()?.into_inner())
    }
}

impl<W: Write + Seek> RolloutWriter<W> {
    /// A recording written to any seekable stream; complete it with
    /// [`finish_into_inner`](Self::finish_into_inner).
    pub fn new(writer: W, meta: &RolloutMeta) -> Result<Self> {
        Self::init(writer, PathBuf::from("<stream>"), meta)
    }

    /// Completes the recording (summary, indexes) and returns the stream. A writer made by
    /// [`RolloutWriter::create`] must be completed with `finish` instead (this is an error for it).
    pub fn finish_into_inner(mut self) -> Result<W> {
        if self.files.is_some() {
            bail!(
                "rollout {}: a file recording is completed with finish(), not finish_into_inner()",
                self.label.display()
            );
        }
        let mut mcap = self.mcap.take().expect("the MCAP writer is only taken by finish");
        mcap.finish().with_context(|| format!("finishing rollout {}", self.label.display()))?;
        Ok(mcap.into_inner())
    }

    /// Number of frames written so far.
    pub fn frames_written(&self) -> u64 {
        self.frames
    }

    fn init(writer: W, label: PathBuf, meta: &RolloutMeta) -> Result<Self> {
        let ctx = || format!("creating rollout {}", label.display());
        let hand = &meta.hand;
        validate_meta(meta).with_context(ctx)?;

        let link_names: Vec<String> = hand.links.iter().map(|l| l.name.clone()).collect();
        let link_frames = link_frame_ids(&link_names);
        let joint_names: Vec<String> = hand.joints.iter().map(|j| j.name.clone()).collect();

        let mut mcap = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .compression_threads(0)
            .library(format!("dextrain {}", env!("CARGO_PKG_VERSION")))
            .create(writer)
            .with_context(ctx)?;

        let mut metadata = BTreeMap::new();
        metadata.insert("format".to_string(), FORMAT_NAME.to_string());
        metadata.insert("version".to_string(), FORMAT_VERSION.to_string());
        metadata.insert("info".to_string(), serde_json::to_string(&meta.info)?);
        metadata.insert("hand".to_string(), hand.name.clone());
        metadata.insert("hand_source".to_string(), hand.source.display().to_string());
        metadata.insert("links".to_string(), serde_json::to_string(&link_names)?);
        metadata.insert("link_frames".to_string(), serde_json::to_string(&link_frames)?);
        metadata.insert("joints".to_string(), serde_json::to_string(&joint_names)?);
        metadata.insert("object".to_string(), serde_json::to_string(&meta.object)?);
        metadata.insert("dt".to_string(), meta.dt.to_string());
        mcap.write_metadata(&mcap::records::Metadata { name: METADATA_NAME.to_string(), metadata })
            .with_context(ctx)?;

        let specs: [(&str, &str, Value); NUM_CHANNELS] = [
            (TOPIC_HAND_STATE, SCHEMA_HAND_STATE, hand_state_schema()),
            (TOPIC_POSES, SCHEMA_POSES, poses_schema()),
            (TOPIC_CONTACTS, SCHEMA_CONTACTS, contacts_schema()),
            (TOPIC_TF, SCHEMA_FRAME_TRANSFORMS, frame_transforms_schema()),
            (TOPIC_SCENE, SCHEMA_SCENE_UPDATE, scene_update_schema()),
        ];
        let mut channel_ids = [0u16; NUM_CHANNELS];
        for (i, (topic, schema_name, schema)) in specs.iter().enumerate() {
            let data = serde_json::to_vec_pretty(schema)?;
            let schema_id = mcap.add_schema(schema_name, SCHEMA_ENCODING, &data).with_context(ctx)?;
            channel_ids[i] =
                mcap.add_channel(schema_id, topic, MESSAGE_ENCODING, &BTreeMap::new()).with_context(ctx)?;
        }

        let (static_entities, ghost_entity) = build_static_entities(meta, &link_frames);

        Ok(Self {
            mcap: Some(mcap),
            label,
            files: None,
            channel_ids,
            sequences: [0; NUM_CHANNELS],
            joint_names,
            link_names,
            link_frames,
            collider_links: hand.colliders.iter().map(|c| c.link).collect(),
            static_entities,
            ghost_entity,
            frames: 0,
        })
    }

    /// Writes one frame: one message on every channel, all at log time `frame.t`.
    pub fn write_frame(&mut self, frame: &RolloutFrame) -> Result<()> {
        self.check_frame(frame)
            .with_context(|| format!("writing rollout {}: frame at t = {}", self.label.display(), frame.t))?;
        let ns = (frame.t * 1e9).round() as u64;
        let stamp = FgTime::from_ns(ns);

        let hand_state = HandStateMsg {
            timestamp: stamp,
            t: frame.t,
            joint_names: &self.joint_names,
            position: &frame.joint_pos,
            velocity: &frame.joint_vel,
            target: &frame.joint_target,
        };
        let poses = PosesMsg {
            timestamp: stamp,
            t: frame.t,
            wrist: PoseMsg::from(&frame.wrist),
            object: PoseMsg::from(&frame.object),
            object_ref: frame.object_ref.as_ref().map(PoseMsg::from),
        };
        let contacts = ContactsMsg {
            timestamp: stamp,
            t: frame.t,
            contacts: frame
                .contacts
                .iter()
                .map(|c| ContactMsg {
                    kind: c.kind.as_str(),
                    index: c.index,
                    link: c.kind.is_hand().then(|| self.link_names[self.collider_links[c.index as usize]].as_str()),
                    pos: XyzMsg::from(c.pos),
                    normal: XyzMsg::from(c.normal),
                    depth: c.depth,
                    force: XyzMsg::from(c.force),
                })
                .collect(),
        };

        let mut transforms = Vec::with_capacity(self.link_frames.len() + 2);
        for (i, child) in self.link_frames.iter().enumerate() {
            let pose = if i == 0 { &frame.wrist } else { &frame.links[i] };
            transforms.push(FgTransform::new(stamp, WORLD_FRAME, child, pose));
        }
        transforms.push(FgTransform::new(stamp, WORLD_FRAME, OBJECT_FRAME, &frame.object));
        if let Some(r) = &frame.object_ref {
            transforms.push(FgTransform::new(stamp, WORLD_FRAME, OBJECT_REF_FRAME, r));
        }
        let tf = FgFrameTransforms { transforms };

        let mut entities: Vec<FgEntity> = self.static_entities.clone();
        let mut deletions = Vec::new();
        if frame.object_ref.is_some() {
            entities.push(self.ghost_entity.clone());
        } else {
            deletions.push(FgDeletion { timestamp: stamp, kind: 0, id: ENTITY_OBJECT_REF.to_string() });
        }
        entities.push(contacts_entity(&frame.contacts));
        for e in &mut entities {
            e.timestamp = stamp;
        }
        let scene = FgSceneUpdate { deletions, entities };

        let payloads: [Vec<u8>; NUM_CHANNELS] = [
            serde_json::to_vec(&hand_state)?,
            serde_json::to_vec(&poses)?,
            serde_json::to_vec(&contacts)?,
            serde_json::to_vec(&tf)?,
            serde_json::to_vec(&scene)?,
        ];
        let mcap = self.mcap.as_mut().expect("the MCAP writer is only taken by finish");
        for (ch, data) in payloads.iter().enumerate() {
            let header = mcap::records::MessageHeader {
                channel_id: self.channel_ids[ch],
                sequence: self.sequences[ch],
                log_time: ns,
                publish_time: ns,
            };
            mcap.write_to_known_channel(&header, data)
                .with_context(|| format!("writing rollout {}", self.label.display()))?;
            self.sequences[ch] = self.sequences[ch].wrapping_add(1);
        }
        self.frames += 1;
        Ok(())
    }

    fn check_frame(&self, f: &RolloutFrame) -> Result<()> {
        if !f.t.is_finite() || f.t < 0.0 {
            bail!("time must be finite and >= 0");
        }
        let nj = self.joint_names.len();
        for (what, len) in
            [("joint_pos", f.joint_pos.len()), ("joint_vel", f.joint_vel.len()), ("joint_target", f.joint_target.len())]
        {
            if len != nj {
                bail!("{what} has {len} entries but the hand has {nj} joints");
            }
        }
        if f.links.len() != self.link_names.len() {
            bail!("{} link poses but the hand has {} links", f.links.len(), self.link_names.len());
        }
        for (k, c) in f.contacts.iter().enumerate() {
            if c.kind.is_hand() && c.index as usize >= self.collider_links.len() {
                bail!(
                    "contact {k} ({}) has collider index {} but the hand has {} colliders",
                    c.kind.as_str(),
                    c.index,
                    self.collider_links.len()
                );
            }
        }
        Ok(())
    }
}

impl<W: Write + Seek> Drop for RolloutWriter<W> {
    fn drop(&mut self) {
        // An unfinished file writer: drop the partial data and remove the temporary file.
        if let Some((tmp, _)) = self.files.take() {
            if let Some(w) = self.mcap.take() {
                drop(w.into_inner());
            }
            let _ = fs::remove_file(&tmp);
        }
    }
}

fn validate_meta(meta: &RolloutMeta) -> Result<()> {
    let hand = &meta.hand;
    if hand.links.is_empty() {
        bail!("hand {} has no links", hand.name);
    }
    if !(meta.dt.is_finite() && meta.dt > 0.0) {
        bail!("dt must be finite and > 0 (got {})", meta.dt);
    }
    for (i, c) in hand.colliders.iter().enumerate() {
        if c.link >= hand.links.len() {
            bail!("hand {}: collider {i} is on link {} but there are {} links", hand.name, c.link, hand.links.len());
        }
    }
    for (i, j) in hand.joints.iter().enumerate() {
        if i + 1 >= hand.links.len() || j.parent_link >= hand.links.len() {
            bail!("hand {}: joint {} has no child link {}", hand.name, j.name, i + 1);
        }
    }
    Ok(())
}

/// `dir/.name.tmp-<pid>-<n>` next to `path`.
fn temp_path_for(path: &Path) -> Result<PathBuf> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let name = path.file_name().with_context(|| "the path has no file name".to_string())?;
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let tmp_name = format!(".{}.tmp-{}-{}", name.to_string_lossy(), std::process::id(), n);
    Ok(path.with_file_name(tmp_name))
}

/// TF frame id of each link: its name, or `hand/<name>` when that would clash with a reserved frame
/// or an earlier link.
fn link_frame_ids(names: &[String]) -> Vec<String> {
    let mut out: Vec<String> = Vec::with_capacity(names.len());
    for n in names {
        let reserved = [WORLD_FRAME, OBJECT_FRAME, OBJECT_REF_FRAME].contains(&n.as_str());
        let mut id = if reserved || n.is_empty() { format!("hand/{n}") } else { n.clone() };
        while out.contains(&id) {
            id = format!("hand/{id}");
        }
        out.push(id);
    }
    out
}

// ------------------------------------------------------------------------------------------------
// Scene construction

const HAND_COLOR: FgColor = FgColor { r: 0.75, g: 0.72, b: 0.68, a: 1.0 };
const OBJECT_COLOR: FgColor = FgColor { r: 0.95, g: 0.55, b: 0.15, a: 1.0 };
const GHOST_COLOR: FgColor = FgColor { r: 0.2, g: 0.85, b: 0.3, a: 0.3 };
const TABLE_COLOR: FgColor = FgColor { r: 0.45, g: 0.42, b: 0.4, a: 1.0 };
const CONTACT_POINT_COLOR: FgColor = FgColor { r: 1.0, g: 1.0, b: 0.2, a: 1.0 };
const CONTACT_POINT_DIAMETER: f32 = 0.006;

fn force_color(kind: ContactKind) -> FgColor {
    match kind {
        ContactKind::HandObject => FgColor { r: 0.9, g: 0.1, b: 0.1, a: 1.0 },
        ContactKind::HandTable => FgColor { r: 0.1, g: 0.3, b: 0.95, a: 1.0 },
        ContactKind::ObjectTable => FgColor { r: 0.1, g: 0.8, b: 0.2, a: 1.0 },
    }
}

#[derive(Default)]
struct Prims {
    cubes: Vec<FgShape>,
    spheres: Vec<FgShape>,
    cylinders: Vec<FgCylinder>,
    /// Foxglove TriangleListPrimitive messages (convex-hull pieces).
    triangles: Vec<Value>,
}

impl Prims {
    fn sphere(&mut self, pose: &Pose, radius: f32, color: FgColor) {
        self.spheres.push(FgShape { pose: FgPose::from(pose), size: fv(Vec3::splat(2.0 * radius)), color });
    }

    fn cube(&mut self, pose: &Pose, half_extents: Vec3, color: FgColor) {
        self.cubes.push(FgShape { pose: FgPose::from(pose), size: fv(2.0 * half_extents), color });
    }

    /// A cylinder along the pose's local z.
    fn cylinder(&mut self, pose: &Pose, radius: f32, half_length: f32, color: FgColor) {
        self.cylinders.push(FgCylinder {
            pose: FgPose::from(pose),
            size: fv(Vec3::new(2.0 * radius, 2.0 * radius, 2.0 * half_length)),
            bottom_scale: 1.0,
            top_scale: 1.0,
            color,
        });
    }

    /// A capsule along the pose's local z: a cylinder and a sphere at each end.
    fn capsule(&mut self, pose: &Pose, radius: f32, half_length: f32, color: FgColor) {
        self.cylinder(pose, radius, half_length, color);
        for s in [-1.0, 1.0] {
            let end = Pose::new(pose.transform_point(Vec3::new(0.0, 0.0, s * half_length)), pose.rot);
            self.sphere(&end, radius, color);
        }
    }

    fn object(&mut self, parts: &[ObjectPart], color: FgColor) {
        for part in parts {
            let at = &part.pose;
            if !part.triangles.is_empty() {
                self.triangles.push(json!({
                    "pose": FgPose::from(at),
                    "points": part.triangles.iter().map(|p| fv(Vec3::from(*p))).collect::<Vec<_>>(),
                    "color": color,
                    "colors": [],
                    "indices": [],
                }));
                continue;
            }
            match part.shape {
                ObjectShape::Sphere { radius } => self.sphere(at, radius, color),
                ObjectShape::Box { half_extents } => self.cube(at, Vec3::from(half_extents), color),
                ObjectShape::Capsule { radius, half_length } => self.capsule(at, radius, half_length, color),
                ObjectShape::Cylinder { radius, half_length } => self.cylinder(at, radius, half_length, color),
            }
        }
    }

    fn into_entity(self, id: &str, frame_id: &str, kind: &str) -> FgEntity {
        FgEntity {
            timestamp: FgTime { sec: 0, nsec: 0 },
            frame_id: frame_id.to_string(),
            id: id.to_string(),
            lifetime: FgDuration { sec: 0, nsec: 0 },
            frame_locked: true,
            metadata: vec![FgKeyValue { key: "kind".to_string(), value: kind.to_string() }],
            arrows: Vec::new(),
            cubes: self.cubes,
            spheres: self.spheres,
            cylinders: self.cylinders,
            lines: Vec::new(),
            triangles: self.triangles,
            texts: Vec::new(),
            models: Vec::new(),
        }
    }
}

/// Hand links (one entity per link, `hand/<link name>` in the link's frame), the object, the table;
/// and the reference ghost.
fn build_static_entities(meta: &RolloutMeta, link_frames: &[String]) -> (Vec<FgEntity>, FgEntity) {
    let hand = &meta.hand;
    let mut entities = Vec::with_capacity(hand.links.len() + 2);
    for (li, link) in hand.links.iter().enumerate() {
        let mut p = Prims::default();
        for c in hand.colliders.iter().filter(|c| c.link == li) {
            match c.shape {
                ColliderShape::Sphere { radius } => p.sphere(&c.pose, radius, HAND_COLOR),
                ColliderShape::Capsule { radius, half_length } => p.capsule(&c.pose, radius, half_length, HAND_COLOR),
                ColliderShape::Box { half_extents } => p.cube(&c.pose, half_extents, HAND_COLOR),
            }
        }
        let mut e = p.into_entity(&format!("hand/{}", link.name), &link_frames[li], "hand_link");
        e.metadata.push(FgKeyValue { key: "link".to_string(), value: link.name.clone() });
        entities.push(e);
    }

    let mut p = Prims::default();
    p.object(&meta.object, OBJECT_COLOR);
    entities.push(p.into_entity(ENTITY_OBJECT, OBJECT_FRAME, "object"));

    let mut p = Prims::default();
    let [sx, sy, sz] = TABLE_SIZE;
    p.cube(&Pose::new(Vec3::new(0.0, 0.0, -0.5 * sz), Quat::IDENTITY), 0.5 * Vec3::new(sx, sy, sz), TABLE_COLOR);
    entities.push(p.into_entity(ENTITY_TABLE, WORLD_FRAME, "table"));

    let mut p = Prims::default();
    p.object(&meta.object, GHOST_COLOR);
    let ghost = p.into_entity(ENTITY_OBJECT_REF, OBJECT_REF_FRAME, "object_ref");
    (entities, ghost)
}

/// Contact points (small spheres) and force arrows (for non-zero forces), in the world frame.
fn contacts_entity(contacts: &[ContactRecord]) -> FgEntity {
    let mut p = Prims::default();
    let mut arrows = Vec::new();
    for c in contacts {
        if !c.pos.is_finite() {
            continue;
        }
        p.sphere(&Pose::new(c.pos, Quat::IDENTITY), 0.5 * CONTACT_POINT_DIAMETER, CONTACT_POINT_COLOR);
        let f = c.force.length();
        if !(f.is_finite() && f > 1e-6) {
            continue;
        }
        let rot = Quat::from_rotation_arc(Vec3::X, c.force / f);
        arrows.push(FgArrow {
            pose: FgPose::from(&Pose::new(c.pos, rot)),
            shaft_length: (f * FORCE_ARROW_M_PER_N).min(FORCE_ARROW_MAX_SHAFT),
            shaft_diameter: 0.003,
            head_length: 0.01,
            head_diameter: 0.008,
            color: force_color(c.kind),
        });
    }
    let mut e = p.into_entity(ENTITY_CONTACTS, WORLD_FRAME, "contacts");
    e.arrows = arrows;
    e
}

// ------------------------------------------------------------------------------------------------
// Message types (JSON)

#[derive(Serialize, Clone, Copy, Debug)]
struct FgTime {
    sec: u32,
    nsec: u32,
}

impl FgTime {
    fn from_ns(ns: u64) -> Self {
        FgTime { sec: (ns / 1_000_000_000).min(u32::MAX as u64) as u32, nsec: (ns % 1_000_000_000) as u32 }
    }
}

#[derive(Serialize, Clone, Copy, Debug)]
struct FgDuration {
    sec: i32,
    nsec: u32,
}

#[derive(Serialize, Clone, Copy, Debug)]
struct FgVec3 {
    x: f32,
    y: f32,
    z: f32,
}

#[derive(Serialize, Clone, Copy, Debug)]
struct FgQuat {
    x: f32,
    y: f32,
    z: f32,
    w: f32,
}

#[derive(Serialize, Clone, Copy, Debug)]
struct FgPose {
    position: FgVec3,
    orientation: FgQuat,
}

#[derive(Serialize, Clone, Copy, Debug)]
struct FgColor {
    r: f32,
    g: f32,
    b: f32,
    a: f32,
}

/// A cube or sphere primitive.
#[derive(Serialize, Clone, Debug)]
struct FgShape {
    pose: FgPose,
    size: FgVec3,
    color: FgColor,
}

#[derive(Serialize, Clone, Debug)]
struct FgCylinder {
    pose: FgPose,
    size: FgVec3,
    bottom_scale: f32,
    top_scale: f32,
    color: FgColor,
}

#[derive(Serialize, Clone, Debug)]
struct FgArrow {
    pose: FgPose,
    shaft_length: f32,
    shaft_diameter: f32,
    head_length: f32,
    head_diameter: f32,
    color: FgColor,
}

#[derive(Serialize, Clone, Debug)]
struct FgKeyValue {
    key: String,
    value: String,
}

#[derive(Serialize, Clone, Debug)]
struct FgEntity {
    timestamp: FgTime,
    frame_id: String,
    id: String,
    lifetime: FgDuration,
    frame_locked: bool,
    metadata: Vec<FgKeyValue>,
    arrows: Vec<FgArrow>,
    cubes: Vec<FgShape>,
    spheres: Vec<FgShape>,
    cylinders: Vec<FgCylinder>,
    lines: Vec<Value>,
    triangles: Vec<Value>,
    texts: Vec<Value>,
    models: Vec<Value>,
}

#[derive(Serialize, Debug)]
struct FgDeletion {
    timestamp: FgTime,
    /// 0 = MATCHING_ID, 1 = ALL.
    #[serde(rename = "type")]
    kind: u32,
    id: String,
}

#[derive(Serialize, Debug)]
struct FgSceneUpdate {
    deletions: Vec<FgDeletion>,
    entities: Vec<FgEntity>,
}

#[derive(Serialize, Debug)]
struct FgTransform<'a> {
    timestamp: FgTime,
    parent_frame_id: &'a str,
    child_frame_id: &'a str,
    translation: FgVec3,
    rotation: FgQuat,
}

impl<'a> FgTransform<'a> {
    fn new(timestamp: FgTime, parent: &'a str, child: &'a str, pose: &Pose) -> Self {
        FgTransform {
            timestamp,
            parent_frame_id: parent,
            child_frame_id: child,
            translation: fv(pose.pos),
            rotation: fq(pose.rot),
        }
    }
}

#[derive(Serialize, Debug)]
struct FgFrameTransforms<'a> {
    transforms: Vec<FgTransform<'a>>,
}

/// A vector for Foxglove messages: non-finite components become 0.
fn fv(v: Vec3) -> FgVec3 {
    let c = |x: f32| if x.is_finite() { x } else { 0.0 };
    FgVec3 { x: c(v.x), y: c(v.y), z: c(v.z) }
}

/// A rotation for Foxglove messages: normalized, the identity if not finite or zero.
fn fq(q: Quat) -> FgQuat {
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
struct HandStateMsg<'a> {
    timestamp: FgTime,
    t: f64,
    joint_names: &'a [String],
    position: &'a [f32],
    velocity: &'a [f32],
    target: &'a [f32],
}

#[derive(Serialize, Debug)]
struct PoseMsg {
    x: f32,
    y: f32,
    z: f32,
    qx: f32,
    qy: f32,
    qz: f32,
    qw: f32,
}

impl From<&Pose> for PoseMsg {
    fn from(p: &Pose) -> Self {
        PoseMsg { x: p.pos.x, y: p.pos.y, z: p.pos.z, qx: p.rot.x, qy: p.rot.y, qz: p.rot.z, qw: p.rot.w }
    }
}

#[derive(Serialize, Debug)]
struct PosesMsg {
    timestamp: FgTime,
    t: f64,
    wrist: PoseMsg,
    object: PoseMsg,
    object_ref: Option<PoseMsg>,
}

#[derive(Serialize, Debug)]
struct XyzMsg {
    x: f32,
    y: f32,
    z: f32,
}

impl From<Vec3> for XyzMsg {
    fn from(v: Vec3) -> Self {
        XyzMsg { x: v.x, y: v.y, z: v.z }
    }
}

#[derive(Serialize, Debug)]
struct ContactMsg<'a> {
    kind: &'static str,
    index: u32,
    link: Option<&'a str>,
    pos: XyzMsg,
    normal: XyzMsg,
    depth: f32,
    force: XyzMsg,
}

#[derive(Serialize, Debug)]
struct ContactsMsg<'a> {
    timestamp: FgTime,
    t: f64,
    contacts: Vec<ContactMsg<'a>>,
}

// ------------------------------------------------------------------------------------------------
// JSON Schemas

const JSON_SCHEMA_DIALECT: &str = "https://json-schema.org/draft/2020-12/schema";

/// A number, or null for a non-finite value.
fn num_or_null(description: &str) -> Value {
    json!({ "type": ["number", "null"], "description": description })
}

fn dx_time(description: &str) -> Value {
    json!({
        "type": "object",
        "title": "time",
        "description": description,
        "properties": {
            "sec": { "type": "integer", "minimum": 0 },
            "nsec": { "type": "integer", "minimum": 0, "maximum": 999_999_999 }
        },
        "required": ["sec", "nsec"],
        "additionalProperties": false
    })
}

fn dx_xyz(title: &str, description: &str) -> Value {
    json!({
        "title": title,
        "description": description,
        "type": "object",
        "properties": {
            "x": num_or_null("x"),
            "y": num_or_null("y"),
            "z": num_or_null("z")
        },
        "required": ["x", "y", "z"],
        "additionalProperties": false
    })
}

fn dx_pose(description: &str) -> Value {
    json!({
        "title": "dextrain.Pose",
        "description": description,
        "type": "object",
        "properties": {
            "x": num_or_null("Position x (m)"),
            "y": num_or_null("Position y (m)"),
            "z": num_or_null("Position z (m)"),
            "qx": num_or_null("Orientation quaternion x"),
            "qy": num_or_null("Orientation quaternion y"),
            "qz": num_or_null("Orientation quaternion z"),
            "qw": num_or_null("Orientation quaternion w")
        },
        "required": ["x", "y", "z", "qx", "qy", "qz", "qw"],
        "additionalProperties": false
    })
}

fn dx_joint_array(description: &str) -> Value {
    json!({ "type": "array", "items": num_or_null("value"), "description": description })
}

fn hand_state_schema() -> Value {
    json!({
        "$schema": JSON_SCHEMA_DIALECT,
        "title": SCHEMA_HAND_STATE,
        "description": "Joint state of the simulated hand at one recorded time. The arrays are in joint_names order (the hand's movable joints, mimic followers included). Non-finite values are null.",
        "type": "object",
        "properties": {
            "timestamp": dx_time("Simulated time of the frame"),
            "t": { "type": "number", "description": "Simulated time (s)" },
            "joint_names": { "type": "array", "items": { "type": "string" }, "description": "Joint names" },
            "position": dx_joint_array("Joint positions (rad)"),
            "velocity": dx_joint_array("Joint velocities (rad/s)"),
            "target": dx_joint_array("Joint position targets (rad)")
        },
        "required": ["timestamp", "t", "joint_names", "position", "velocity", "target"],
        "additionalProperties": false
    })
}

fn poses_schema() -> Value {
    json!({
        "$schema": JSON_SCHEMA_DIALECT,
        "title": SCHEMA_POSES,
        "description": "World poses (z up, metres, unit quaternions) of the wrist (root link), the object and, when there is one, the reference object pose. Non-finite values are null.",
        "type": "object",
        "properties": {
            "timestamp": dx_time("Simulated time of the frame"),
            "t": { "type": "number", "description": "Simulated time (s)" },
            "wrist": dx_pose("Wrist (root link) pose"),
            "object": dx_pose("Object pose"),
            "object_ref": {
                "anyOf": [dx_pose("Reference object pose"), { "type": "null" }],
                "description": "Reference object pose, null when there is none"
            }
        },
        "required": ["timestamp", "t", "wrist", "object", "object_ref"],
        "additionalProperties": false
    })
}

fn contacts_schema() -> Value {
    json!({
        "$schema": JSON_SCHEMA_DIALECT,
        "title": SCHEMA_CONTACTS,
        "description": "Contacts at one recorded time, in the world frame. Non-finite values are null.",
        "type": "object",
        "properties": {
            "timestamp": dx_time("Simulated time of the frame"),
            "t": { "type": "number", "description": "Simulated time (s)" },
            "contacts": {
                "type": "array",
                "description": "Contacts",
                "items": {
                    "title": "dextrain.Contact",
                    "description": "One contact between the hand and the object, the hand and the table, or the object and the table",
                    "type": "object",
                    "properties": {
                        "kind": { "type": "string", "enum": ["hand_object", "hand_table", "object_table"], "description": "Pair in contact (first body, second body)" },
                        "index": { "type": "integer", "minimum": 0, "description": "Hand collider index for hand contacts, object support-point index for object_table" },
                        "link": { "type": ["string", "null"], "description": "Name of the hand link owning the collider (hand contacts), else null" },
                        "pos": dx_xyz("dextrain.Vector3", "Contact point (m)"),
                        "normal": dx_xyz("dextrain.Vector3", "Unit normal from the second body to the first"),
                        "depth": num_or_null("Penetration depth (m)"),
                        "force": dx_xyz("dextrain.Vector3", "Total contact force on the first body (N)")
                    },
                    "required": ["kind", "index", "link", "pos", "normal", "depth", "force"],
                    "additionalProperties": false
                }
            }
        },
        "required": ["timestamp", "t", "contacts"],
        "additionalProperties": false
    })
}

// Foxglove schemas, in the form published in foxglove/schemas `schemas/jsonschema/*.json`: a nested
// message takes the field's description; arrays of messages keep the message's own description.

fn fg_time(description: &str) -> Value {
    json!({
        "type": "object",
        "title": "time",
        "properties": {
            "sec": { "type": "integer", "minimum": 0 },
            "nsec": { "type": "integer", "minimum": 0, "maximum": 999_999_999 }
        },
        "description": description
    })
}

fn fg_duration(description: &str) -> Value {
    json!({
        "type": "object",
        "title": "duration",
        "properties": {
            "sec": { "type": "integer", "minimum": -2_147_483_648i64, "maximum": 2_147_483_647 },
            "nsec": { "type": "integer", "minimum": 0, "maximum": 999_999_999 }
        },
        "description": description
    })
}

fn fg_number(description: &str) -> Value {
    json!({ "type": "number", "description": description })
}

fn fg_message(title: &str, description: &str, properties: Value) -> Value {
    json!({ "title": title, "description": description, "type": "object", "properties": properties })
}

fn fg_array(items: Value, description: &str) -> Value {
    json!({ "type": "array", "items": items, "description": description })
}

fn fg_vector3(description: &str) -> Value {
    fg_message(
        "foxglove.Vector3",
        description,
        json!({
            "x": fg_number("x coordinate length"),
            "y": fg_number("y coordinate length"),
            "z": fg_number("z coordinate length")
        }),
    )
}

fn fg_point3(description: &str) -> Value {
    fg_message(
        "foxglove.Point3",
        description,
        json!({
            "x": fg_number("x coordinate position"),
            "y": fg_number("y coordinate position"),
            "z": fg_number("z coordinate position")
        }),
    )
}

fn fg_quaternion(description: &str) -> Value {
    fg_message(
        "foxglove.Quaternion",
        description,
        json!({
            "x": fg_number("x value"),
            "y": fg_number("y value"),
            "z": fg_number("z value"),
            "w": fg_number("w value")
        }),
    )
}

fn fg_pose(description: &str) -> Value {
    fg_message(
        "foxglove.Pose",
        description,
        json!({
            "position": fg_vector3("Point denoting position in 3D space"),
            "orientation": fg_quaternion("Quaternion denoting orientation in 3D space")
        }),
    )
}

fn fg_color(description: &str) -> Value {
    fg_message(
        "foxglove.Color",
        description,
        json!({
            "r": fg_number("Red value between 0 and 1"),
            "g": fg_number("Green value between 0 and 1"),
            "b": fg_number("Blue value between 0 and 1"),
            "a": fg_number("Alpha value between 0 and 1")
        }),
    )
}

const INDICES_DESCRIPTION: &str = "Indices into the `points` and `colors` attribute arrays, which can be used to avoid duplicating attribute data.\n\nIf omitted or empty, indexing will not be used. This default behavior is equivalent to specifying [0, 1, ..., N-1] for the indices (where N is the number of `points` provided).";

fn frame_transforms_schema() -> Value {
    let transform = fg_message(
        "foxglove.FrameTransform",
        "A transform between two reference frames in 3D space",
        json!({
            "timestamp": fg_time("Timestamp of transform"),
            "parent_frame_id": { "type": "string", "description": "Name of the parent frame" },
            "child_frame_id": { "type": "string", "description": "Name of the child frame" },
            "translation": fg_vector3("Translation component of the transform"),
            "rotation": fg_quaternion("Rotation component of the transform")
        }),
    );
    json!({
        "title": "foxglove.FrameTransforms",
        "description": "An array of FrameTransform messages",
        "$comment": "Generated by https://github.com/foxglove/schemas",
        "type": "object",
        "properties": {
            "transforms": fg_array(transform, "Array of transforms")
        }
    })
}

fn scene_update_schema() -> Value {
    let deletion = fg_message(
        "foxglove.SceneEntityDeletion",
        "Command to remove previously published entities",
        json!({
            "timestamp": fg_time("Timestamp of the deletion. Only matching entities earlier than this timestamp will be deleted."),
            "type": {
                "title": "foxglove.SceneEntityDeletionType",
                "description": "Type of deletion action to perform",
                "oneOf": [
                    { "title": "MATCHING_ID", "const": 0, "description": "Delete the existing entity on the same topic that has the provided `id`" },
                    { "title": "ALL", "const": 1, "description": "Delete all existing entities on the same topic" }
                ]
            },
            "id": { "type": "string", "description": "Identifier which must match if `type` is `MATCHING_ID`." }
        }),
    );
    let key_value = fg_message(
        "foxglove.KeyValuePair",
        "A key with its associated value",
        json!({
            "key": { "type": "string", "description": "Key" },
            "value": { "type": "string", "description": "Value" }
        }),
    );
    let arrow = fg_message(
        "foxglove.ArrowPrimitive",
        "A primitive representing an arrow",
        json!({
            "pose": fg_pose("Position of the arrow's tail and orientation of the arrow. Identity orientation means the arrow points in the +x direction."),
            "shaft_length": fg_number("Length of the arrow shaft"),
            "shaft_diameter": fg_number("Diameter of the arrow shaft"),
            "head_length": fg_number("Length of the arrow head"),
            "head_diameter": fg_number("Diameter of the arrow head"),
            "color": fg_color("Color of the arrow")
        }),
    );
    let cube = fg_message(
        "foxglove.CubePrimitive",
        "A primitive representing a cube or rectangular prism",
        json!({
            "pose": fg_pose("Position of the center of the cube and orientation of the cube"),
            "size": fg_vector3("Size of the cube along each axis"),
            "color": fg_color("Color of the cube")
        }),
    );
    let sphere = fg_message(
        "foxglove.SpherePrimitive",
        "A primitive representing a sphere or ellipsoid",
        json!({
            "pose": fg_pose("Position of the center of the sphere and orientation of the sphere"),
            "size": fg_vector3("Size (diameter) of the sphere along each axis"),
            "color": fg_color("Color of the sphere")
        }),
    );
    let cylinder = fg_message(
        "foxglove.CylinderPrimitive",
        "A primitive representing a cylinder, elliptic cylinder, or truncated cone",
        json!({
            "pose": fg_pose("Position of the center of the cylinder and orientation of the cylinder. The flat face(s) are perpendicular to the z-axis."),
            "size": fg_vector3("Size of the cylinder's bounding box"),
            "bottom_scale": fg_number("0-1, ratio of the diameter of the cylinder's bottom face (min z) to the bottom of the bounding box"),
            "top_scale": fg_number("0-1, ratio of the diameter of the cylinder's top face (max z) to the top of the bounding box"),
            "color": fg_color("Color of the cylinder")
        }),
    );
    let line = fg_message(
        "foxglove.LinePrimitive",
        "A primitive representing a series of points connected by lines",
        json!({
            "type": {
                "title": "foxglove.LineType",
                "description": "Drawing primitive to use for lines",
                "oneOf": [
                    { "title": "LINE_STRIP", "const": 0, "description": "Connected line segments: 0-1, 1-2, ..., (n-1)-n" },
                    { "title": "LINE_LOOP", "const": 1, "description": "Closed polygon: 0-1, 1-2, ..., (n-1)-n, n-0" },
                    { "title": "LINE_LIST", "const": 2, "description": "Individual line segments: 0-1, 2-3, 4-5, ..." }
                ]
            },
            "pose": fg_pose("Origin of lines relative to reference frame"),
            "thickness": fg_number("Line thickness"),
            "scale_invariant": { "type": "boolean", "description": "Indicates whether `thickness` is a fixed size in screen pixels (true), or specified in world coordinates and scales with distance from the camera (false)" },
            "points": fg_array(fg_point3("A point representing a position in 3D space"), "Points along the line"),
            "color": fg_color("Solid color to use for the whole line. One of `color` or `colors` must be provided."),
            "colors": fg_array(fg_color("A color in RGBA format"), "Per-point colors (if specified, must have the same length as `points`). One of `color` or `colors` must be provided."),
            "indices": { "type": "array", "items": { "type": "integer", "minimum": 0 }, "description": INDICES_DESCRIPTION }
        }),
    );
    let triangles = fg_message(
        "foxglove.TriangleListPrimitive",
        "A primitive representing a set of triangles or a surface tiled by triangles",
        json!({
            "pose": fg_pose("Origin of triangles relative to reference frame"),
            "points": fg_array(fg_point3("A point representing a position in 3D space"), "Vertices to use for triangles, interpreted as a list of triples (0-1-2, 3-4-5, ...)"),
            "color": fg_color("Solid color to use for the whole shape. One of `color` or `colors` must be provided."),
            "colors": fg_array(fg_color("A color in RGBA format"), "Per-vertex colors (if specified, must have the same length as `points`). One of `color` or `colors` must be provided."),
            "indices": { "type": "array", "items": { "type": "integer", "minimum": 0 }, "description": INDICES_DESCRIPTION }
        }),
    );
    let text = fg_message(
        "foxglove.TextPrimitive",
        "A primitive representing a text label",
        json!({
            "pose": fg_pose("Position of the center of the text box and orientation of the text. Identity orientation means the text is oriented in the xy-plane and flows from -x to +x."),
            "billboard": { "type": "boolean", "description": "Whether the text should respect `pose.orientation` (false) or always face the camera (true)" },
            "font_size": fg_number("Font size (height of one line of text)"),
            "scale_invariant": { "type": "boolean", "description": "Indicates whether `font_size` is a fixed size in screen pixels (true), or specified in world coordinates and scales with distance from the camera (false)" },
            "color": fg_color("Color of the text"),
            "text": { "type": "string", "description": "Text" }
        }),
    );
    let model = fg_message(
        "foxglove.ModelPrimitive",
        "A primitive representing a 3D model file loaded from an external URL or embedded data",
        json!({
            "pose": fg_pose("Origin of model relative to reference frame"),
            "scale": fg_vector3("Scale factor to apply to the model along each axis"),
            "color": fg_color("Solid color to use for the whole model if `override_color` is true."),
            "override_color": { "type": "boolean", "description": "Whether to use the color specified in `color` instead of any materials embedded in the original model." },
            "url": { "type": "string", "description": "URL pointing to model file. One of `url` or `data` should be provided." },
            "media_type": { "type": "string", "description": "[Media type](https://developer.mozilla.org/en-US/docs/Web/HTTP/Basics_of_HTTP/MIME_types) of embedded model (e.g. `model/gltf-binary`). Required if `data` is provided instead of `url`. Overrides the inferred media type if `url` is provided." },
            "data": { "type": "string", "contentEncoding": "base64", "description": "Embedded model. One of `url` or `data` should be provided. If `data` is provided, `media_type` must be set to indicate the type of the data." }
        }),
    );
    let entity = fg_message(
        "foxglove.SceneEntity",
        "A visual element in a 3D scene. An entity may be composed of multiple primitives which all share the same frame of reference.",
        json!({
            "timestamp": fg_time("Timestamp of the entity"),
            "frame_id": { "type": "string", "description": "Frame of reference" },
            "id": { "type": "string", "description": "Identifier for the entity. A entity will replace any prior entity on the same topic with the same `id`." },
            "lifetime": fg_duration("Length of time (relative to `timestamp`) after which the entity should be automatically removed. Zero value indicates the entity should remain visible until it is replaced or deleted."),
            "frame_locked": { "type": "boolean", "description": "Whether the entity should keep its location in the fixed frame (false) or follow the frame specified in `frame_id` as it moves relative to the fixed frame (true)" },
            "metadata": fg_array(key_value, "Additional user-provided metadata associated with the entity. Keys must be unique."),
            "arrows": fg_array(arrow, "Arrow primitives"),
            "cubes": fg_array(cube, "Cube primitives"),
            "spheres": fg_array(sphere, "Sphere primitives"),
            "cylinders": fg_array(cylinder, "Cylinder primitives"),
            "lines": fg_array(line, "Line primitives"),
            "triangles": fg_array(triangles, "Triangle list primitives"),
            "texts": fg_array(text, "Text primitives"),
            "models": fg_array(model, "Model primitives")
        }),
    );
    json!({
        "title": "foxglove.SceneUpdate",
        "description": "An update to the entities displayed in a 3D scene",
        "$comment": "Generated by https://github.com/foxglove/schemas",
        "type": "object",
        "properties": {
            "deletions": fg_array(deletion, "Scene entities to delete"),
            "entities": fg_array(entity, "Scene entities to add or replace")
        }
    })
}
