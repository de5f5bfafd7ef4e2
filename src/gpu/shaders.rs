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
/// Invocations per workgroup (keep in sync with `WORKGROUP_SIZE` in common.wgsl).
pub const WORKGROUP_SIZE: u32 = 64;

/// The WGSL module the simulator runs: common, reset, physics and its narrow-phase rounds
/// concatenated, its kernels at [`WORKGROUP_SIZE`] invocations a workgroup.
pub fn shader_source() -> String {
    [SHADER_COMMON, SHADER_RESET, SHADER_PHYSICS, SHADER_NARROW_ROUNDS].join("\n")
}

/// The texts of the simulator's module that set its workgroup size (common.wgsl's constant, which
/// the rounds' lists and `env_index` read, and the two entry points' attributes), each once in
/// [`shader_source`].
const WORKGROUP_SIZE_TEXTS: [(&str, &str); 3] = [
    ("const WORKGROUP_SIZE: u32 = 64u;", "const WORKGROUP_SIZE: u32 = {}u;"),
    ("@compute @workgroup_size(64)\nfn reset_main(", "@compute @workgroup_size({})\nfn reset_main("),
    ("@compute @workgroup_size(64)\nfn step_main(", "@compute @workgroup_size({})\nfn step_main("),
];

/// The text of the simulator's module that sets the words of its collider bit lists
/// (common.wgsl's `REVISIT_WORDS`: 8, for `hand::MAX_COLLIDERS` = 256), once in [`shader_source`].
const COLLIDER_WORDS_TEXT: (&str, &str) = ("const REVISIT_WORDS: u32 = 8u;", "const REVISIT_WORDS: u32 = {}u;");

/// The words of a collider bit list (bit ci % 32 of word ci / 32) for a hand of `n_colliders`
/// colliders: 1 to 8.
pub fn collider_words(n_colliders: usize) -> u32 {
    n_colliders.div_ceil(32).clamp(1, crate::hand::MAX_COLLIDERS / 32) as u32
}

/// [`shader_source`] for a batch: `step_main` and `reset_main` at `workgroup_size` invocations a
/// workgroup (the narrow-phase rounds shared out over that many envs), and the collider bit lists
/// (the pass's lists of pairs, the rounds' lists in workgroup memory) of `collider_words` words,
/// [`collider_words`] of the model's hand, where the text has room for 256 colliders. The same
/// physics, query for query: a list's words past the hand's colliders are always zero.
pub fn shader_source_at(workgroup_size: u32, collider_words: u32) -> String {
    let mut source = shader_source();
    let texts = WORKGROUP_SIZE_TEXTS.map(|t| (t, workgroup_size)).into_iter().chain([(COLLIDER_WORDS_TEXT, collider_words)]);
    for ((text, sized), value) in texts {
        debug_assert_eq!(source.matches(text).count(), 1, "the simulator's module should hold {text:?} once");
        source = source.replace(text, &sized.replace("{}", &value.to_string()));
    }
    source
}

/// The step's workgroup sizes the simulator chooses from, largest first.
pub const STEP_WORKGROUP_SIZES: [u32; 5] = [512, 256, 128, 64, 32];

/// The workgroups a batch's step should at least make (about one per multiprocessor of an H100 or
/// H200, which have 132).
pub const MIN_STEP_WORKGROUPS: usize = 128;

/// The simulator step's workgroup size for `n_envs` envs: the largest of
/// [`STEP_WORKGROUP_SIZES`] that leaves at least [`MIN_STEP_WORKGROUPS`] workgroups and that
/// `fits` the device (its workgroup memory and invocation limits), else the smallest. On an H200
/// (2026-12-01, BENCHMARKS.md "The step's workgroup size") the bench scene at 65,536 envs stepped
/// 1.50× faster in workgroups of 512 than of 64 (the driver left 128 registers an invocation
/// where it took 168, and each round shared its queries over 512 envs), 1.33× in 256, 1.20× in
/// 128, 0.82× in 32; at 2,048 envs (the lift configs') workgroups of 32 were 1.16× faster than
/// of 64 (64 multiprocessors at work instead of 32), 512 0.50×.
pub fn step_workgroup_size(n_envs: usize, fits: impl Fn(u32) -> bool) -> u32 {
    let smallest = STEP_WORKGROUP_SIZES[STEP_WORKGROUP_SIZES.len() - 1];
    STEP_WORKGROUP_SIZES.into_iter().find(|&size| n_envs >= MIN_STEP_WORKGROUPS * size as usize && fits(size)).unwrap_or(smallest)
}

/// What a WGSL module's dispatches need to know of it: the invocations per workgroup
/// (`@workgroup_size(x)`, one-dimensional) of each entry point asked for, in their order, and
/// the bytes of workgroup memory the module declares (all of its `var<workgroup>`s: at least what
/// any one entry point takes). The built-in modules' kernels take [`WORKGROUP_SIZE`]; a module
/// given to `dextrain bench --physics-wgsl` may choose its own for `step_main` and `reset_main`
/// (benches/physics_variants.py's `workgroup_N`), and the simulator dispatches each entry point by
/// its own size. wgpu does not check the workgroup memory against the device's limit, and a
/// driver may run a module over it with the memory overlapping (lavapipe did, at 36 kB against its
/// 32 kB): the simulator checks it.
pub fn module_workgroups(source: &str, entry_points: &[&str]) -> anyhow::Result<(Vec<u32>, u32)> {
    let module = naga::front::wgsl::parse_str(source).map_err(|e| anyhow::anyhow!("not valid WGSL: {}", e.emit_to_string(source).lines().next().unwrap_or("")))?;
    let mut sizes = Vec::with_capacity(entry_points.len());
    for &name in entry_points {
        let entry = module.entry_points.iter().find(|e| e.name == name).ok_or_else(|| anyhow::anyhow!("the module has no entry point `{name}`"))?;
        let [x, y, z] = entry.workgroup_size;
        anyhow::ensure!(x >= 1 && y == 1 && z == 1, "entry point `{name}`: @workgroup_size({x}, {y}, {z}); expected one dimension, @workgroup_size(N)");
        sizes.push(x);
    }
    let mut layouter = naga::proc::Layouter::default();
    layouter.update(module.to_ctx()).map_err(|e| anyhow::anyhow!("cannot lay out the module's types: {e}"))?;
    let bytes = module.global_variables.iter().filter(|(_, v)| v.space == naga::AddressSpace::WorkGroup).map(|(_, v)| layouter[v.ty].size).sum();
    Ok((sizes, bytes))
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
