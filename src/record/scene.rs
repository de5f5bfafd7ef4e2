//! The Foxglove scene of a recording: the static entities (hand links, object, table) and the
//! per-frame contact arrows and overlay.

use super::*;

pub(super) const HAND_COLOR: FgColor = FgColor { r: 0.75, g: 0.72, b: 0.68, a: 1.0 };
pub(super) const OBJECT_COLOR: FgColor = FgColor { r: 0.95, g: 0.55, b: 0.15, a: 1.0 };
pub(super) const GHOST_COLOR: FgColor = FgColor { r: 0.2, g: 0.85, b: 0.3, a: 0.3 };
pub(super) const TABLE_COLOR: FgColor = FgColor { r: 0.45, g: 0.42, b: 0.4, a: 1.0 };
pub(super) const CONTACT_POINT_COLOR: FgColor = FgColor { r: 1.0, g: 1.0, b: 0.2, a: 1.0 };
pub(super) const CONTACT_POINT_DIAMETER: f32 = 0.006;
/// The overlay (a human demonstration's keypoints): blue dots joined by lines.
pub(super) const OVERLAY_COLOR: FgColor = FgColor { r: 0.2, g: 0.45, b: 1.0, a: 1.0 };
pub(super) const OVERLAY_POINT_DIAMETER: f32 = 0.008;
pub(super) const OVERLAY_LINE_THICKNESS: f32 = 0.003;

pub(super) fn force_color(kind: ContactKind) -> FgColor {
    match kind {
        ContactKind::HandObject => FgColor { r: 0.9, g: 0.1, b: 0.1, a: 1.0 },
        ContactKind::HandTable => FgColor { r: 0.1, g: 0.3, b: 0.95, a: 1.0 },
        ContactKind::ObjectTable => FgColor { r: 0.1, g: 0.8, b: 0.2, a: 1.0 },
    }
}

#[derive(Default)]
pub(super) struct Prims {
    pub(super) cubes: Vec<FgShape>,
    pub(super) spheres: Vec<FgShape>,
    pub(super) cylinders: Vec<FgCylinder>,
    /// Foxglove TriangleListPrimitive messages (convex-hull pieces).
    pub(super) triangles: Vec<Value>,
}

impl Prims {
    pub(super) fn sphere(&mut self, pose: &Pose, radius: f32, color: FgColor) {
        self.spheres.push(FgShape { pose: FgPose::from(pose), size: fv(Vec3::splat(2.0 * radius)), color });
    }

    pub(super) fn cube(&mut self, pose: &Pose, half_extents: Vec3, color: FgColor) {
        self.cubes.push(FgShape { pose: FgPose::from(pose), size: fv(2.0 * half_extents), color });
    }

    /// A cylinder along the pose's local z.
    pub(super) fn cylinder(&mut self, pose: &Pose, radius: f32, half_length: f32, color: FgColor) {
        self.cylinders.push(FgCylinder {
            pose: FgPose::from(pose),
            size: fv(Vec3::new(2.0 * radius, 2.0 * radius, 2.0 * half_length)),
            bottom_scale: 1.0,
            top_scale: 1.0,
            color,
        });
    }

    /// A capsule along the pose's local z: a cylinder and a sphere at each end.
    pub(super) fn capsule(&mut self, pose: &Pose, radius: f32, half_length: f32, color: FgColor) {
        self.cylinder(pose, radius, half_length, color);
        for s in [-1.0, 1.0] {
            let end = Pose::new(pose.transform_point(Vec3::new(0.0, 0.0, s * half_length)), pose.rot);
            self.sphere(&end, radius, color);
        }
    }

    pub(super) fn object(&mut self, parts: &[ObjectPart], color: FgColor) {
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

    pub(super) fn into_entity(self, id: &str, frame_id: &str, kind: &str) -> FgEntity {
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
pub(super) fn build_static_entities(meta: &RolloutMeta, link_frames: &[String]) -> (Vec<FgEntity>, FgEntity) {
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
/// The overlay's polylines (`RolloutFrame::overlay`): a line strip each, a dot at every vertex.
pub(super) fn overlay_entity(chains: &[Vec<Vec3>]) -> FgEntity {
    let mut p = Prims::default();
    let mut lines = Vec::with_capacity(chains.len());
    for chain in chains {
        let points: Vec<Vec3> = chain.iter().copied().filter(|v| v.is_finite()).collect();
        for v in &points {
            p.sphere(&Pose::new(*v, Quat::IDENTITY), 0.5 * OVERLAY_POINT_DIAMETER, OVERLAY_COLOR);
        }
        lines.push(json!({
            "type": 0, // LINE_STRIP
            "pose": FgPose::from(&Pose::IDENTITY),
            "thickness": OVERLAY_LINE_THICKNESS,
            "scale_invariant": false,
            "points": points.iter().map(|v| json!({"x": v.x, "y": v.y, "z": v.z})).collect::<Vec<_>>(),
            "color": OVERLAY_COLOR,
            "colors": [],
            "indices": [],
        }));
    }
    let mut e = p.into_entity(ENTITY_OVERLAY, WORLD_FRAME, "overlay");
    e.lines = lines;
    e
}

pub(super) fn contacts_entity(contacts: &[ContactRecord]) -> FgEntity {
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
