//! The WGSL sources of the simulator and of the learner's own kernels (`shaders/`), how they are
//! concatenated into modules, and the workgroup arithmetic of their dispatches. The task layer's
//! sources are `task::shaders`.

/// shaders/common.wgsl: constants, structs, bindings 0–8, maths shared by every shader.
pub const SHADER_COMMON: &str = include_str!("../../shaders/common.wgsl");
/// shaders/reset.wgsl: `reset_main` and the per-env draws.
pub const SHADER_RESET: &str = include_str!("../../shaders/reset.wgsl");
/// shaders/physics.wgsl: `step_main`, one control step.
pub const SHADER_PHYSICS: &str = include_str!("../../shaders/physics.wgsl");
/// shaders/narrow_rounds.wgsl: the physics step's hand–object narrow phases shared out over the
/// workgroup (GPU only; physics.wgsl calls it, every module holding physics.wgsl joins it after).
pub const SHADER_NARROW_ROUNDS: &str = include_str!("../../shaders/narrow_rounds.wgsl");
/// The learner's action noise (appended to common.wgsl; `learn::noise`).
pub const SHADER_NOISE: &str = include_str!("../../shaders/noise.wgsl");
/// The learner's optimiser (a module of its own; `learn::kernels::fused_adam`).
pub const SHADER_ADAM: &str = include_str!("../../shaders/adam.wgsl");
/// The device-resident learners' observation normalisers (a module of its own;
/// `learn::kernels::fused_normalizer`).
pub const SHADER_NORMALIZER: &str = include_str!("../../shaders/normalizer.wgsl");
/// Invocations per workgroup (keep in sync with `WORKGROUP_SIZE` in common.wgsl).
pub const WORKGROUP_SIZE: u32 = 64;

/// The WGSL module the simulator runs: common, reset, physics and its narrow-phase rounds
/// concatenated.
pub fn shader_source() -> String {
    [SHADER_COMMON, SHADER_RESET, SHADER_PHYSICS, SHADER_NARROW_ROUNDS].join("\n")
}

/// Workgroups (x, y) of a dispatch of `invocations` invocations (one per env, or per number drawn):
/// 2-D past 65,535 workgroups, as `env_index` in common.wgsl reads them; at least one.
pub fn workgroups_for(invocations: u32) -> (u32, u32) {
    workgroups_of(invocations, WORKGROUP_SIZE)
}

/// Workgroups (x, y) of `size` invocations each for `invocations` invocations: 2-D past 65,535
/// workgroups (the shader's index is `gid.x + gid.y · nwg.x · size`); at least one.
pub fn workgroups_of(invocations: u32, size: u32) -> (u32, u32) {
    let wg = invocations.div_ceil(size).max(1);
    let x = wg.min(65535);
    (x, wg.div_ceil(x))
}

/// The WGSL module of the learner's action noise: common.wgsl (the counter hash) and noise.wgsl.
pub fn noise_shader_source() -> String {
    [SHADER_COMMON, SHADER_NOISE].join("\n")
}
