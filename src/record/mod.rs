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

use anyhow::{Context, Result, bail};
use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use crate::geom::{ObjectShape, Pose};
use crate::hand::{ColliderShape, HandModel};

mod foxglove_frames;
mod messages;
mod scene;
mod schemas;

pub use foxglove_frames::{FoxgloveFrames, FoxgloveMessages};

use messages::*;
use scene::*;
use schemas::*;

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

/// The pieces of `object` with every length multiplied by `scale` (an env's object scale), for
/// recordings.
pub fn object_parts(object: &crate::object::ObjectModel, scale: f32) -> Vec<ObjectPart> {
    object
        .pieces
        .iter()
        .map(|p| {
            // a hull is drawn as its triangles
            let triangles = p.hull.as_ref().map_or_else(Vec::new, |h| h.faces.iter().flat_map(|f| f.map(|i| (h.vertices[i as usize] * scale).to_array())).collect());
            ObjectPart { shape: p.shape.scaled(scale), pose: Pose::new(p.pose.pos * scale, p.pose.rot), triangles }
        })
        .collect()
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
    /// Polylines drawn beside the rollout (world frame; each a line strip with a dot at every
    /// vertex: a human demonstration's fingers, wrist to tip, beside the robot hand that follows
    /// them); none drawn when empty.
    pub overlay: Vec<Vec<Vec3>>,
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

/// The JSON Schema of the `foxglove.FrameTransforms` messages a recording writes (on `/tf`), for
/// other writers of the same messages (the live view).
pub fn frame_transforms_json_schema() -> Value {
    frame_transforms_schema()
}

/// The JSON Schema of the `foxglove.SceneUpdate` messages a recording writes (on `/scene`).
pub fn scene_update_json_schema() -> Value {
    scene_update_schema()
}

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
pub const ENTITY_OVERLAY: &str = "overlay";

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
    /// Link index of every collider.
    collider_links: Vec<usize>,
    /// The `/tf` and `/scene` messages of a frame.
    foxglove: FoxgloveFrames,
    frames: u64,
}

impl RolloutWriter<BufWriter<File>> {
    /// Starts a recording that [`finish`](Self::finish) will leave at `path`. Writes go to a
    /// temporary file in the same directory. Errors name `path`.
    pub fn create(path: &Path, meta: &RolloutMeta) -> Result<Self> {
        let tmp = crate::files::temp_path_beside(path).with_context(|| format!("creating rollout {}", path.display()))?;
        crate::files::create_parent_dir(path).with_context(|| format!("creating rollout {}", path.display()))?;
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

        Ok(Self {
            mcap: Some(mcap),
            label,
            files: None,
            channel_ids,
            sequences: [0; NUM_CHANNELS],
            joint_names,
            link_names,
            collider_links: hand.colliders.iter().map(|c| c.link).collect(),
            foxglove: FoxgloveFrames::new(meta, ""),
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

        let mut foxglove = FoxgloveMessages::default();
        self.foxglove.append(frame, ns, None, &mut foxglove);

        let payloads: [Vec<u8>; NUM_CHANNELS] = [
            serde_json::to_vec(&hand_state)?,
            serde_json::to_vec(&poses)?,
            serde_json::to_vec(&contacts)?,
            foxglove.tf_json()?,
            foxglove.scene_json()?,
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
