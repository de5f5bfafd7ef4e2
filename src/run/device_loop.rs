//! The runner's env loop with the rollouts on the device (README "The GPU loop"): the envs and the
//! learner share one wgpu device, observations and actions pass between them as tensors
//! ([`crate::task::TaskBatch::step_on_device`], [`Algorithm::act_device`]), and the metrics' sums
//! and the running episodes' accumulators are tensors too. The host reads one vector of sums per
//! iteration ([`DeviceLoop::take_sums`]); the observations and accumulators come to the host only
//! for a checkpoint ([`DeviceLoop::to_host`]).

use anyhow::{Result, bail};
use burn::prelude::*;

use super::algorithm::{Algorithm, DeviceOutcome};
use super::runner::{Episodes, RolloutSums};
use crate::learn::nets::{sum_all, to_host, to_tensor};
use crate::task::TaskBatch;
use crate::task::task::{OUT_BAD_RESET, OUT_LIFT, OUT_MISC, OUT_OBJ_POS_ERR, OUT_OBJ_ROT_ERR, OUT_REWARD, OUT_SUCCESS, OUT_TERMINATED, OUT_TERMS, OUT_TIME_OUT};

/// The loop's tensors on the learner device.
pub(super) struct DeviceLoop {
    device: Device,
    /// Raw observations of the current state `[N, O]` / `[N, P]`.
    pub obs: Tensor<2>,
    pub priv_obs: Tensor<2>,
    /// The running episodes' return and length `[N, 1]`.
    ep_ret: Tensor<2>,
    ep_len: Tensor<2>,
    /// Σ over the iteration's env steps and envs of every output-record column `[1, OUT_MISC]`.
    all_steps: Tensor<2>,
    /// The same sums over the envs whose episode ended at the step `[1, OUT_MISC]`.
    ended: Tensor<2>,
    /// [Σ return, Σ length, count] of the episodes that ended, and the non-finite actions `[1, 4]`.
    episodes: Tensor<2>,
    /// Env steps of all envs in the iteration so far.
    steps: u64,
}

impl DeviceLoop {
    /// The loop's state from host observations and accumulators (a new run's first observations or
    /// a checkpoint's), uploaded once.
    pub(super) fn new(obs: &[f32], priv_obs: &[f32], eps: &Episodes, dims: [usize; 3], device: &Device) -> DeviceLoop {
        let n = eps.ret.len();
        let dev = device.clone().inner();
        let col = |v: &[f64]| to_tensor(v.iter().map(|&x| x as f32).collect(), [n, 1], &dev);
        DeviceLoop {
            obs: to_tensor(obs.to_vec(), [n, dims[0]], &dev),
            priv_obs: to_tensor(priv_obs.to_vec(), [n, dims[1]], &dev),
            ep_ret: col(&eps.ret),
            ep_len: col(&eps.len),
            all_steps: Tensor::zeros([1, OUT_MISC], &dev),
            ended: Tensor::zeros([1, OUT_MISC], &dev),
            episodes: Tensor::zeros([1, 4], &dev),
            steps: 0,
            device: dev,
        }
    }

    /// `steps` env steps of every env: the algorithm acts on the device, the task steps on the
    /// device, the algorithm observes, the sums accumulate on the device.
    pub(super) fn collect(&mut self, task: &mut dyn TaskBatch, algo: &mut dyn Algorithm, steps: usize) -> Result<()> {
        let n = task.spec().num_envs;
        let column = |m: &Tensor<2>, k: usize| m.clone().slice([0..n, k..k + 1]); // [N, 1]
        for _ in 0..steps {
            let actions = algo.act_device(&self.obs, &self.priv_obs)?;
            // a non-finite action: x − x is NaN exactly for ±∞ and NaN
            let bad = sum_all((actions.clone() - actions.clone()).is_nan().float()).reshape([1, 1]);
            let out = task.step_on_device(&actions, &self.device)?;
            let (reward, terminated, time_out) = (column(&out.misc, OUT_REWARD), column(&out.misc, OUT_TERMINATED), column(&out.misc, OUT_TIME_OUT));
            algo.observe_device(&DeviceOutcome {
                reward: &reward,
                terminated: &terminated,
                time_out: &time_out,
                obs: &out.obs,
                priv_obs: &out.priv_obs,
                final_obs: out.final_obs.as_ref(),
                final_priv_obs: out.final_priv_obs.as_ref(),
            })?;
            let done = (terminated + time_out).clamp(0.0, 1.0); // [N, 1]
            self.ep_ret = self.ep_ret.clone() + reward;
            self.ep_len = self.ep_len.clone().add_scalar(1.0);
            self.all_steps = self.all_steps.clone() + out.misc.clone().sum_dim(0);
            self.ended = self.ended.clone() + (out.misc * done.clone()).sum_dim(0);
            let ended_eps = Tensor::cat(
                vec![
                    sum_all(self.ep_ret.clone() * done.clone()).reshape([1, 1]),
                    sum_all(self.ep_len.clone() * done.clone()).reshape([1, 1]),
                    sum_all(done.clone()).reshape([1, 1]),
                    bad,
                ],
                1,
            );
            self.episodes = self.episodes.clone() + ended_eps;
            let keep = done.ones_like() - done; // the ended episodes restart from 0
            self.ep_ret = self.ep_ret.clone() * keep.clone();
            self.ep_len = self.ep_len.clone() * keep;
            self.obs = out.obs;
            self.priv_obs = out.priv_obs;
            self.steps += n as u64;
        }
        Ok(())
    }

    /// The iteration's sums (one readback of `2 · OUT_MISC + 4` floats), then zeroed. A non-finite
    /// action in the iteration is an error, as the host path's check of each step's actions.
    pub(super) fn take_sums(&mut self, n_terms: usize) -> Result<RolloutSums> {
        let v = to_host(Tensor::cat(vec![self.all_steps.clone(), self.ended.clone(), self.episodes.clone()], 1))?;
        let (all, ended, eps) = (&v[..OUT_MISC], &v[OUT_MISC..2 * OUT_MISC], &v[2 * OUT_MISC..]);
        if eps[3] > 0.0 {
            bail!("the policy gave {} non-finite actions in this iteration (actions must be finite)", eps[3]);
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
        self.all_steps = self.all_steps.zeros_like();
        self.ended = self.ended.zeros_like();
        self.episodes = self.episodes.zeros_like();
        self.steps = 0;
        Ok(s)
    }

    /// The observations and the running episodes' accumulators on the host (for a checkpoint).
    pub(super) fn to_host(&self) -> Result<(Vec<f32>, Vec<f32>, Episodes)> {
        let wide = |t: &Tensor<2>| -> Result<Vec<f64>> { Ok(to_host(t.clone())?.into_iter().map(|x| x as f64).collect()) };
        Ok((to_host(self.obs.clone())?, to_host(self.priv_obs.clone())?, Episodes { ret: wide(&self.ep_ret)?, len: wide(&self.ep_len)? }))
    }
}
