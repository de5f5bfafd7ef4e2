//! The binding table of the shaders: every `@group(0) @binding(k) var<space> name` that the WGSL of
//! `shaders/` declares, as named constants, and the bindings each entry point uses.
//!
//! The Rust side builds every bind group from these constants (`gpu::bind_group`), never from bare
//! indices; `tests/suite/shaders.rs` checks them with naga against the WGSL (name, index, address space of
//! every global, and the globals each entry point really uses), so a binding renamed or moved on one
//! side only fails a test that needs no GPU instead of a pipeline at run time.
//!
//! Bindings 0–8, 16 and 18–21 are the simulator's (common.wgsl), 24 its narrow-phase rounds'
//! (narrow_rounds.wgsl), 9–12 and 17 the task layer's (task.wgsl), 13–15 the reference bank's
//! (reference.wgsl), 22–23 the learner's action noise (noise.wgsl). Indices from 25 up are free
//! for the test kernels of `gpu::run_kernel` (the parity tests use 30 and up).

/// Where a binding lives in WGSL: its address space and, for storage, its access mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BindingSpace {
    /// `var<uniform>`.
    Uniform,
    /// `var<storage, read>`.
    StorageRead,
    /// `var<storage, read_write>`.
    StorageReadWrite,
}

impl BindingSpace {
    /// The buffer usages a buffer bound here needs (uploads and readbacks included).
    pub fn usage(self) -> wgpu::BufferUsages {
        match self {
            BindingSpace::Uniform => wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            BindingSpace::StorageRead | BindingSpace::StorageReadWrite => {
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC
            }
        }
    }
}

/// One `@group(0) @binding(index) var<space> name` of the shaders.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Binding {
    /// The `@binding(k)` index in group 0.
    pub index: u32,
    /// The WGSL variable's name (also the label of the buffer bound to it).
    pub name: &'static str,
    /// The address space (and access) of the WGSL variable.
    pub space: BindingSpace,
}

const fn binding(index: u32, name: &'static str, space: BindingSpace) -> Binding {
    Binding { index, name, space }
}

use BindingSpace::{StorageRead, StorageReadWrite, Uniform};

// ---- the simulator (common.wgsl; bound by gpu.rs) ----
/// `Globals`: the model's constants.
pub const GLOBALS: Binding = binding(0, "g", Uniform);
/// `array<JointDesc>`: the hand's joints.
pub const JOINTS: Binding = binding(1, "joints", StorageRead);
/// `array<ColliderDesc>`: the hand's collision primitives.
pub const COLLIDERS: Binding = binding(2, "colliders", StorageRead);
/// `array<TipDesc>`: the fingertip frames (used by the task layer only).
pub const TIPS: Binding = binding(3, "tips", StorageRead);
/// `array<EnvState>` `[N]`.
pub const STATES: Binding = binding(4, "states", StorageReadWrite);
/// `array<EnvParams>` `[N]`.
pub const PARAMS: Binding = binding(5, "params", StorageReadWrite);
/// `array<Targets>` `[N]` (written by the task layer's `task_act`).
pub const TARGETS: Binding = binding(6, "targets", StorageReadWrite);
/// `array<StepStats>` `[N]`.
pub const STATS: Binding = binding(7, "stats", StorageReadWrite);
/// `array<u32>` `[N]`: reset request per env (0 none, 1 next episode, 2 episode 0).
pub const RESET_MASK: Binding = binding(8, "reset_mask", StorageReadWrite);
/// `array<vec4<f32>>` `[N, n_springs]`: the contact springs (`gpu::layout::spring_slot`).
pub const SPRINGS: Binding = binding(16, "springs", StorageReadWrite);
/// `array<PieceDesc>`: the objects' collision pieces.
pub const PIECES: Binding = binding(18, "pieces", StorageRead);
/// `array<ObjectDesc>`: the run's objects.
pub const OBJECTS: Binding = binding(19, "objects", StorageRead);
/// `array<vec4<f32>>`: the convex-hull pieces' planes, triangles and vertices.
pub const HULLS: Binding = binding(20, "hulls", StorageRead);
/// `array<u32>`: the object of each reference (`SimModel::ref_objects`).
pub const REF_OBJECTS: Binding = binding(21, "ref_objects", StorageRead);
/// `array<vec4<f32>>` `[N, 2, n_colliders, 4]`: the physics step's hand–object queries and their
/// contacts (narrow_rounds.wgsl; scratch of one env step, never read by the host).
pub const NARROW_QUERIES: Binding = binding(24, "narrow_queries", StorageReadWrite);

// ---- the task layer (task.wgsl; bound by task_gpu.rs) ----
/// `TaskGlobals`: the task's constants.
pub const TASK_CFG: Binding = binding(9, "tc", Uniform);
/// `array<TaskState>` `[N]`.
pub const TASK_STATES: Binding = binding(10, "task_states", StorageReadWrite);
/// `array<f32>` `[N, action_dim]`.
pub const ACTIONS: Binding = binding(11, "actions", StorageRead);
/// `array<f32>`: obs `[N, obs_dim]`, priv obs `[N, priv_dim]`, records `[N, OUT_MISC]`.
pub const TASK_OUT: Binding = binding(12, "task_out", StorageReadWrite);
/// `array<f32>`: final obs `[N, obs_dim]`, final priv obs `[N, priv_dim]` (`task_observe_final`).
pub const FINAL_OUT: Binding = binding(17, "final_out", StorageReadWrite);

// ---- the reference bank (reference.wgsl; bound by task_gpu.rs) ----
/// `array<f32>` `[Σ n_frames, stride]`: the reference frames.
pub const REF_FRAMES: Binding = binding(13, "ref_frames", StorageRead);
/// `array<RefInfo>` `[n_refs]`.
pub const REF_INFO: Binding = binding(14, "ref_info", StorageRead);
/// `RefGlobals`: the reference layer's constants.
pub const REF_CFG: Binding = binding(15, "rg", Uniform);

// ---- the learner's action noise (noise.wgsl; bound by learn/noise.rs) ----
/// `NoiseCfg`: seed, draw, rows, columns.
pub const NOISE_CFG: Binding = binding(22, "nc", Uniform);
/// `array<f32>` `[rows, cols]`: the draws.
pub const NOISE_OUT: Binding = binding(23, "noise_out", StorageReadWrite);

