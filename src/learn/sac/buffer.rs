//! The replay buffer: one ring of `capacity` transitions per env (FastTD3's layout: every env
//! steps at once, so all rings fill and wrap together, and sampling the same number of transitions
//! from every env keeps old and new data balanced).
//!
//! Storage is time-major, `[capacity, N_env, dim]`: slot `j` of every env is written by one push
//! (row `j · N + i` is env `i`'s transition in slot `j`). Slots fill 0, 1, … and then wrap, so the
//! written slots are always `0..len`. A transition holds the raw observations before the step, the
//! action, the learner's reward (scaled), whether the episode ended after it and whether it ended by
//! a termination, and the raw observations after it (for an episode that ended: the observation of
//! the state it ended in, not the next episode's first).
//!
//! [`ReplayBuffer::sample`] draws a batch and its n-step targets' parts: `R = Σ_{k<m} γᵏ r_{t+k}`
//! over the window of `m ≤ n` transitions that ends at the first episode end (or at the newest
//! transition), the observation after the window's last transition, and the bootstrap factor `γᵐ`
//! (0 when the window ended by a termination: no bootstrap through a termination; a time-out keeps
//! `γᵐ` and bootstraps from the episode's true final observation).

use anyhow::{Result, ensure};

use crate::rng::Rng;
use super::super::state::{LearnerState, TensorValues};

/// Per-env ring buffers of transitions, on the host (the CPU learner's device).
#[derive(Clone, Debug)]
pub struct ReplayBuffer {
    /// Envs N.
    pub envs: usize,
    /// Transitions kept per env.
    pub capacity: usize,
    /// Actor-observation size stored (0 when only the critics' inputs are kept).
    pub obs_dim: usize,
    /// Critic-observation size.
    pub priv_dim: usize,
    /// Action size.
    pub act_dim: usize,
    /// [C, N, obs_dim] actor observations before the step (raw).
    pub obs: Vec<f32>,
    /// [C, N, priv_dim] critic observations before the step (raw).
    pub priv_obs: Vec<f32>,
    /// [C, N, act_dim] actions taken.
    pub actions: Vec<f32>,
    /// [C, N] the learner's rewards (`sac.reward_scale` × the env's).
    pub rewards: Vec<f32>,
    /// [C, N] 1 when the episode ended after this transition (termination or time-out).
    pub done: Vec<u8>,
    /// [C, N] 1 when it ended by a termination.
    pub terminated: Vec<u8>,
    /// [C, N, obs_dim] actor observations after the step (an ended episode's final one).
    pub next_obs: Vec<f32>,
    /// [C, N, priv_dim] critic observations after the step.
    pub next_priv_obs: Vec<f32>,
    /// The slot the next push writes.
    pub pos: usize,
    /// Written slots per env (≤ capacity).
    pub len: usize,
}

/// One push: every env's transition, `[N, dim]` rows.
pub struct Transitions<'a> {
    pub obs: &'a [f32],
    pub priv_obs: &'a [f32],
    pub actions: &'a [f32],
    pub rewards: &'a [f32],
    pub done: &'a [bool],
    pub terminated: &'a [bool],
    pub next_obs: &'a [f32],
    pub next_priv_obs: &'a [f32],
}

/// A sampled batch (B rows each, raw observations) with its n-step return and bootstrap factor.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sample {
    /// [B, obs_dim] (empty when the buffer keeps no actor observations).
    pub obs: Vec<f32>,
    /// [B, priv_dim].
    pub priv_obs: Vec<f32>,
    /// [B, act_dim].
    pub actions: Vec<f32>,
    /// [B] `Σ_{k<m} γᵏ r_{t+k}`.
    pub returns: Vec<f32>,
    /// [B] `γᵐ`, or 0 after a termination.
    pub bootstrap: Vec<f32>,
    /// [B, obs_dim] the actor observation after the window.
    pub next_obs: Vec<f32>,
    /// [B, priv_dim] the critic observation after the window.
    pub next_priv_obs: Vec<f32>,
    /// [B] (env, slot) of each row (tests).
    pub rows: Vec<(usize, usize)>,
}

/// The rows a sampled batch of B transitions reads ([`ReplayBuffer::draw`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Draw {
    /// [B] (env, slot) of each batch row (its window's first transition).
    pub rows: Vec<(usize, usize)>,
    /// [n_step, B] the row (`slot · N + env`) of window step w of batch row k at `w · B + k`
    /// (0 where not valid).
    pub window: Vec<usize>,
    /// [n_step, B] whether that slot is written (the window stops at the newest transition).
    pub valid: Vec<bool>,
    /// B.
    pub batch: usize,
}

fn copy_row(dst: &mut Vec<f32>, src: &[f32], row: usize, dim: usize) {
    dst.extend_from_slice(&src[row * dim..(row + 1) * dim]);
}

