//! Retargeting-like errors on the hand part of a reference: what `dextrain traj synth --count N`
//! writes so that open-loop replay fails often and a residual policy is needed (issue 4, item 5).
//!
//! A human demonstration retargeted to a robot hand has the object's motion right (it was tracked)
//! and the hand's motion slightly wrong: the wrist sits a little off the object, the finger
//! postures are off, the hand's schedule is early or late against the object's, and the signal is
//! noisy. [`perturb`] makes such a reference from a clean one; the object part is never changed.
//!
//! For reference `index` of a dataset (all draws from one `Rng` seeded by `(seed, index)`):
//! 1. time shift `τ ~ U(−time_shift, time_shift)`: the hand at time t is the clean hand at
//!    `clamp(t − τ, 0, duration)` (τ > 0: the hand is late against the object);
//! 2. wrist offset: a constant translation drawn uniformly in the ball of radius `wrist_offset` and
//!    a constant rotation by `U(0, wrist_rot_offset)` about a uniform random axis, applied to the
//!    wrist in the world frame (`p + δ`, `exp(ω) ⊗ q`);
//! 3. joint offsets: per actuated joint `U(−joint_offset, joint_offset)`;
//! 4. noise: per output frame, Gaussian `N(0, wrist_noise²)` on each wrist coordinate and
//!    `N(0, joint_noise²)` on each actuated joint;
//! 5. joints clamped to their limits, mimic followers recomputed from their leaders, fingertips
//!    recomputed by forward kinematics from the perturbed wrist and joints (the hand part stays
//!    self-consistent).
//!
//! The output has keyframes at `rate` Hz (`Trajectory::resample`), plus the last instant.

use anyhow::{Result, bail};
use glam::{Quat, Vec3};

use super::{Keyframe, Trajectory};
use crate::hand::HandModel;
use crate::rng::Rng;

/// The sizes of the errors (see the module documentation); all zero = a clean resampled copy.
#[derive(clap::Args, Debug, Clone, PartialEq)]
pub struct PerturbArgs {
    /// Half-range (s) of the shift of the hand's schedule against the object's.
    #[arg(long, default_value_t = 0.0)]
    pub time_shift: f32,
    /// Radius (m) of the constant wrist position offset.
    #[arg(long, default_value_t = 0.0)]
    pub wrist_offset: f32,
    /// Largest angle (rad) of the constant wrist rotation offset.
    #[arg(long, default_value_t = 0.0)]
    pub wrist_rot_offset: f32,
    /// Half-range (rad) of the constant offset of each actuated joint.
    #[arg(long, default_value_t = 0.0)]
    pub joint_offset: f32,
    /// Standard deviation (m) of the per-frame noise on each wrist coordinate.
    #[arg(long, default_value_t = 0.0)]
    pub wrist_noise: f32,
    /// Standard deviation (rad) of the per-frame noise on each actuated joint.
    #[arg(long, default_value_t = 0.0)]
    pub joint_noise: f32,
    /// Keyframes per second of a perturbed reference.
    #[arg(long, default_value_t = 30.0)]
    pub rate: f32,
}

impl Default for PerturbArgs {
    fn default() -> Self {
        PerturbArgs { time_shift: 0.0, wrist_offset: 0.0, wrist_rot_offset: 0.0, joint_offset: 0.0, wrist_noise: 0.0, joint_noise: 0.0, rate: 30.0 }
    }
}

impl PerturbArgs {
    /// Whether any error is switched on.
    pub fn is_active(&self) -> bool {
        [self.time_shift, self.wrist_offset, self.wrist_rot_offset, self.joint_offset, self.wrist_noise, self.joint_noise].iter().any(|&v| v != 0.0)
    }

    /// One-line errors naming the flag.
    pub fn validate(&self) -> Result<()> {
        for (name, v) in [
            ("--time-shift", self.time_shift),
            ("--wrist-offset", self.wrist_offset),
            ("--wrist-rot-offset", self.wrist_rot_offset),
            ("--joint-offset", self.joint_offset),
            ("--wrist-noise", self.wrist_noise),
            ("--joint-noise", self.joint_noise),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                bail!("{name} = {v}: expected a finite number ≥ 0");
            }
        }
        if !(self.rate.is_finite() && self.rate > 0.0 && self.rate <= 1000.0) {
            bail!("--rate = {}: expected keyframes per second in (0, 1000]", self.rate);
        }
        Ok(())
    }
}

