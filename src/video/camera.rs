//! The two cameras of a video frame: a fixed one looking at the workspace from the front side,
//! above the table, and one that follows the object (its target eases toward the object's
//! position). Right-handed, z up; wgpu's clip space (depth 0..1, y up).

use glam::{Mat4, Vec3, Vec4};

/// Vertical field of view of both cameras (rad): 45°.
pub const FOV_Y: f32 = std::f32::consts::FRAC_PI_4;
/// Near clip plane (m).
pub const NEAR: f32 = 0.02;
/// Far clip plane (m).
pub const FAR: f32 = 10.0;
/// The fixed camera's target: above the table's centre, where the object rests and the hand works
/// (m, world frame).
pub const FIXED_TARGET: Vec3 = Vec3::new(0.0, 0.0, 0.1);
/// The fixed camera's eye: front right and above (m, world frame).
pub const FIXED_EYE: Vec3 = Vec3::new(0.3, -0.38, 0.3);
/// The follow camera's eye relative to its target (m): the fixed camera's direction, closer.
pub const FOLLOW_OFFSET: Vec3 = Vec3::new(0.17, -0.21, 0.15);
/// Fraction of the way to the object the follow camera's target moves each frame (1 = locked on).
pub const FOLLOW_GAIN: f32 = 0.3;

/// A pinhole camera: eye, the point it looks at, z up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Where the camera is (world, m).
    pub eye: Vec3,
    /// The point it looks at (world, m): the centre of its view.
    pub target: Vec3,
}

impl Camera {
    /// The fixed camera.
    pub fn fixed() -> Camera {
        Camera { eye: FIXED_EYE, target: FIXED_TARGET }
    }

    /// The follow camera looking at `target`.
    pub fn following(target: Vec3) -> Camera {
        Camera { eye: target + FOLLOW_OFFSET, target }
    }

    /// World → clip space for a view of `aspect` = width / height: P · V, with V = look-at (z up)
    /// and P = perspective (FOV_Y, depth 0..1).
    pub fn view_proj(&self, aspect: f32) -> Mat4 {
        perspective(FOV_Y, aspect, NEAR, FAR) * look_at(self.eye, self.target, Vec3::Z)
    }

    /// Where world point `p` lands in a view of `width` × `height` pixels: (column, row) from the
    /// top left, in pixels (fractional); None when it is behind the camera or outside the clip
    /// volume.
    pub fn project(&self, p: Vec3, width: u32, height: u32) -> Option<(f32, f32)> {
        let clip: Vec4 = self.view_proj(width as f32 / height as f32) * p.extend(1.0);
        if clip.w <= 0.0 {
            return None;
        }
        // NDC = clip.xyz / w; x ∈ [−1, 1] left to right, y ∈ [−1, 1] bottom to top, z ∈ [0, 1]
        let ndc = clip.truncate() / clip.w;
        if ndc.x.abs() > 1.0 || ndc.y.abs() > 1.0 || !(0.0..=1.0).contains(&ndc.z) {
            return None;
        }
        // pixel = ((x + 1)/2 · W, (1 − y)/2 · H)
        Some(((ndc.x + 1.0) * 0.5 * width as f32, (1.0 - ndc.y) * 0.5 * height as f32))
    }
}

/// The right-handed view matrix of a camera at `eye` looking at `target`, `up` up: rows
/// (s, −s·eye), (u, −u·eye), (−f, f·eye), (0, 0, 0, 1) with f = (target − eye)/‖·‖, s = f × up
/// normalised, u = s × f (the camera looks down its −z).
fn look_at(eye: Vec3, target: Vec3, up: Vec3) -> Mat4 {
    let f = (target - eye).normalize();
    let s = f.cross(up).normalize();
    let u = s.cross(f);
    Mat4::from_cols(
        Vec4::new(s.x, u.x, -f.x, 0.0),
        Vec4::new(s.y, u.y, -f.y, 0.0),
        Vec4::new(s.z, u.z, -f.z, 0.0),
        Vec4::new(-s.dot(eye), -u.dot(eye), f.dot(eye), 1.0),
    )
}

/// The right-handed perspective projection onto wgpu's clip space (depth 0 at `near`, 1 at
/// `far`): x' = x·h/aspect, y' = y·h with h = 1/tan(fov_y/2), z' = r·z + r·near with
/// r = far/(near − far), w' = −z.
fn perspective(fov_y: f32, aspect: f32, near: f32, far: f32) -> Mat4 {
    let h = 1.0 / (0.5 * fov_y).tan();
    let r = far / (near - far);
    Mat4::from_cols(Vec4::new(h / aspect, 0.0, 0.0, 0.0), Vec4::new(0.0, h, 0.0, 0.0), Vec4::new(0.0, 0.0, r, -1.0), Vec4::new(0.0, 0.0, r * near, 0.0))
}

/// The follow camera's target over an episode: it starts on the object and then moves
/// `FOLLOW_GAIN` of the way to the object's position each frame (a non-finite position leaves it
/// where it is).
#[derive(Clone, Copy, Debug)]
pub struct FollowTarget {
    target: Option<Vec3>,
}

impl FollowTarget {
    /// A target that locks on at its first `update`.
    pub fn new() -> FollowTarget {
        FollowTarget { target: None }
    }

    /// The camera for the frame whose object is at `object`.
    pub fn update(&mut self, object: Vec3) -> Camera {
        let next = match (self.target, object.is_finite()) {
            (None, true) => object,
            // t ← t + g (o − t)
            (Some(t), true) => t + FOLLOW_GAIN * (object - t),
            (Some(t), false) => t,
            (None, false) => FIXED_TARGET,
        };
        self.target = Some(next);
        Camera::following(next)
    }
}

impl Default for FollowTarget {
    fn default() -> Self {
        FollowTarget::new()
    }
}