/// The bindings one entry point uses. Its bind group lists exactly these: pipelines derive their
/// layout from the shader, which leaves out every global the entry point does not use.
#[derive(Clone, Copy, Debug)]
pub struct EntryBindings {
    /// The `@compute` function's name.
    pub entry_point: &'static str,
    /// The globals it uses (reads, writes or queries), by index.
    pub bindings: &'static [Binding],
}

/// One shader module the Rust side builds, with every binding it declares and the entry points
/// it makes pipelines of.
#[derive(Clone, Copy, Debug)]
pub struct ShaderGroup {
    /// The module's label (named in errors).
    pub shader: &'static str,
    /// Every `@group(0)` global the module declares, by index.
    pub bindings: &'static [Binding],
    /// The entry points the Rust side makes pipelines of.
    pub entry_points: &'static [EntryBindings],
}

/// `step_main`: one control step of every env.
pub const STEP_MAIN: EntryBindings = EntryBindings {
    entry_point: "step_main",
    bindings: &[GLOBALS, JOINTS, COLLIDERS, STATES, PARAMS, TARGETS, STATS, SPRINGS, PIECES, OBJECTS, HULLS, REF_OBJECTS, NARROW_QUERIES],
};
/// `step_main` of a simulator module from before the narrow-phase rounds (af98c83 and earlier,
/// read by `bench --physics-wgsl` to time them against today's): no `narrow_queries`.
pub const STEP_MAIN_WITHOUT_ROUNDS: EntryBindings =
    EntryBindings { entry_point: "step_main", bindings: &[GLOBALS, JOINTS, COLLIDERS, STATES, PARAMS, TARGETS, STATS, SPRINGS, PIECES, OBJECTS, HULLS, REF_OBJECTS] };
/// `reset_main`: the resets that `reset_mask` asks for.
pub const RESET_MAIN: EntryBindings = EntryBindings { entry_point: "reset_main", bindings: &[GLOBALS, JOINTS, STATES, PARAMS, RESET_MASK, SPRINGS, OBJECTS, REF_OBJECTS] };
/// `task_act`: actions → targets.
pub const TASK_ACT: EntryBindings = EntryBindings {
    entry_point: "task_act",
    bindings: &[GLOBALS, JOINTS, TIPS, STATES, TARGETS, TASK_CFG, TASK_STATES, ACTIONS, REF_FRAMES, REF_INFO, REF_CFG],
};
/// `task_reward`: rewards, terms, dones and reset requests.
pub const TASK_REWARD: EntryBindings = EntryBindings {
    entry_point: "task_reward",
    bindings: &[GLOBALS, JOINTS, TIPS, STATES, PARAMS, STATS, RESET_MASK, TASK_CFG, TASK_STATES, TASK_OUT, REF_FRAMES, REF_INFO, REF_CFG],
};
/// `task_observe`: observations (and the task state of the envs just reset).
pub const TASK_OBSERVE: EntryBindings = EntryBindings {
    entry_point: "task_observe",
    bindings: &[GLOBALS, JOINTS, TIPS, STATES, PARAMS, RESET_MASK, TASK_CFG, TASK_STATES, TASK_OUT, FINAL_OUT, REF_FRAMES, REF_INFO, REF_CFG],
};
/// `task_observe_final`: the observations of the ending envs' final states (before the resets).
pub const TASK_OBSERVE_FINAL: EntryBindings = EntryBindings {
    entry_point: "task_observe_final",
    bindings: &[GLOBALS, JOINTS, TIPS, STATES, PARAMS, RESET_MASK, TASK_CFG, TASK_STATES, TASK_OUT, FINAL_OUT, REF_FRAMES, REF_INFO, REF_CFG],
};

/// The simulator's module (`gpu::shader_source`: common + reset + physics).
pub const SIM_GROUP: ShaderGroup = ShaderGroup {
    shader: "dextrain physics",
    bindings: &[GLOBALS, JOINTS, COLLIDERS, TIPS, STATES, PARAMS, TARGETS, STATS, RESET_MASK, SPRINGS, PIECES, OBJECTS, HULLS, REF_OBJECTS, NARROW_QUERIES],
    entry_points: &[STEP_MAIN, RESET_MAIN],
};

/// The task layer's module (`gpu::task_shader_source`: the simulator's, reference, ik and task).
pub const TASK_GROUP: ShaderGroup = ShaderGroup {
    shader: "dextrain task",
    bindings: &[
        GLOBALS, JOINTS, COLLIDERS, TIPS, STATES, PARAMS, TARGETS, STATS, RESET_MASK, TASK_CFG, TASK_STATES, ACTIONS, TASK_OUT, REF_FRAMES,
        REF_INFO, REF_CFG, SPRINGS, FINAL_OUT, PIECES, OBJECTS, HULLS, REF_OBJECTS, NARROW_QUERIES,
    ],
    entry_points: &[TASK_ACT, TASK_REWARD, TASK_OBSERVE, TASK_OBSERVE_FINAL],
};

/// `learner_noise`: standard normal draws for the learner's actions.
pub const LEARNER_NOISE: EntryBindings = EntryBindings { entry_point: "learner_noise", bindings: &[NOISE_CFG, NOISE_OUT] };
/// `learner_uniform`: uniform draws in [−1, 1) (SAC's random actions).
pub const LEARNER_UNIFORM: EntryBindings = EntryBindings { entry_point: "learner_uniform", bindings: &[NOISE_CFG, NOISE_OUT] };

/// The action-noise module (`gpu::noise_shader_source`: common + noise).
pub const NOISE_GROUP: ShaderGroup = ShaderGroup {
    shader: "dextrain action noise",
    bindings: &[GLOBALS, JOINTS, COLLIDERS, TIPS, STATES, PARAMS, TARGETS, STATS, RESET_MASK, SPRINGS, PIECES, OBJECTS, HULLS, REF_OBJECTS, NOISE_CFG, NOISE_OUT],
    entry_points: &[LEARNER_NOISE, LEARNER_UNIFORM],
};

// ---- the GPU learner's matrix product of our own (matmul.wgsl, a module of its own, launched
// by learn/kernels/wgsl_matmul.rs on burn's stream: cubecl binds the buffers in order, then the uniform) ----

