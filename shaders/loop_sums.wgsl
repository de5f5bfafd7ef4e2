// The device-resident env loop's per-env sums of one env step (run/device_loop.rs), one
// invocation per env: what the loop's ~19 element-wise tensor ops did per step, with the same
// f32 arithmetic. The accumulators' row of env i, acc [N, 2M + 6] (M = OUT_MISC):
//   [0, M)        Σ over the iteration's steps of the step's output record
//   [M, 2M)       the same over the steps at which the env's episode ended
//   2M, 2M+1, 2M+2  Σ of the ended episodes' return and length, and of the ended flags
//   2M + 3        Σ_k (a_k − a_k) of the actions: 0, or NaN once an action was not finite
//   2M+4, 2M+5    the running episode's return and length
// done = max(terminated, time-out); the episode adds [reward, 1], then what ended ([return,
// length] · done) is added to the ended sums and taken off the running episode.

struct LoopSumsCfg {
    envs: u32,
    // actions per env
    act: u32,
    // the output record's floats M, and where the reward, terminated and time-out flags sit in it
    misc: u32,
    reward_col: u32,
    terminated_col: u32,
    time_out_col: u32,
}

@group(0) @binding(0) var<storage, read_write> ls_actions: array<f32>;  // [N, A]
@group(0) @binding(1) var<storage, read_write> ls_misc: array<f32>;     // [N, M] the step's output records
@group(0) @binding(2) var<storage, read_write> ls_acc: array<f32>;      // [N, 2M + 6] before the step
@group(0) @binding(3) var<storage, read_write> ls_acc_out: array<f32>;  // [N, 2M + 6] after it
@group(0) @binding(4) var<storage, read_write> ls_reward: array<f32>;   // [N, 1]
@group(0) @binding(5) var<storage, read_write> ls_terminated: array<f32>; // [N, 1]
@group(0) @binding(6) var<storage, read_write> ls_time_out: array<f32>; // [N, 1]
@group(0) @binding(7) var<uniform> lc: LoopSumsCfg;

@compute @workgroup_size(64, 1, 1)
fn loop_sums(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if i >= lc.envs {
        return;
    }
    let m = lc.misc;
    let w = 2u * m + 6u;
    let rec = i * m;
    let row = i * w;
    let reward = ls_misc[rec + lc.reward_col];
    let terminated = ls_misc[rec + lc.terminated_col];
    let time_out = ls_misc[rec + lc.time_out_col];
    ls_reward[i] = reward;
    ls_terminated[i] = terminated;
    ls_time_out[i] = time_out;
    var done = time_out; // max(terminated, time-out) as burn's max_pair (time-out unless terminated is larger)
    if terminated >= time_out {
        done = terminated;
    }
    for (var k = 0u; k < m; k++) {
        let x = ls_misc[rec + k];
        ls_acc_out[row + k] = ls_acc[row + k] + x;
        ls_acc_out[row + m + k] = ls_acc[row + m + k] + x * done;
    }
    var bad = 0.0;
    for (var k = 0u; k < lc.act; k++) {
        let a = ls_actions[i * lc.act + k];
        bad += a - a;
    }
    ls_acc_out[row + 2u * m + 3u] = ls_acc[row + 2u * m + 3u] + bad;
    let ret = ls_acc[row + 2u * m + 4u] + reward;
    let len = ls_acc[row + 2u * m + 5u] + 1.0;
    let ended_ret = ret * done;
    let ended_len = len * done;
    ls_acc_out[row + 2u * m] = ls_acc[row + 2u * m] + ended_ret;
    ls_acc_out[row + 2u * m + 1u] = ls_acc[row + 2u * m + 1u] + ended_len;
    ls_acc_out[row + 2u * m + 2u] = ls_acc[row + 2u * m + 2u] + done;
    ls_acc_out[row + 2u * m + 4u] = ret - ended_ret;
    ls_acc_out[row + 2u * m + 5u] = len - ended_len;
}
