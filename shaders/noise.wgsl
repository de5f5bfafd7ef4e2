// ---- the learner's action noise on the device, Gaussian or uniform (src/learn/noise.rs; CPU twins:
// learn::noise::host_normals, host_uniforms). Appended to common.wgsl (its counter hash and
// env_index). ----

// the stream of the action noise in the counter hash (the env's purposes are 1–5)
const PURPOSE_ACTION_NOISE: u32 = 6u;

struct NoiseCfg {
    seed: u32,
    // the first draw's number (the learner's act calls so far): the hash's episode slot
    draw: u32,
    // rows of the output: `draws` consecutive draws of `envs` rows each, draw after draw
    rows: u32,
    cols: u32,
    // rows of one draw (the envs): output row r is row r mod envs of draw `draw + r / envs`
    envs: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(22) var<uniform> nc: NoiseCfg;
// [rows, cols] standard normal draws, row-major
@group(0) @binding(23) var<storage, read_write> noise_out: array<f32>;

// ε[i, k] ~ N(0, 1) for row i (the env) and column k (the action) of draw d (row r of the output:
// i = r mod envs, d = nc.draw + r / envs): Box–Muller √(−2 ln u1) cos(2π u2) with u1 ∈ (0, 1] and
// u2 from the counter hash
@compute @workgroup_size(WORKGROUP_SIZE)
fn learner_noise(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let e = env_index(gid, nwg);
    if (e >= nc.rows * nc.cols) {
        return;
    }
    let r = e / nc.cols;
    let i = r % nc.envs;
    let d = nc.draw + r / nc.envs;
    let k = e % nc.cols;
    let u1 = 1.0 - rand_uniform(nc.seed, i, d, PURPOSE_ACTION_NOISE, 2u * k);
    let u2 = rand_uniform(nc.seed, i, d, PURPOSE_ACTION_NOISE, 2u * k + 1u);
    noise_out[e] = sqrt(-2.0 * log(u1)) * cos(6.2831853 * u2);
}

// u[i, k] ~ U[−1, 1) for row i and column k of draw d (rows as learner_noise's): 2 u − 1 with u the hash's uniform of
// key 2k (a draw is either normal or uniform, never both)
@compute @workgroup_size(WORKGROUP_SIZE)
fn learner_uniform(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let e = env_index(gid, nwg);
    if (e >= nc.rows * nc.cols) {
        return;
    }
    let r = e / nc.cols;
    let i = r % nc.envs;
    let d = nc.draw + r / nc.envs;
    let k = e % nc.cols;
    noise_out[e] = 2.0 * rand_uniform(nc.seed, i, d, PURPOSE_ACTION_NOISE, 2u * k) - 1.0;
}