/// `array<f32>`: A's memory (any strides).
pub const MM_A: Binding = binding(0, "mm_a", StorageReadWrite);
/// `array<f32>`: B's memory (any strides).
pub const MM_B: Binding = binding(1, "mm_b", StorageReadWrite);
/// `array<f32>` `[batches, M, N]`: the product, row-major.
pub const MM_C: Binding = binding(2, "mm_c", StorageReadWrite);
/// `array<f32>`: the epilogue's operand (the bias `[N]`, or ELU's output `[M, N]`), or the sums
/// of A's row of ones written out `[splits, N]` (any buffer without either).
pub const MM_BIAS: Binding = binding(3, "mm_bias", StorageReadWrite);
/// `MatmulCfg`: the product's sizes, the operands' strides, the epilogue (cubecl's launch constants).
pub const MM_CFG: Binding = binding(4, "mc", Uniform);

/// `matmul_tiled`: one tile of C per workgroup.
pub const MM_TILED: EntryBindings = EntryBindings { entry_point: "matmul_tiled", bindings: &[MM_A, MM_B, MM_C, MM_BIAS, MM_CFG] };

/// The matrix product's module (shaders/matmul.wgsl alone, any tile shape).
pub const MM_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain matmul", bindings: &[MM_A, MM_B, MM_C, MM_BIAS, MM_CFG], entry_points: &[MM_TILED] };

// ---- the partials of a product split over k summed (sum_splits.wgsl, a module of its own, launched
// by learn/kernels/wgsl_matmul.rs on burn's stream: cubecl binds the buffers in order, then the uniform) ----

/// `array<f32>` `[S, len_c]`: the partial products.
pub const SS_PARTIALS: Binding = binding(0, "ss_partials", StorageReadWrite);
/// `array<f32>` `[S, len_s]`: the partial sums of the row of ones (any buffer without them).
pub const SS_SUM_PARTIALS: Binding = binding(1, "ss_sum_partials", StorageReadWrite);
/// `array<f32>` `[len_c]`: the product.
pub const SS_OUT: Binding = binding(2, "ss_out", StorageReadWrite);
/// `array<f32>` `[len_s]`: the row of ones' sums (any buffer without them).
pub const SS_SUMS_OUT: Binding = binding(3, "ss_sums_out", StorageReadWrite);
/// `SumSplitsCfg`: the lengths, the splits and the grid's row length.
pub const SS_CFG: Binding = binding(4, "sc", Uniform);

/// `sum_splits`: one entry per invocation.
pub const SUM_SPLITS: EntryBindings = EntryBindings { entry_point: "sum_splits", bindings: &[SS_PARTIALS, SS_SUM_PARTIALS, SS_OUT, SS_SUMS_OUT, SS_CFG] };

/// The split sums' module (shaders/sum_splits.wgsl alone).
pub const SS_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain sum splits", bindings: &[SS_PARTIALS, SS_SUM_PARTIALS, SS_OUT, SS_SUMS_OUT, SS_CFG], entry_points: &[SUM_SPLITS] };

// ---- ELU's gradient (elu_backward.wgsl, a module of its own, launched by learn/kernels/elu.rs on burn's
// stream: cubecl binds the buffers in order, then the uniform) ----

/// `array<f32>` `[count]`: ELU's output y.
pub const ELU_Y: Binding = binding(0, "elu_y", StorageReadWrite);
/// `array<f32>` `[count]`: ∂L/∂y.
pub const ELU_GRAD: Binding = binding(1, "elu_grad", StorageReadWrite);
/// `array<f32>` `[count]`: ∂L/∂x.
pub const ELU_OUT: Binding = binding(2, "elu_out", StorageReadWrite);
/// `EluCfg`: the entry count and the grid's row length.
pub const ELU_CFG: Binding = binding(3, "ec", Uniform);

/// `elu_backward`: one entry per invocation.
pub const ELU_BACKWARD: EntryBindings = EntryBindings { entry_point: "elu_backward", bindings: &[ELU_Y, ELU_GRAD, ELU_OUT, ELU_CFG] };

/// ELU's gradient module (shaders/elu_backward.wgsl alone).
pub const ELU_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain elu backward", bindings: &[ELU_Y, ELU_GRAD, ELU_OUT, ELU_CFG], entry_points: &[ELU_BACKWARD] };

// ---- ELU (elu_forward.wgsl, a module of its own, launched by learn/kernels/elu.rs on burn's stream:
// cubecl binds the buffers in order, then the uniform) ----

/// `array<f32>` `[count]`: ELU's input x.
pub const ELU_X: Binding = binding(0, "elu_x", StorageReadWrite);
/// `array<f32>` `[count]`: ELU(x).
pub const ELU_Y_OUT: Binding = binding(1, "elu_y_out", StorageReadWrite);
/// `EluForwardCfg`: the entry count and the grid's row length.
pub const ELU_FORWARD_CFG: Binding = binding(2, "efc", Uniform);

/// `elu_forward`: one entry per invocation.
pub const ELU_FORWARD: EntryBindings = EntryBindings { entry_point: "elu_forward", bindings: &[ELU_X, ELU_Y_OUT, ELU_FORWARD_CFG] };

/// ELU's module (shaders/elu_forward.wgsl alone).
pub const ELU_FORWARD_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain elu forward", bindings: &[ELU_X, ELU_Y_OUT, ELU_FORWARD_CFG], entry_points: &[ELU_FORWARD] };

// ---- SAC's device-resident batch (replay_gather.wgsl and replay_window.wgsl, a module each,
// launched by learn/kernels/replay_sample.rs on burn's stream: cubecl binds the buffers in order,
// then the uniform) ----

/// `array<u32>` `[≥ n]`: the ring rows to gather.
pub const RG_ROWS: Binding = binding(0, "rg_rows", StorageReadWrite);
/// `array<f32>` `[piece_rows, dim]`: one piece of a ring.
pub const RG_PIECE: Binding = binding(1, "rg_piece", StorageReadWrite);
/// `array<f32>` `[1, ≥ cols]`: the normaliser's μ.
pub const RG_MEAN: Binding = binding(2, "rg_mean", StorageReadWrite);
/// `array<f32>` `[1, ≥ cols]`: the normaliser's 1 / (σ + ε).
pub const RG_SCALE: Binding = binding(3, "rg_scale", StorageReadWrite);
/// `array<f32>` `[out_first + n, cols]`: the gathered rows.
pub const RG_OUT: Binding = binding(4, "rg_out", StorageReadWrite);
/// `GatherCfg`: the rows, columns, piece and normalisation of one launch.
pub const RG_CFG: Binding = binding(5, "gc", Uniform);