impl ReplayBuffer {
    /// An empty buffer of `capacity` transitions for each of `envs` envs (`obs_dim` 0: no actor
    /// observations kept). The arrays are zero-filled allocations: the OS provides their pages as
    /// they are first written.
    pub fn new(envs: usize, capacity: usize, obs_dim: usize, priv_dim: usize, act_dim: usize) -> ReplayBuffer {
        let rows = envs * capacity;
        ReplayBuffer {
            envs,
            capacity,
            obs_dim,
            priv_dim,
            act_dim,
            obs: vec![0.0; rows * obs_dim],
            priv_obs: vec![0.0; rows * priv_dim],
            actions: vec![0.0; rows * act_dim],
            rewards: vec![0.0; rows],
            done: vec![0; rows],
            terminated: vec![0; rows],
            next_obs: vec![0.0; rows * obs_dim],
            next_priv_obs: vec![0.0; rows * priv_dim],
            pos: 0,
            len: 0,
        }
    }

    /// Transitions held (all envs).
    pub fn transitions(&self) -> usize {
        self.len * self.envs
    }

    /// Writes one transition of every env into slot `pos` and advances it (overwriting the oldest
    /// slot once the rings are full).
    pub fn push(&mut self, t: &Transitions<'_>) -> Result<()> {
        let (n, od, pd, ad) = (self.envs, self.obs_dim, self.priv_dim, self.act_dim);
        ensure!(
            t.obs.len() == n * od && t.next_obs.len() == n * od && t.priv_obs.len() == n * pd && t.next_priv_obs.len() == n * pd,
            "replay buffer: observation sizes do not match the buffer's"
        );
        ensure!(t.actions.len() == n * ad && t.rewards.len() == n && t.done.len() == n && t.terminated.len() == n, "replay buffer: transition sizes do not match the buffer's");
        let j = self.pos;
        let rows = j * n..(j + 1) * n;
        self.obs[rows.start * od..rows.end * od].copy_from_slice(t.obs);
        self.next_obs[rows.start * od..rows.end * od].copy_from_slice(t.next_obs);
        self.priv_obs[rows.start * pd..rows.end * pd].copy_from_slice(t.priv_obs);
        self.next_priv_obs[rows.start * pd..rows.end * pd].copy_from_slice(t.next_priv_obs);
        self.actions[rows.start * ad..rows.end * ad].copy_from_slice(t.actions);
        self.rewards[rows.clone()].copy_from_slice(t.rewards);
        for i in 0..n {
            self.done[j * n + i] = (t.done[i] || t.terminated[i]) as u8;
            self.terminated[j * n + i] = t.terminated[i] as u8;
        }
        self.advance();
        Ok(())
    }

    /// Moves to the next slot after a push (the device-resident buffer keeps its data on the
    /// device and only these counters here).
    pub fn advance(&mut self) {
        self.pos = (self.pos + 1) % self.capacity;
        self.len = (self.len + 1).min(self.capacity);
    }

    /// Which rows a batch of `batch` transitions with windows of `n_step` reads: env of row k
    /// `(k + o) mod N` for a random offset o (every env gives ⌊B/N⌋ or ⌈B/N⌉ rows); its slot
    /// uniform over the written ones; the window's rows are the env's next slots, as far as they
    /// are written. Only the RNG and the buffer's counters decide it (no data), so a buffer on the
    /// device samples the rows the host's would.
    pub fn draw(&self, batch: usize, n_step: usize, rng: &mut Rng) -> Result<Draw> {
        ensure!(self.len > 0, "replay buffer: sampling from an empty buffer");
        let (n, c) = (self.envs, self.capacity);
        let oldest = (self.pos + c - self.len) % c;
        let offset = rng.below(n);
        let mut d = Draw { rows: Vec::with_capacity(batch), window: vec![0; n_step * batch], valid: vec![false; n_step * batch], batch };
        for k in 0..batch {
            let env = (k + offset) % n;
            let age = rng.below(self.len); // 0 = the oldest written slot
            for w in 0..n_step {
                if age + w < self.len {
                    d.window[w * batch + k] = ((oldest + age + w) % c) * n + env;
                    d.valid[w * batch + k] = true;
                }
            }
            d.rows.push((env, (oldest + age) % c));
        }
        Ok(d)
    }

