//! The Foxglove part of rollout frames: the `/tf` transforms and the `/scene` update of one env's
//! frame, for a recording (no prefix: the frame ids of the module docs) or for one env of a live
//! view (`--live`), where every frame id and entity id is under the env's prefix (`env3/`) and
//! the env's own world frame (`env3/world`) is placed in the view's shared `world` by one transform.
//! Several envs' messages are gathered into one [`FoxgloveMessages`] and sent as one message each.

use super::*;

/// Builds the Foxglove messages of one env's frames (see the module docs).
#[derive(Clone, Debug)]
pub struct FoxgloveFrames {
    /// The env's world frame: `world`, or `<prefix>world`.
    world: String,
    object: String,
    object_ref: String,
    /// TF frame id of every link, prefixed.
    link_frames: Vec<String>,
    /// Scene entities that only change by timestamp: hand links, object, table (ids prefixed).
    static_entities: Vec<FgEntity>,
    /// The reference ghost (sent when the frame has an `object_ref`).
    ghost_entity: FgEntity,
    /// Ids of the per-frame entities, prefixed.
    contacts_id: String,
    overlay_id: String,
    ghost_id: String,
}

/// The `/tf` and `/scene` messages of one or several frames, gathered by [`FoxgloveFrames::append`].
#[derive(Debug, Default)]
pub struct FoxgloveMessages {
    transforms: Vec<FgTransform>,
    scene: FgSceneUpdate,
}

impl FoxgloveMessages {
    /// The `foxglove.FrameTransforms` message as JSON.
    pub fn tf_json(&self) -> Result<Vec<u8>> {
        Ok(serde_json::to_vec(&FgFrameTransforms { transforms: &self.transforms })?)
    }

    /// The `foxglove.SceneUpdate` message as JSON.
    pub fn scene_json(&self) -> Result<Vec<u8>> {
        Ok(serde_json::to_vec(&self.scene)?)
    }

    /// Number of scene entities gathered.
    pub fn entity_count(&self) -> usize {
        self.scene.entities.len()
    }
}

impl FoxgloveFrames {
    /// The messages of `meta`'s frames with every frame id and entity id under `prefix` (empty for a
    /// recording).
    pub fn new(meta: &RolloutMeta, prefix: &str) -> FoxgloveFrames {
        let names: Vec<String> = meta.hand.links.iter().map(|l| l.name.clone()).collect();
        let link_frames: Vec<String> = link_frame_ids(&names).into_iter().map(|f| format!("{prefix}{f}")).collect();
        let (mut static_entities, mut ghost_entity) = build_static_entities(meta, &link_frames);
        let world = format!("{prefix}{WORLD_FRAME}");
        let object = format!("{prefix}{OBJECT_FRAME}");
        let object_ref = format!("{prefix}{OBJECT_REF_FRAME}");
        if !prefix.is_empty() {
            for e in static_entities.iter_mut().chain(std::iter::once(&mut ghost_entity)) {
                e.id = format!("{prefix}{}", e.id);
                // (the link entities are already in their prefixed link frames)
                for (plain, prefixed) in [(WORLD_FRAME, &world), (OBJECT_FRAME, &object), (OBJECT_REF_FRAME, &object_ref)] {
                    if e.frame_id == plain {
                        e.frame_id = prefixed.clone();
                    }
                }
            }
        }
        FoxgloveFrames {
            world,
            object,
            object_ref,
            link_frames,
            static_entities,
            ghost_entity,
            contacts_id: format!("{prefix}{ENTITY_CONTACTS}"),
            overlay_id: format!("{prefix}{ENTITY_OVERLAY}"),
            ghost_id: format!("{prefix}{ENTITY_OBJECT_REF}"),
        }
    }

    /// Adds `frame`'s transforms and scene entities to `out`, stamped `stamp_ns`; `placement`: where
    /// this env's world frame sits in the view's `world` (a live view's env grid), None for a
    /// recording (whose world is the view's).
    pub fn append(&self, frame: &RolloutFrame, stamp_ns: u64, placement: Option<Vec3>, out: &mut FoxgloveMessages) {
        let stamp = FgTime::from_ns(stamp_ns);
        if let Some(offset) = placement {
            out.transforms.push(FgTransform::new(stamp, WORLD_FRAME, &self.world, &Pose::new(offset, Quat::IDENTITY)));
        }
        for (i, child) in self.link_frames.iter().enumerate() {
            let pose = if i == 0 { &frame.wrist } else { &frame.links[i] };
            out.transforms.push(FgTransform::new(stamp, &self.world, child, pose));
        }
        out.transforms.push(FgTransform::new(stamp, &self.world, &self.object, &frame.object));
        if let Some(r) = &frame.object_ref {
            out.transforms.push(FgTransform::new(stamp, &self.world, &self.object_ref, r));
        }

        let first = out.scene.entities.len();
        out.scene.entities.extend(self.static_entities.iter().cloned());
        if frame.object_ref.is_some() {
            out.scene.entities.push(self.ghost_entity.clone());
        } else {
            out.scene.deletions.push(FgDeletion { timestamp: stamp, kind: 0, id: self.ghost_id.clone() });
        }
        let mut contacts = contacts_entity(&frame.contacts);
        contacts.id = self.contacts_id.clone();
        contacts.frame_id = self.world.clone();
        out.scene.entities.push(contacts);
        if !frame.overlay.is_empty() {
            let mut overlay = overlay_entity(&frame.overlay);
            overlay.id = self.overlay_id.clone();
            overlay.frame_id = self.world.clone();
            out.scene.entities.push(overlay);
        }
        for e in &mut out.scene.entities[first..] {
            e.timestamp = stamp;
        }
    }
}