/// `replay_gather`: one output entry per invocation.
pub const REPLAY_GATHER: EntryBindings = EntryBindings { entry_point: "replay_gather", bindings: &[RG_ROWS, RG_PIECE, RG_MEAN, RG_SCALE, RG_OUT, RG_CFG] };

/// The replay gather's module (shaders/replay_gather.wgsl alone).
pub const RG_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain replay gather", bindings: &[RG_ROWS, RG_PIECE, RG_MEAN, RG_SCALE, RG_OUT, RG_CFG], entry_points: &[REPLAY_GATHER] };

/// `array<u32>` `[2 · n_step · B]`: each window step's ring rows, then whether each is written.
pub const RW_IDX: Binding = binding(0, "rw_idx", StorageReadWrite);
/// `array<f32>` `[3 · n_step · B]`: those rows' rewards, done and terminated flags.
pub const RW_FLAGS: Binding = binding(1, "rw_flags", StorageReadWrite);
/// `array<f32>` `[B]`: the n-step return.
pub const RW_RETURN: Binding = binding(2, "rw_return", StorageReadWrite);
/// `array<f32>` `[B]`: the bootstrap factor.
pub const RW_BOOTSTRAP: Binding = binding(3, "rw_bootstrap", StorageReadWrite);
/// `array<u32>` `[B]`: each window's last row.
pub const RW_LAST: Binding = binding(4, "rw_last", StorageReadWrite);
/// `WindowCfg`: the batch, n and γ − 1.
pub const RW_CFG: Binding = binding(5, "wc", Uniform);

/// `replay_window`: one batch row per invocation.
pub const REPLAY_WINDOW: EntryBindings = EntryBindings { entry_point: "replay_window", bindings: &[RW_IDX, RW_FLAGS, RW_RETURN, RW_BOOTSTRAP, RW_LAST, RW_CFG] };

/// The replay windows' module (shaders/replay_window.wgsl alone).
pub const RW_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain replay window", bindings: &[RW_IDX, RW_FLAGS, RW_RETURN, RW_BOOTSTRAP, RW_LAST, RW_CFG], entry_points: &[REPLAY_WINDOW] };

// ---- Column sums (column_sums.wgsl, a module of its own, launched by learn/kernels/row_sums.rs on
// burn's stream: cubecl binds the buffers in order, then the uniform) ----

/// `array<f32>` `[R, C]`: the matrix summed over its rows.
pub const CS_IN: Binding = binding(0, "cs_in", StorageReadWrite);
/// `array<f32>` `[C]`: its column sums.
pub const CS_OUT: Binding = binding(1, "cs_out", StorageReadWrite);
/// `ColumnSumsCfg`: rows, columns and the blocks of the first stage.
pub const CS_CFG: Binding = binding(2, "csc", Uniform);

/// `column_sums`: 16 columns per workgroup.
pub const COLUMN_SUMS: EntryBindings = EntryBindings { entry_point: "column_sums", bindings: &[CS_IN, CS_OUT, CS_CFG] };

/// The column sums' module (shaders/column_sums.wgsl alone).
pub const CS_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain column sums", bindings: &[CS_IN, CS_OUT, CS_CFG], entry_points: &[COLUMN_SUMS] };

// ---- LayerNorm (layer_norm_common.wgsl with layer_norm.wgsl, with or without ELU after it, and
// with each section of layer_norm_backward.wgsl: a module each, launched by
// learn/kernels/layer_norm.rs on burn's stream: cubecl binds the buffers in order, then the
// uniform) ----

/// `array<f32>` `[B, n]`: the rows to normalise.
pub const LN_H: Binding = binding(0, "ln_h", StorageReadWrite);
/// `array<f32>` `[n]`: the gain.
pub const LN_GAIN: Binding = binding(1, "ln_gain", StorageReadWrite);
/// `array<f32>` `[n]`: the shift.
pub const LN_SHIFT: Binding = binding(2, "ln_shift", StorageReadWrite);
/// `array<f32>` `[B, n]`: the output.
pub const LN_Y: Binding = binding(3, "ln_y", StorageReadWrite);
/// `array<f32>` `[B, n]`: the normalised rows ĥ.
pub const LN_NORMED: Binding = binding(4, "ln_normed", StorageReadWrite);
/// `array<f32>` `[B]`: 1/√(σ² + ε) per row.
pub const LN_RSTD: Binding = binding(5, "ln_rstd", StorageReadWrite);
/// `LnCfg`: rows, row length, the grid's row length, ε.
pub const LN_CFG: Binding = binding(6, "lc", Uniform);

/// `layer_norm_forward`: a workgroup per row.
pub const LN_FORWARD: EntryBindings = EntryBindings { entry_point: "layer_norm_forward", bindings: &[LN_H, LN_GAIN, LN_SHIFT, LN_Y, LN_NORMED, LN_RSTD, LN_CFG] };

/// LayerNorm's forward module (shaders/layer_norm_common.wgsl and layer_norm.wgsl).
pub const LN_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain layer norm", bindings: &[LN_H, LN_GAIN, LN_SHIFT, LN_Y, LN_NORMED, LN_RSTD, LN_CFG], entry_points: &[LN_FORWARD] };

/// `array<f32>` `[B, n]`: the normalised rows ĥ of the forward pass.
pub const LNB_NORMED: Binding = binding(0, "lnb_normed", StorageReadWrite);
/// `array<f32>` `[B]`: 1/√(σ² + ε) per row, of the forward pass.
pub const LNB_RSTD: Binding = binding(1, "lnb_rstd", StorageReadWrite);
/// `array<f32>` `[n]`: the gain.
pub const LNB_GAIN: Binding = binding(2, "lnb_gain", StorageReadWrite);
/// `array<f32>` `[B, n]`: ∂L/∂y.
pub const LNB_DY: Binding = binding(3, "lnb_dy", StorageReadWrite);
/// `array<f32>` `[B, n]`: ∂L/∂h.
pub const LNB_DH: Binding = binding(4, "lnb_dh", StorageReadWrite);
/// `array<f32>` `[B, 2n]`: `[∂y ĥ | ∂y]` (its column sums are the gain's and the shift's gradients).
pub const LNB_PARAM_ROWS: Binding = binding(5, "lnb_param_rows", StorageReadWrite);
/// `LnCfg`: rows, row length, the grid's row length, ε.
pub const LNB_CFG: Binding = binding(6, "lbc", Uniform);

