//! The runner's env loop with the rollouts on the device (docs/gpu.md "The GPU loop"): the envs and the
//! learner share one wgpu device, observations and actions pass between them as tensors
//! ([`crate::task::TaskBatch::step_on_device`], [`Algorithm::act_device`]), and the metrics' sums
//! and the running episodes' accumulators are tensors too. The host reads one vector of sums per
//! iteration ([`DeviceLoop::take_sums`]); the observations and accumulators come to the host only
//! for a checkpoint ([`DeviceLoop::to_host`]).

use crate::gpu::profile::around_burn;
use anyhow::{Result, bail};
use burn::prelude::*;

use super::algorithm::{Algorithm, DeviceOutcome};
use super::runner::{Episodes, RolloutSums};
use crate::learn::nets::{to_host, to_tensor};
use crate::task::TaskBatch;
use crate::task::task::{OUT_BAD_RESET, OUT_LIFT, OUT_MISC, OUT_OBJ_POS_ERR, OUT_OBJ_ROT_ERR, OUT_REWARD, OUT_SUCCESS, OUT_TERMINATED, OUT_TERMS, OUT_TIME_OUT};

/// Columns of [`DeviceLoop`]'s accumulators `[N, ACC_WIDTH]` per env: Σ over the iteration's steps
/// of the output record `[0, M)`; the same over the steps at which the env's episode ended
/// `[M, 2M)`; Σ of the ended episodes' return and length and of the ended flags (`ACC_EPISODES`,
/// 3 columns); Σ over the steps of the actions minus themselves (`ACC_BAD`: 0, or NaN once an
/// action was not finite, as x − x is NaN exactly for ±∞ and NaN); the running episode's return
/// and length (`ACC_EPISODE`, 2 columns). M = `OUT_MISC`.
const ACC_EPISODES: usize = 2 * OUT_MISC;
const ACC_BAD: usize = ACC_EPISODES + 3;
const ACC_EPISODE: usize = ACC_BAD + 1;
const ACC_WIDTH: usize = ACC_EPISODE + 2;

/// The loop's tensors on the learner device. The iteration's sums are kept per env and reduced
/// over the envs once, when the host reads them ([`DeviceLoop::take_sums`]): an env step adds one
/// kernel of ours (shaders/loop_sums.wgsl, where the tensor ops were ~19 element-wise kernels) and
/// no reduction.
pub(super) struct DeviceLoop {
    device: Device,
    /// Raw observations of the current state `[N, O]` / `[N, P]`.
    pub obs: Tensor<2>,
    pub priv_obs: Tensor<2>,
    /// The per-env sums and the running episodes `[N, ACC_WIDTH]` (see [`ACC_WIDTH`]).
    acc: Tensor<2>,
    /// Env steps of all envs in the iteration so far.
    steps: u64,
}

impl DeviceLoop {
    /// The loop's state from host observations and accumulators (a new run's first observations or
    /// a checkpoint's), uploaded once.
    pub(super) fn new(obs: &[f32], priv_obs: &[f32], eps: &Episodes, dims: [usize; 3], device: &Device) -> DeviceLoop {
        let n = eps.ret.len();
        let dev = device.clone().inner();
        let mut acc = vec![0.0f32; n * ACC_WIDTH];
        for (i, (&r, &l)) in eps.ret.iter().zip(&eps.len).enumerate() {
            acc[i * ACC_WIDTH + ACC_EPISODE] = r as f32;
            acc[i * ACC_WIDTH + ACC_EPISODE + 1] = l as f32;
        }
        DeviceLoop {
            obs: to_tensor(obs.to_vec(), [n, dims[0]], &dev),
            priv_obs: to_tensor(priv_obs.to_vec(), [n, dims[1]], &dev),
            acc: to_tensor(acc, [n, ACC_WIDTH], &dev),
            steps: 0,
            device: dev,
        }
    }

    /// `steps` env steps of every env: the algorithm acts on the device, the task steps on the
    /// device, the algorithm observes, the sums accumulate on the device.
    /// A live view reads the shown envs after a step, when it sends a scene.
    pub(super) fn collect(&mut self, task: &mut dyn TaskBatch, algo: &mut dyn Algorithm, steps: usize, mut live: Option<&mut crate::live::LiveView>) -> Result<()> {
        let n = task.spec().num_envs;
        // `--gpu-profile` (gpu::profile): the learner's acting and observing as spans of their own;
        // the task's kernels are stamped one by one where they are recorded
        let ctx = crate::learn::device::gpu_context_of(&self.device);
        let ctx = ctx.as_ref();
        for _ in 0..steps {
            let actions = around_burn(ctx, &self.device, "act", || algo.act_device(&self.obs, &self.priv_obs))?;
            let out = task.step_on_device(&actions, &self.device)?;
            around_burn(ctx, &self.device, "observe", || {
                let (acc, [reward, terminated, time_out]) = step_sums(&actions, &out.misc, &self.acc)?;
                self.acc = acc;
                algo.observe_device(&DeviceOutcome {
                    reward: &reward,
                    terminated: &terminated,
                    time_out: &time_out,
                    obs: &out.obs,
                    priv_obs: &out.priv_obs,
                    final_obs: out.final_obs.as_ref(),
                    final_priv_obs: out.final_priv_obs.as_ref(),
                })
            })?;
            self.obs = out.obs;
            self.priv_obs = out.priv_obs;
            self.steps += n as u64;
            if let Some(l) = live.as_deref_mut() {
                l.after_step(task)?;
            }
        }
        Ok(())
    }

