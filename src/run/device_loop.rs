//! The runner's env loop with the rollouts on the device (docs/gpu.md "The GPU loop"): the envs and the
//! learner share one wgpu device, observations and actions pass between them as tensors
//! ([`crate::task::TaskBatch::step_on_device`], [`Algorithm::act_device`]), and the metrics' sums
//! and the running episodes' accumulators are tensors too. The host reads one vector of sums per
//! iteration ([`DeviceLoop::take_sums`]); the observations and accumulators come to the host only
//! for a checkpoint ([`DeviceLoop::to_host`]).

use anyhow::{Result, bail};
use burn::prelude::*;

use super::algorithm::{Algorithm, DeviceOutcome};
use super::runner::{Episodes, RolloutSums};
use crate::learn::nets::{to_host, to_tensor};
use crate::task::TaskBatch;
use crate::task::task::{OUT_BAD_RESET, OUT_LIFT, OUT_MISC, OUT_OBJ_POS_ERR, OUT_OBJ_ROT_ERR, OUT_REWARD, OUT_SUCCESS, OUT_TERMINATED, OUT_TERMS, OUT_TIME_OUT};

/// The loop's tensors on the learner device. The iteration's sums are kept per env and reduced
/// over the envs once, when the host reads them ([`DeviceLoop::take_sums`]): an env step adds a
/// handful of element-wise kernels and no reduction.
pub(super) struct DeviceLoop {
    device: Device,
    /// Raw observations of the current state `[N, O]` / `[N, P]`.
    pub obs: Tensor<2>,
    pub priv_obs: Tensor<2>,
    /// The running episodes' [return, length] `[N, 2]`.
    episode: Tensor<2>,
    /// Ones `[N, 1]`: each env step adds [reward, 1] to `episode`.
    ones: Tensor<2>,
    /// Σ over the iteration's env steps of every output-record column, per env `[N, OUT_MISC]`.
    all_steps: Tensor<2>,
    /// The same sums over the steps at which the env's episode ended `[N, OUT_MISC]`.
    ended: Tensor<2>,
    /// Σ of the ended episodes' [return, length], and of the ended flags, per env `[N, 3]`.
    episodes: Tensor<2>,
    /// Σ over the iteration's steps of each env's actions minus themselves `[N, 1]`: 0, or NaN once
    /// an action was not finite (x − x is NaN exactly for ±∞ and NaN).
    bad: Tensor<2>,
    /// Env steps of all envs in the iteration so far.
    steps: u64,
}

impl DeviceLoop {
    /// The loop's state from host observations and accumulators (a new run's first observations or
    /// a checkpoint's), uploaded once.
    pub(super) fn new(obs: &[f32], priv_obs: &[f32], eps: &Episodes, dims: [usize; 3], device: &Device) -> DeviceLoop {
        let n = eps.ret.len();
        let dev = device.clone().inner();
        let episode: Vec<f32> = eps.ret.iter().zip(&eps.len).flat_map(|(&r, &l)| [r as f32, l as f32]).collect();
        DeviceLoop {
            obs: to_tensor(obs.to_vec(), [n, dims[0]], &dev),
            priv_obs: to_tensor(priv_obs.to_vec(), [n, dims[1]], &dev),
            episode: to_tensor(episode, [n, 2], &dev),
            ones: Tensor::ones([n, 1], &dev),
            all_steps: Tensor::zeros([n, OUT_MISC], &dev),
            ended: Tensor::zeros([n, OUT_MISC], &dev),
            episodes: Tensor::zeros([n, 3], &dev),
            bad: Tensor::zeros([n, 1], &dev),
            steps: 0,
            device: dev,
        }
    }

    /// `steps` env steps of every env: the algorithm acts on the device, the task steps on the
    /// device, the algorithm observes, the sums accumulate on the device.
    /// A live view reads the shown envs after a step, when it sends a scene.
    pub(super) fn collect(&mut self, task: &mut dyn TaskBatch, algo: &mut dyn Algorithm, steps: usize, mut live: Option<&mut crate::live::LiveView>) -> Result<()> {
        let n = task.spec().num_envs;
        let column = |m: &Tensor<2>, k: usize| m.clone().slice([0..n, k..k + 1]); // [N, 1]
        for _ in 0..steps {
            let actions = algo.act_device(&self.obs, &self.priv_obs)?;
            // Σ_k (a − a): NaN for an env with a non-finite action
            self.bad = self.bad.clone() + (actions.clone() - actions.clone()).sum_dim(1);
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
            let done = terminated.max_pair(time_out); // [N, 1], flags 0 or 1
            // the episodes' return and length, then what ended: [return, length] · done
            self.episode = self.episode.clone() + Tensor::cat(vec![reward, self.ones.clone()], 1);
            let ended_episode = self.episode.clone() * done.clone(); // [N, 2]
            self.episodes = self.episodes.clone() + Tensor::cat(vec![ended_episode.clone(), done.clone()], 1);
            self.episode = self.episode.clone() - ended_episode; // the ended episodes restart from 0
            self.all_steps = self.all_steps.clone() + out.misc.clone();
            self.ended = self.ended.clone() + out.misc * done;
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
        let per_env = Tensor::cat(vec![self.all_steps.clone(), self.ended.clone(), self.episodes.clone(), self.bad.clone().is_nan().float()], 1);
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
        self.all_steps = self.all_steps.zeros_like();
        self.ended = self.ended.zeros_like();
        self.episodes = self.episodes.zeros_like();
        self.bad = self.bad.zeros_like();
        self.steps = 0;
        Ok(s)
    }

    /// The observations and the running episodes' accumulators on the host (for a checkpoint).
    pub(super) fn to_host(&self) -> Result<(Vec<f32>, Vec<f32>, Episodes)> {
        let episode = to_host(self.episode.clone())?; // [N, 2]: return, length
        let ret = episode.iter().step_by(2).map(|&x| x as f64).collect();
        let len = episode.iter().skip(1).step_by(2).map(|&x| x as f64).collect();
        Ok((to_host(self.obs.clone())?, to_host(self.priv_obs.clone())?, Episodes { ret, len }))
    }
}