/// `layer_norm_backward`: a workgroup per row.
pub const LN_BACKWARD: EntryBindings = EntryBindings { entry_point: "layer_norm_backward", bindings: &[LNB_NORMED, LNB_RSTD, LNB_GAIN, LNB_DY, LNB_DH, LNB_PARAM_ROWS, LNB_CFG] };

/// LayerNorm's backward module (shaders/layer_norm_common.wgsl and layer_norm_backward.wgsl's
/// `layer_norm_backward` section).
pub const LNB_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain layer norm backward", bindings: &[LNB_NORMED, LNB_RSTD, LNB_GAIN, LNB_DY, LNB_DH, LNB_PARAM_ROWS, LNB_CFG], entry_points: &[LN_BACKWARD] };

/// `array<f32>` `[B, n]`: ∂L/∂z for the ELU's output z (LayerNorm then ELU).
pub const LNBE_DZ: Binding = binding(3, "lnb_dz", StorageReadWrite);
/// `array<f32>` `[B, n]`: z = ELU(y), the forward pass's output.
pub const LNBE_Z: Binding = binding(4, "lnb_z", StorageReadWrite);
/// `array<f32>` `[B, n]`: ∂L/∂h.
pub const LNBE_DH: Binding = binding(5, "lnb_dh", StorageReadWrite);
/// `array<f32>` `[B, 2n]`: `[∂y ĥ | ∂y]`.
pub const LNBE_PARAM_ROWS: Binding = binding(6, "lnb_param_rows", StorageReadWrite);
/// `LnCfg`.
pub const LNBE_CFG: Binding = binding(7, "lbc", Uniform);

/// `layer_norm_elu_backward`: a workgroup per row, ELU's gradient first.
pub const LN_ELU_BACKWARD: EntryBindings = EntryBindings { entry_point: "layer_norm_elu_backward", bindings: &[LNB_NORMED, LNB_RSTD, LNB_GAIN, LNBE_DZ, LNBE_Z, LNBE_DH, LNBE_PARAM_ROWS, LNBE_CFG] };

/// LayerNorm then ELU's backward module (layer_norm_common.wgsl and layer_norm_backward.wgsl's
/// `layer_norm_elu_backward` section).
pub const LNBE_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain layer norm elu backward", bindings: &[LNB_NORMED, LNB_RSTD, LNB_GAIN, LNBE_DZ, LNBE_Z, LNBE_DH, LNBE_PARAM_ROWS, LNBE_CFG], entry_points: &[LN_ELU_BACKWARD] };

// ---- SAC's squashed-Gaussian sample (squashed_common.wgsl with squashed_sample.wgsl, and with
// squashed_sample_backward.wgsl: two modules, launched by learn/kernels/squashed.rs on burn's stream:
// cubecl binds the buffers in order, then the uniform) ----

/// `array<f32>` `[B, 2A]`: the actor's head (μ, then the unsquashed log σ).
pub const SQ_HEAD: Binding = binding(0, "sq_head", StorageReadWrite);
/// `array<f32>` `[B, A]`: the noise ε.
pub const SQ_EPS: Binding = binding(1, "sq_eps", StorageReadWrite);
/// `array<f32>` `[B, A + 1]`: the actions, then log π.
pub const SQ_OUT: Binding = binding(2, "sq_out", StorageReadWrite);
/// `SqCfg`: rows, actions, the grid's row length, log σ's range.
pub const SQ_CFG: Binding = binding(3, "sc", Uniform);
/// `array<f32>` `[B, A + 1]`: ∂L/∂a, then ∂L/∂log π (the backward module).
pub const SQ_DOUT: Binding = binding(2, "sq_dout", StorageReadWrite);
/// `array<f32>` `[B, 2A]`: ∂L/∂head (the backward module).
pub const SQ_DHEAD: Binding = binding(3, "sq_dhead", StorageReadWrite);
/// `SqCfg` in the backward module.
pub const SQB_CFG: Binding = binding(4, "sc", Uniform);

/// `squashed_sample`: one row per invocation.
pub const SQ_FORWARD: EntryBindings = EntryBindings { entry_point: "squashed_sample", bindings: &[SQ_HEAD, SQ_EPS, SQ_OUT, SQ_CFG] };
/// `squashed_sample_backward`: one row per invocation.
pub const SQ_BACKWARD: EntryBindings = EntryBindings { entry_point: "squashed_sample_backward", bindings: &[SQ_HEAD, SQ_EPS, SQ_DOUT, SQ_DHEAD, SQB_CFG] };

/// The squashed sample's forward module.
pub const SQ_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain squashed sample", bindings: &[SQ_HEAD, SQ_EPS, SQ_OUT, SQ_CFG], entry_points: &[SQ_FORWARD] };
/// The squashed sample's backward module.
pub const SQB_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain squashed sample backward", bindings: &[SQ_HEAD, SQ_EPS, SQ_DOUT, SQ_DHEAD, SQB_CFG], entry_points: &[SQ_BACKWARD] };

// ---- dextrain's kernels on burn's stream for the learners' losses and the device-resident loop's
// bookkeeping (learn/kernels/ppo_loss.rs, sac_loss.rs, adaptive_lr.rs, standardize.rs,
// ppo_rollout.rs, run/device_loop.rs; each WGSL file a module of its own, bound in this order by
// learn::kernels::wgsl_kernel::launch: the buffers, then the constants as a uniform)

