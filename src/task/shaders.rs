//! The task layer's WGSL: task.wgsl, the reference sampler and the fingertip IK, appended to the
//! simulator's module (task.wgsl reuses the physics' hand kinematics).

use crate::gpu::shaders::{SHADER_COMMON, SHADER_NARROW_ROUNDS, SHADER_PHYSICS, SHADER_RESET};

/// shaders/task.wgsl: the task layer's entry points and bindings 9–12.
pub const SHADER_TASK: &str = include_str!("../../shaders/task.wgsl");
/// shaders/reference.wgsl: the reference sampler and bindings 13–15.
pub const SHADER_REFERENCE: &str = include_str!("../../shaders/reference.wgsl");
/// shaders/ik.wgsl: the fingertip inverse kinematics.
pub const SHADER_IK: &str = include_str!("../../shaders/ik.wgsl");

/// The WGSL module of the task layer: the simulator's module with the reference layer, the
/// fingertip IK and task.wgsl appended (task.wgsl reuses the physics' hand kinematics).
pub fn task_shader_source() -> String {
    [SHADER_COMMON, SHADER_RESET, SHADER_PHYSICS, SHADER_NARROW_ROUNDS, SHADER_REFERENCE, SHADER_IK, SHADER_TASK].join("\n")
}