    /// Draws `batch` transitions with their `n_step` returns (discount `gamma`): the rows of
    /// [`ReplayBuffer::draw`], then the window's return, stopping at an episode's end.
    pub fn sample(&self, batch: usize, n_step: usize, gamma: f32, rng: &mut Rng) -> Result<Sample> {
        let draw = self.draw(batch, n_step, rng)?;
        let (od, pd, ad) = (self.obs_dim, self.priv_dim, self.act_dim);
        let mut s = Sample {
            obs: Vec::with_capacity(batch * od),
            priv_obs: Vec::with_capacity(batch * pd),
            actions: Vec::with_capacity(batch * ad),
            returns: Vec::with_capacity(batch),
            bootstrap: Vec::with_capacity(batch),
            next_obs: Vec::with_capacity(batch * od),
            next_priv_obs: Vec::with_capacity(batch * pd),
            rows: draw.rows.clone(),
        };
        for k in 0..batch {
            let row = draw.window[k];
            copy_row(&mut s.obs, &self.obs, row, od);
            copy_row(&mut s.priv_obs, &self.priv_obs, row, pd);
            copy_row(&mut s.actions, &self.actions, row, ad);
            // R = Σ_{k<m} γᵏ r_{t+k}, stopping at an episode's end or at the newest transition
            let (mut ret, mut disc, mut last) = (0.0f32, 1.0f32, row);
            for w in 0..n_step {
                if !draw.valid[w * batch + k] {
                    break;
                }
                let r = draw.window[w * batch + k];
                ret += disc * self.rewards[r];
                disc *= gamma;
                last = r;
                if self.done[r] != 0 {
                    if self.terminated[r] != 0 {
                        disc = 0.0; // no bootstrap through a termination
                    }
                    break;
                }
            }
            s.returns.push(ret);
            s.bootstrap.push(disc);
            copy_row(&mut s.next_obs, &self.next_obs, last, od);
            copy_row(&mut s.next_priv_obs, &self.next_priv_obs, last, pd);
        }
        Ok(s)
    }

    /// Writes the written slots (`[len, N, dim]` of each array) into file `file` of `state`, and
    /// `replay_pos` / `replay_len`.
    pub fn save(&self, state: &mut LearnerState, file: &str) {
        let rows = self.len * self.envs;
        let f32s = |v: &[f32], d: usize| TensorValues::F32(v[..rows * d].to_vec());
        let shape = |d: usize| vec![self.len, self.envs, d];
        state.push_tensor(file, "obs", shape(self.obs_dim), f32s(&self.obs, self.obs_dim));
        state.push_tensor(file, "priv_obs", shape(self.priv_dim), f32s(&self.priv_obs, self.priv_dim));
        state.push_tensor(file, "actions", shape(self.act_dim), f32s(&self.actions, self.act_dim));
        state.push_tensor(file, "rewards", shape(1), f32s(&self.rewards, 1));
        state.push_tensor(file, "done", shape(1), TensorValues::U8(self.done[..rows].to_vec()));
        state.push_tensor(file, "terminated", shape(1), TensorValues::U8(self.terminated[..rows].to_vec()));
        state.push_tensor(file, "next_obs", shape(self.obs_dim), f32s(&self.next_obs, self.obs_dim));
        state.push_tensor(file, "next_priv_obs", shape(self.priv_dim), f32s(&self.next_priv_obs, self.priv_dim));
        state.set_u64("replay_pos", self.pos as u64);
        state.set_u64("replay_len", self.len as u64);
    }

    /// Restores what [`ReplayBuffer::save`] wrote (same sizes).
    pub fn load(&mut self, state: &LearnerState, file: &str) -> Result<()> {
        let len = state.u64("replay_len")? as usize;
        let pos = state.u64("replay_pos")? as usize;
        ensure!(len <= self.capacity && pos < self.capacity && (len == self.capacity || pos == len), "{file}.safetensors: replay_len {len} / replay_pos {pos} do not fit a buffer of {} slots", self.capacity);
        let rows = len * self.envs;
        let fill = |dst: &mut Vec<f32>, name: &str, d: usize| -> Result<()> {
            let v = state.f32s(file, name, Some(rows * d))?;
            dst[..rows * d].copy_from_slice(&v);
            Ok(())
        };
        fill(&mut self.obs, "obs", self.obs_dim)?;
        fill(&mut self.priv_obs, "priv_obs", self.priv_dim)?;
        fill(&mut self.actions, "actions", self.act_dim)?;
        fill(&mut self.rewards, "rewards", 1)?;
        fill(&mut self.next_obs, "next_obs", self.obs_dim)?;
        fill(&mut self.next_priv_obs, "next_priv_obs", self.priv_dim)?;
        for (dst, name) in [(&mut self.done, "done"), (&mut self.terminated, "terminated")] {
            let v = state.bytes(file, name)?;
            ensure!(v.len() == rows, "{file}.safetensors: tensor `{name}` has {} values, expected {rows}", v.len());
            dst[..rows].copy_from_slice(&v);
        }
        self.len = len;
        self.pos = pos;
        Ok(())
    }

    /// Empties the buffer (a resume without a saved buffer).
    pub fn clear(&mut self) {
        self.len = 0;
        self.pos = 0;
    }
}