/// [B, A] μ (ppo_loss_rows.wgsl).
pub const PL_ROWS_MU: Binding = binding(0, "pl_mu", StorageReadWrite);
/// [B, 1] V (ppo_loss_rows.wgsl).
pub const PL_ROWS_V: Binding = binding(1, "pl_v", StorageReadWrite);
/// [1, A] log σ (ppo_loss_rows.wgsl).
pub const PL_ROWS_LOG_STD: Binding = binding(2, "pl_log_std", StorageReadWrite);
/// [1, A] σ_old (ppo_loss_rows.wgsl).
pub const PL_ROWS_OLD_SIGMA: Binding = binding(3, "pl_old_sigma", StorageReadWrite);
/// [B, 2A + 4] the minibatch's columns (ppo_loss_rows.wgsl).
pub const PL_ROWS_COLS: Binding = binding(4, "pl_cols", StorageReadWrite);
/// [groups, 3] Σ surrogate, value, KL (ppo_loss_rows.wgsl).
pub const PL_ROWS_PARTIAL: Binding = binding(5, "pl_partial", StorageReadWrite);
/// the launch's constants (ppo_loss_rows.wgsl).
pub const PL_ROWS_CFG: Binding = binding(6, "pc", Uniform);
/// `ppo_loss_rows`: PPO's loss, forward, stage 1 (after ppo_loss_common.wgsl).
pub const PL_ROWS_ENTRY: EntryBindings = EntryBindings { entry_point: "ppo_loss_rows", bindings: &[PL_ROWS_MU, PL_ROWS_V, PL_ROWS_LOG_STD, PL_ROWS_OLD_SIGMA, PL_ROWS_COLS, PL_ROWS_PARTIAL, PL_ROWS_CFG] };
/// shaders/ppo_loss_rows.wgsl.
pub const PL_ROWS_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain ppo loss rows", bindings: &[PL_ROWS_MU, PL_ROWS_V, PL_ROWS_LOG_STD, PL_ROWS_OLD_SIGMA, PL_ROWS_COLS, PL_ROWS_PARTIAL, PL_ROWS_CFG], entry_points: &[PL_ROWS_ENTRY] };

/// [groups, 3] (ppo_loss_finish.wgsl).
pub const PL_FINISH_PARTIAL: Binding = binding(0, "pl_partial", StorageReadWrite);
/// [1, A] log σ (ppo_loss_finish.wgsl).
pub const PL_FINISH_LOG_STD: Binding = binding(1, "pl_log_std", StorageReadWrite);
/// [1, 5] (ppo_loss_finish.wgsl).
pub const PL_FINISH_OUT: Binding = binding(2, "pl_out", StorageReadWrite);
/// the launch's constants (ppo_loss_finish.wgsl).
pub const PL_FINISH_CFG: Binding = binding(3, "pc", Uniform);
/// `ppo_loss_finish`: PPO's loss, forward, stage 2.
pub const PL_FINISH_ENTRY: EntryBindings = EntryBindings { entry_point: "ppo_loss_finish", bindings: &[PL_FINISH_PARTIAL, PL_FINISH_LOG_STD, PL_FINISH_OUT, PL_FINISH_CFG] };
/// shaders/ppo_loss_finish.wgsl.
pub const PL_FINISH_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain ppo loss finish", bindings: &[PL_FINISH_PARTIAL, PL_FINISH_LOG_STD, PL_FINISH_OUT, PL_FINISH_CFG], entry_points: &[PL_FINISH_ENTRY] };

/// [B, A] μ (ppo_loss_backward.wgsl).
pub const PL_BACKWARD_MU: Binding = binding(0, "pl_mu", StorageReadWrite);
/// [B, 1] V (ppo_loss_backward.wgsl).
pub const PL_BACKWARD_V: Binding = binding(1, "pl_v", StorageReadWrite);
/// [1, A] log σ (ppo_loss_backward.wgsl).
pub const PL_BACKWARD_LOG_STD: Binding = binding(2, "pl_log_std", StorageReadWrite);
/// [B, 2A + 4] (ppo_loss_backward.wgsl).
pub const PL_BACKWARD_COLS: Binding = binding(3, "pl_cols", StorageReadWrite);
/// [1, 5] ∂L/∂out (∂L/∂total first) (ppo_loss_backward.wgsl).
pub const PL_BACKWARD_DOUT: Binding = binding(4, "pl_dout", StorageReadWrite);
/// [B, A] ∂L/∂μ (ppo_loss_backward.wgsl).
pub const PL_BACKWARD_DMU: Binding = binding(5, "pl_dmu", StorageReadWrite);
/// [B, 1] ∂L/∂V (ppo_loss_backward.wgsl).
pub const PL_BACKWARD_DV: Binding = binding(6, "pl_dv", StorageReadWrite);
/// [groups, A] Σ over rows of ∂L/∂log σ's row terms (ppo_loss_backward.wgsl).
pub const PL_BACKWARD_PARTIAL: Binding = binding(7, "pl_partial", StorageReadWrite);
/// the launch's constants (ppo_loss_backward.wgsl).
pub const PL_BACKWARD_CFG: Binding = binding(8, "pc", Uniform);
/// `ppo_loss_backward`: PPO's loss, backward, stage 1.
pub const PL_BACKWARD_ENTRY: EntryBindings = EntryBindings { entry_point: "ppo_loss_backward", bindings: &[PL_BACKWARD_MU, PL_BACKWARD_V, PL_BACKWARD_LOG_STD, PL_BACKWARD_COLS, PL_BACKWARD_DOUT, PL_BACKWARD_DMU, PL_BACKWARD_DV, PL_BACKWARD_PARTIAL, PL_BACKWARD_CFG] };
/// shaders/ppo_loss_backward.wgsl.
pub const PL_BACKWARD_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain ppo loss backward", bindings: &[PL_BACKWARD_MU, PL_BACKWARD_V, PL_BACKWARD_LOG_STD, PL_BACKWARD_COLS, PL_BACKWARD_DOUT, PL_BACKWARD_DMU, PL_BACKWARD_DV, PL_BACKWARD_PARTIAL, PL_BACKWARD_CFG], entry_points: &[PL_BACKWARD_ENTRY] };