/// Reference `index` of a perturbed dataset made from `clean` for `hand` (joint names must be the
/// hand's, as `synth` writes them). Deterministic in `(seed, index)`.
pub fn perturb(clean: &Trajectory, hand: &HandModel, args: &PerturbArgs, seed: u64, index: u64) -> Result<Trajectory> {
    args.validate()?;
    let map = clean.joint_map(&hand.joints.iter().map(|j| j.name.clone()).collect::<Vec<_>>())?;
    if map.iter().any(|m| m.is_none()) {
        bail!("perturb: the reference must name every joint of the hand {}", hand.source.display());
    }
    let mut rng = Rng::new(seed, 0x7065_7274_0000 + index);
    let mut u = |lo: f32, hi: f32| lo + (hi - lo) * rng.uniform() as f32;
    let tau = u(-args.time_shift, args.time_shift) as f64;
    // a uniform point in the ball: direction from a normalised Gaussian-free construction (uniform
    // z and azimuth), radius r·∛u
    let dir = |z: f32, phi: f32| {
        let s = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(s * phi.cos(), s * phi.sin(), z)
    };
    let off_dir = dir(u(-1.0, 1.0), u(0.0, std::f32::consts::TAU));
    let off = off_dir * args.wrist_offset * u(0.0, 1.0).cbrt();
    let rot_axis = dir(u(-1.0, 1.0), u(0.0, std::f32::consts::TAU));
    let rot_off = Quat::from_axis_angle(rot_axis, u(0.0, args.wrist_rot_offset));
    let leaders: Vec<usize> = (0..hand.joints.len()).filter(|&j| hand.joints[j].mimic.is_none()).collect();
    let joint_off: Vec<f32> = leaders.iter().map(|_| u(-args.joint_offset, args.joint_offset)).collect();
    let mut rng = Rng::new(seed, 0x6e6f_6973_0000 + index);
    let mut gauss = |sigma: f32| if sigma > 0.0 { sigma * rng.normal() as f32 } else { 0.0 };

    let duration = clean.duration();
    let times = clean.resample(1.0 / args.rate as f64);
    let mut frames = Vec::with_capacity(times.frames.len());
    for f in &times.frames {
        let object = clean.sample(f.t).object;
        // the hand at the shifted time
        let h = clean.sample((f.t - tau).clamp(0.0, duration));
        let mut wrist = h.wrist;
        wrist.pos += off + Vec3::new(gauss(args.wrist_noise), gauss(args.wrist_noise), gauss(args.wrist_noise));
        if args.wrist_rot_offset > 0.0 {
            wrist.rot = (rot_off * wrist.rot).normalize(); // exp(ω) ⊗ q
        }
        // joints in hand order, offset and noise on the leaders, then limits and followers
        let mut q: Vec<f32> = map.iter().map(|m| h.joints[m.expect("checked")]).collect();
        for (k, &j) in leaders.iter().enumerate() {
            let jt = &hand.joints[j];
            q[j] = (q[j] + joint_off[k] + gauss(args.joint_noise)).max(jt.lower).min(jt.upper);
        }
        for (j, jt) in hand.joints.iter().enumerate() {
            if let Some(m) = jt.mimic {
                q[j] = m.multiplier * q[m.leader] + m.offset;
            }
        }
        let links = hand.forward_kinematics(&q);
        let tips = hand.fingertips.iter().map(|tp| wrist.transform_point(links[tp.link].transform_point(tp.pos))).collect();
        // back to the reference's joint column order
        let mut joints = vec![0.0f32; clean.joint_names.len()];
        for (j, m) in map.iter().enumerate() {
            joints[m.expect("checked")] = q[j];
        }
        frames.push(Keyframe { t: f.t, wrist, joints, fingertips: Some(tips), object });
    }
    let out = Trajectory {
        joint_names: clean.joint_names.clone(),
        fingertip_names: hand.fingertips.iter().map(|t| t.name.clone()).collect(),
        frames,
        object_name: clean.object_name.clone(),
    };
    out.validate()?;
    Ok(out)
}