    /// The iteration's sums (one readback of `2 · OUT_MISC + 4` floats: the per-env sums reduced
    /// over the envs), then zeroed. A non-finite action in the iteration is an error, as the host
    /// path's check of each step's actions.
    pub(super) fn take_sums(&mut self, n_terms: usize) -> Result<RolloutSums> {
        let n = self.acc.dims()[0];
        let per_env = Tensor::cat(vec![self.acc.clone().narrow(1, 0, ACC_BAD), self.acc.clone().narrow(1, ACC_BAD, 1).is_nan().float()], 1);
        let v = to_host(per_env.sum_dim(0))?; // [1, 2 · OUT_MISC + 4]: Σ over the envs
        let (all, ended, eps) = (&v[..OUT_MISC], &v[OUT_MISC..2 * OUT_MISC], &v[2 * OUT_MISC..]);
        if eps[3] > 0.0 {
            bail!("the policy gave non-finite actions in {} envs in this iteration (actions must be finite)", eps[3]);
        }
        let s = RolloutSums {
            reward: all[OUT_REWARD] as f64,
            terms: (0..n_terms).map(|k| all[OUT_TERMS + k] as f64).collect(),
            steps: self.steps,
            episodes: eps[2].round() as u64,
            successes: ended[OUT_SUCCESS].round() as u64,
            terminated: ended[OUT_TERMINATED].round() as u64,
            bad_resets: ended[OUT_BAD_RESET].round() as u64,
            ep_return: eps[0] as f64,
            ep_len: eps[1] as f64,
            lift: ended[OUT_LIFT] as f64,
            obj_pos_err: all[OUT_OBJ_POS_ERR] as f64,
            obj_rot_err: (all[OUT_OBJ_ROT_ERR] as f64).to_degrees(),
        };
        // the sums start again from zero; the running episodes go on
        self.acc = Tensor::cat(vec![Tensor::zeros([n, ACC_EPISODE], &self.device), self.acc.clone().narrow(1, ACC_EPISODE, 2)], 1);
        self.steps = 0;
        Ok(s)
    }

    /// The observations and the running episodes' accumulators on the host (for a checkpoint).
    pub(super) fn to_host(&self) -> Result<(Vec<f32>, Vec<f32>, Episodes)> {
        let episode = to_host(self.acc.clone().narrow(1, ACC_EPISODE, 2))?; // [N, 2]: return, length
        let ret = episode.iter().step_by(2).map(|&x| x as f64).collect();
        let len = episode.iter().skip(1).step_by(2).map(|&x| x as f64).collect();
        Ok((to_host(self.obs.clone())?, to_host(self.priv_obs.clone())?, Episodes { ret, len }))
    }
}

/// shaders/loop_sums.wgsl.
const SHADER_LOOP_SUMS: &str = include_str!("../../shaders/loop_sums.wgsl");

/// The loop-sums kernel's module (one variant).
pub fn loop_sums_source(_: ()) -> String {
    SHADER_LOOP_SUMS.to_string()
}

/// One env step's sums as one kernel of ours on burn's stream: the accumulators after the step
/// `[N, ACC_WIDTH]` (a fresh tensor) from those before it, the step's actions `[N, A]` and output
/// records `misc` `[N, OUT_MISC]`, and the step's reward, terminated and time-out flags, each
/// `[N, 1]`, for the algorithm.
fn step_sums(actions: &Tensor<2>, misc: &Tensor<2>, acc: &Tensor<2>) -> Result<(Tensor<2>, [Tensor<2>; 3])> {
    use burn::backend::Cube;
    use burn::backend::ops::FloatTensorOps;
    use burn::backend::tensor::FloatTensor;
    use burn::tensor::{FloatDType, Shape};
    use crate::learn::kernels::wgsl_kernel::{WgslKernel, launch};
    let [n, a] = actions.dims();
    let prim = |t: &Tensor<2>, cols: usize| -> Result<FloatTensor<Cube>> {
        use anyhow::Context;
        crate::learn::kernels::wgsl_kernel::plain_primitive(&t.clone().inner(), [n, cols]).context("the device-resident loop's sums")
    };
    let (ap, mp, cp) = (prim(actions, a)?, prim(misc, OUT_MISC)?, prim(acc, ACC_WIDTH)?);
    let empty = |cols: usize| Cube::float_empty(Shape::new([n, cols]), &ap.device, FloatDType::F32); // written whole by the kernel
    let (acc_out, reward, terminated, time_out) = (empty(ACC_WIDTH), empty(1), empty(1), empty(1));
    let kernel = WgslKernel { name: "dextrain_loop_sums", key: (), source: loop_sums_source, entry_point: "loop_sums", workgroup: [64, 1] };
    let groups = u32::try_from(n.div_ceil(64)).ok().filter(|&g| g <= 65_535).ok_or_else(|| anyhow::anyhow!("the device-resident loop's sums: {n} envs are more than one kernel's grid"))?;
    let constants = [n as u32, a as u32, OUT_MISC as u32, OUT_REWARD as u32, OUT_TERMINATED as u32, OUT_TIME_OUT as u32];
    launch(kernel, [groups, 1, 1], &[&ap, &mp, &cp, &acc_out, &reward, &terminated, &time_out], &constants);
    let t = |p: FloatTensor<Cube>| Tensor::<2>::from_primitive::<Cube>(p);
    Ok((t(acc_out), [t(reward), t(terminated), t(time_out)]))
}