/// [groups, A] (ppo_loss_backward_finish.wgsl).
pub const PL_BACKWARD_FINISH_PARTIAL: Binding = binding(0, "pl_partial", StorageReadWrite);
/// [1, 5] ∂L/∂out (ppo_loss_backward_finish.wgsl).
pub const PL_BACKWARD_FINISH_DOUT: Binding = binding(1, "pl_dout", StorageReadWrite);
/// [1, A] ∂L/∂ log σ (ppo_loss_backward_finish.wgsl).
pub const PL_BACKWARD_FINISH_DLOG_STD: Binding = binding(2, "pl_dlog_std", StorageReadWrite);
/// the launch's constants (ppo_loss_backward_finish.wgsl).
pub const PL_BACKWARD_FINISH_CFG: Binding = binding(3, "pc", Uniform);
/// `ppo_loss_backward_finish`: PPO's loss, backward, stage 2.
pub const PL_BACKWARD_FINISH_ENTRY: EntryBindings = EntryBindings { entry_point: "ppo_loss_backward_finish", bindings: &[PL_BACKWARD_FINISH_PARTIAL, PL_BACKWARD_FINISH_DOUT, PL_BACKWARD_FINISH_DLOG_STD, PL_BACKWARD_FINISH_CFG] };
/// shaders/ppo_loss_backward_finish.wgsl.
pub const PL_BACKWARD_FINISH_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain ppo loss backward finish", bindings: &[PL_BACKWARD_FINISH_PARTIAL, PL_BACKWARD_FINISH_DOUT, PL_BACKWARD_FINISH_DLOG_STD, PL_BACKWARD_FINISH_CFG], entry_points: &[PL_BACKWARD_FINISH_ENTRY] };

/// [B, 1] (sac_loss_rows.wgsl).
pub const SL_ROWS_A: Binding = binding(0, "sl_a", StorageReadWrite);
/// [B, 1] (sac_loss_rows.wgsl).
pub const SL_ROWS_B: Binding = binding(1, "sl_b", StorageReadWrite);
/// [1, 1] log α (kind 1) (sac_loss_rows.wgsl).
pub const SL_ROWS_ALPHA: Binding = binding(2, "sl_alpha", StorageReadWrite);
/// [groups, 2] (sac_loss_rows.wgsl).
pub const SL_ROWS_PARTIAL: Binding = binding(3, "sl_partial", StorageReadWrite);
/// the launch's constants (sac_loss_rows.wgsl).
pub const SL_ROWS_CFG: Binding = binding(4, "sc", Uniform);
/// `sac_loss_rows`: SAC's per-row losses, forward, stage 1 (after sac_loss_common.wgsl).
pub const SL_ROWS_ENTRY: EntryBindings = EntryBindings { entry_point: "sac_loss_rows", bindings: &[SL_ROWS_A, SL_ROWS_B, SL_ROWS_ALPHA, SL_ROWS_PARTIAL, SL_ROWS_CFG] };
/// shaders/sac_loss_rows.wgsl.
pub const SL_ROWS_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain sac loss rows", bindings: &[SL_ROWS_A, SL_ROWS_B, SL_ROWS_ALPHA, SL_ROWS_PARTIAL, SL_ROWS_CFG], entry_points: &[SL_ROWS_ENTRY] };

/// [groups, 2] (sac_loss_finish.wgsl).
pub const SL_FINISH_PARTIAL: Binding = binding(0, "sl_partial", StorageReadWrite);
/// [1, 2] (sac_loss_finish.wgsl).
pub const SL_FINISH_OUT: Binding = binding(1, "sl_out", StorageReadWrite);
/// the launch's constants (sac_loss_finish.wgsl).
pub const SL_FINISH_CFG: Binding = binding(2, "sc", Uniform);
/// `sac_loss_finish`: SAC's per-row losses, forward, stage 2.
pub const SL_FINISH_ENTRY: EntryBindings = EntryBindings { entry_point: "sac_loss_finish", bindings: &[SL_FINISH_PARTIAL, SL_FINISH_OUT, SL_FINISH_CFG] };
/// shaders/sac_loss_finish.wgsl.
pub const SL_FINISH_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain sac loss finish", bindings: &[SL_FINISH_PARTIAL, SL_FINISH_OUT, SL_FINISH_CFG], entry_points: &[SL_FINISH_ENTRY] };

/// [B, 1] (sac_loss_backward.wgsl).
pub const SL_BACKWARD_A: Binding = binding(0, "sl_a", StorageReadWrite);
/// [B, 1] (sac_loss_backward.wgsl).
pub const SL_BACKWARD_B: Binding = binding(1, "sl_b", StorageReadWrite);
/// [1, 1] log α (kind 1) (sac_loss_backward.wgsl).
pub const SL_BACKWARD_ALPHA: Binding = binding(2, "sl_alpha", StorageReadWrite);
/// [1, 2] ∂L/∂out (sac_loss_backward.wgsl).
pub const SL_BACKWARD_DOUT: Binding = binding(3, "sl_dout", StorageReadWrite);
/// [B, 1] (sac_loss_backward.wgsl).
pub const SL_BACKWARD_DA: Binding = binding(4, "sl_da", StorageReadWrite);
/// [B, 1] (sac_loss_backward.wgsl).
pub const SL_BACKWARD_DB: Binding = binding(5, "sl_db", StorageReadWrite);
/// the launch's constants (sac_loss_backward.wgsl).
pub const SL_BACKWARD_CFG: Binding = binding(6, "sc", Uniform);
/// `sac_loss_backward`: SAC's per-row losses, backward.
pub const SL_BACKWARD_ENTRY: EntryBindings = EntryBindings { entry_point: "sac_loss_backward", bindings: &[SL_BACKWARD_A, SL_BACKWARD_B, SL_BACKWARD_ALPHA, SL_BACKWARD_DOUT, SL_BACKWARD_DA, SL_BACKWARD_DB, SL_BACKWARD_CFG] };
/// shaders/sac_loss_backward.wgsl.
pub const SL_BACKWARD_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain sac loss backward", bindings: &[SL_BACKWARD_A, SL_BACKWARD_B, SL_BACKWARD_ALPHA, SL_BACKWARD_DOUT, SL_BACKWARD_DA, SL_BACKWARD_DB, SL_BACKWARD_CFG], entry_points: &[SL_BACKWARD_ENTRY] };

