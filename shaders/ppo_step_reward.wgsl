// PPO's reward and done flag of one env step of a device-resident rollout (learn/kernels/
// ppo_rollout.rs; the tensor ops of ppo/device.rs's process_step_device it replaces computed the
// same f32 arithmetic), one invocation per env:
//   done = max(terminated, time-out) (flags 0 or 1), and with a time-out that is not a termination
//   (done − terminated) the reward bootstraps through it: r' = scale · r + (γ V(s_t)) · (done − terminated)

struct StepRewardCfg {
    envs: u32,
    _pad: u32,
    // the reward scale and γ as f32 bits
    scale_bits: u32,
    gamma_bits: u32,
}

@group(0) @binding(0) var<storage, read_write> sr_reward: array<f32>;     // [N, 1] the env's reward
@group(0) @binding(1) var<storage, read_write> sr_terminated: array<f32>; // [N, 1]
@group(0) @binding(2) var<storage, read_write> sr_time_out: array<f32>;   // [N, 1]
@group(0) @binding(3) var<storage, read_write> sr_values: array<f32>;     // [N, 1] V(s_t)
@group(0) @binding(4) var<storage, read_write> sr_out: array<f32>;        // [N, 2] r', done
@group(0) @binding(5) var<uniform> rc: StepRewardCfg;

@compute @workgroup_size(64, 1, 1)
fn ppo_step_reward(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if i >= rc.envs {
        return;
    }
    let terminated = sr_terminated[i];
    let time_out = sr_time_out[i];
    var done = time_out; // burn's max_pair: time-out unless terminated is not smaller
    if terminated >= time_out {
        done = terminated;
    }
    let timeout_only = done - terminated;
    sr_out[2u * i] = sr_reward[i] * bitcast<f32>(rc.scale_bits) + (sr_values[i] * bitcast<f32>(rc.gamma_bits)) * timeout_only;
    sr_out[2u * i + 1u] = done;
}