/// [1, 1] the learning rate (adaptive_lr.wgsl).
pub const AL_LR: Binding = binding(0, "al_lr", StorageReadWrite);
/// [1, n] holding the KL at `column` (adaptive_lr.wgsl).
pub const AL_KL_ROW: Binding = binding(1, "al_kl_row", StorageReadWrite);
/// [1, 1] the adapted learning rate (adaptive_lr.wgsl).
pub const AL_OUT: Binding = binding(2, "al_out", StorageReadWrite);
/// the launch's constants (adaptive_lr.wgsl).
pub const AL_CFG: Binding = binding(3, "ac", Uniform);
/// `adaptive_lr`: PPO's adaptive learning rate.
pub const AL_ENTRY: EntryBindings = EntryBindings { entry_point: "adaptive_lr", bindings: &[AL_LR, AL_KL_ROW, AL_OUT, AL_CFG] };
/// shaders/adaptive_lr.wgsl.
pub const AL_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain adaptive lr", bindings: &[AL_LR, AL_KL_ROW, AL_OUT, AL_CFG], entry_points: &[AL_ENTRY] };

/// [rows, dim] (standardize.wgsl).
pub const ST_X: Binding = binding(0, "st_x", StorageReadWrite);
/// [2, dim] μ, then s (standardize.wgsl).
pub const ST_STATS: Binding = binding(1, "st_stats", StorageReadWrite);
/// [rows, dim] (standardize.wgsl).
pub const ST_OUT: Binding = binding(2, "st_out", StorageReadWrite);
/// the launch's constants (standardize.wgsl).
pub const ST_CFG: Binding = binding(3, "sc", Uniform);
/// `standardize`: a host-path batch's standardisation.
pub const ST_ENTRY: EntryBindings = EntryBindings { entry_point: "standardize", bindings: &[ST_X, ST_STATS, ST_OUT, ST_CFG] };
/// shaders/standardize.wgsl.
pub const ST_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain standardize", bindings: &[ST_X, ST_STATS, ST_OUT, ST_CFG], entry_points: &[ST_ENTRY] };

/// [N, 1] the env's reward (ppo_step_reward.wgsl).
pub const SR_REWARD: Binding = binding(0, "sr_reward", StorageReadWrite);
/// [N, 1] (ppo_step_reward.wgsl).
pub const SR_TERMINATED: Binding = binding(1, "sr_terminated", StorageReadWrite);
/// [N, 1] (ppo_step_reward.wgsl).
pub const SR_TIME_OUT: Binding = binding(2, "sr_time_out", StorageReadWrite);
/// [N, 1] V(s_t) (ppo_step_reward.wgsl).
pub const SR_VALUES: Binding = binding(3, "sr_values", StorageReadWrite);
/// [N, 2] r', done (ppo_step_reward.wgsl).
pub const SR_OUT: Binding = binding(4, "sr_out", StorageReadWrite);
/// the launch's constants (ppo_step_reward.wgsl).
pub const SR_CFG: Binding = binding(5, "rc", Uniform);
/// `ppo_step_reward`: PPO's step reward and done flag.
pub const SR_ENTRY: EntryBindings = EntryBindings { entry_point: "ppo_step_reward", bindings: &[SR_REWARD, SR_TERMINATED, SR_TIME_OUT, SR_VALUES, SR_OUT, SR_CFG] };
/// shaders/ppo_step_reward.wgsl.
pub const SR_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain ppo step reward", bindings: &[SR_REWARD, SR_TERMINATED, SR_TIME_OUT, SR_VALUES, SR_OUT, SR_CFG], entry_points: &[SR_ENTRY] };

/// [T · N, 2] r', done (gae.wgsl).
pub const GAE_RD: Binding = binding(0, "gae_rd", StorageReadWrite);
/// [T · N, 1] V(s_t) (gae.wgsl).
pub const GAE_VALUES: Binding = binding(1, "gae_values", StorageReadWrite);
/// [N, 1] V(s_T) (gae.wgsl).
pub const GAE_LAST: Binding = binding(2, "gae_last", StorageReadWrite);
/// [T · N, 1] A_t (gae.wgsl).
pub const GAE_ADV: Binding = binding(3, "gae_adv", StorageReadWrite);
/// the launch's constants (gae.wgsl).
pub const GAE_CFG: Binding = binding(4, "gc", Uniform);
/// `gae`: GAE over a device-resident rollout.
pub const GAE_ENTRY: EntryBindings = EntryBindings { entry_point: "gae", bindings: &[GAE_RD, GAE_VALUES, GAE_LAST, GAE_ADV, GAE_CFG] };
/// shaders/gae.wgsl.
pub const GAE_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain gae", bindings: &[GAE_RD, GAE_VALUES, GAE_LAST, GAE_ADV, GAE_CFG], entry_points: &[GAE_ENTRY] };

/// [N, A] (loop_sums.wgsl).
pub const LS_ACTIONS: Binding = binding(0, "ls_actions", StorageReadWrite);
/// [N, M] the step's output records (loop_sums.wgsl).
pub const LS_MISC: Binding = binding(1, "ls_misc", StorageReadWrite);
/// [N, 2M + 6] before the step (loop_sums.wgsl).
pub const LS_ACC: Binding = binding(2, "ls_acc", StorageReadWrite);
/// [N, 2M + 6] after it (loop_sums.wgsl).
pub const LS_ACC_OUT: Binding = binding(3, "ls_acc_out", StorageReadWrite);
/// [N, 1] (loop_sums.wgsl).
pub const LS_REWARD: Binding = binding(4, "ls_reward", StorageReadWrite);
/// [N, 1] (loop_sums.wgsl).
pub const LS_TERMINATED: Binding = binding(5, "ls_terminated", StorageReadWrite);
/// [N, 1] (loop_sums.wgsl).
pub const LS_TIME_OUT: Binding = binding(6, "ls_time_out", StorageReadWrite);
/// the launch's constants (loop_sums.wgsl).
pub const LS_CFG: Binding = binding(7, "lc", Uniform);
/// `loop_sums`: the device-resident env loop's per-env sums.
pub const LS_ENTRY: EntryBindings = EntryBindings { entry_point: "loop_sums", bindings: &[LS_ACTIONS, LS_MISC, LS_ACC, LS_ACC_OUT, LS_REWARD, LS_TERMINATED, LS_TIME_OUT, LS_CFG] };
/// shaders/loop_sums.wgsl.
pub const LS_GROUP: ShaderGroup = ShaderGroup { shader: "dextrain loop sums", bindings: &[LS_ACTIONS, LS_MISC, LS_ACC, LS_ACC_OUT, LS_REWARD, LS_TERMINATED, LS_TIME_OUT, LS_CFG], entry_points: &[LS_ENTRY] };

