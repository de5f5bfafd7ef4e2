//! `CpuEnvBatch`: the env batch on the CPU, rayon over envs, running the CPU twins of the shaders.

use anyhow::{Result, ensure};
use rayon::prelude::*;

use crate::gpu::layout::*;
use super::physics::env_step;
use super::reset::{clear_springs, reset_params, reset_state};
use super::{EnvBatch, EnvSpec, SimModel};

pub struct CpuEnvBatch {
    model: SimModel,
    states: Vec<EnvState>,
    /// `[N, n_springs]` contact springs (see `gpu::layout::spring_slot`).
    springs: Vec<[f32; 4]>,
    params: Vec<EnvParams>,
    stats: Vec<StepStats>,
}

impl CpuEnvBatch {
    /// Makes the batch with every env at the start of episode 0.
    pub fn new(model: SimModel) -> CpuEnvBatch {
        let n = model.spec.num_envs;
        let per_env = model.globals.n_springs as usize;
        let mut b = CpuEnvBatch {
            model,
            states: vec![EnvState::default(); n],
            springs: vec![[0.0; 4]; n * per_env],
            params: vec![bytemuck::Zeroable::zeroed(); n],
            stats: vec![bytemuck::Zeroable::zeroed(); n],
        };
        b.reset_where(|_| Some(0));
        b
    }

    pub fn model(&self) -> &SimModel {
        &self.model
    }

    /// The current states, borrowed (the task layer reads them without a copy).
    pub fn states_ref(&self) -> &[EnvState] {
        &self.states
    }

    /// The contact springs `[N, n_springs]`, borrowed.
    pub fn springs_ref(&self) -> &[[f32; 4]] {
        &self.springs
    }

    /// The model, the states (mutable: the task layer places a reference task's hand and object at
    /// a reset) and the parameters, borrowed together.
    pub fn parts_mut(&mut self) -> (&SimModel, &mut [EnvState], &[EnvParams]) {
        (&self.model, &mut self.states, &self.params)
    }

    /// The current parameters, borrowed.
    pub fn params_ref(&self) -> &[EnvParams] {
        &self.params
    }

    /// Overwrites the parameters (checkpoint restore).
    pub fn set_params(&mut self, params: &[EnvParams]) -> Result<()> {
        ensure!(params.len() == self.params.len(), "{} parameter sets for {} envs", params.len(), self.params.len());
        self.params.copy_from_slice(params);
        Ok(())
    }

    /// What happened in each env during the last step, borrowed.
    pub fn stats_ref(&self) -> &[StepStats] {
        &self.stats
    }

    /// Resets env i to the episode `episode_of(i)` returns (None = leave it).
    fn reset_where(&mut self, episode_of: impl Fn(usize) -> Option<u32> + Sync) {
        let g = &self.model.globals;
        let joints = &self.model.joints;
        let objects = &self.model.object_descs;
        let ref_objects = &self.model.ref_objects;
        let per_env = g.n_springs as usize;
        self.states
            .par_iter_mut()
            .zip(self.params.par_iter_mut())
            .zip(self.springs.par_chunks_mut(per_env.max(1)))
            .enumerate()
            .for_each(|(i, ((st, p), springs))| {
                let next = st.episode + 1;
                if let Some(ep) = episode_of(i) {
                    let ep = if ep == u32::MAX { next } else { ep };
                    *p = reset_params(g, objects, ref_objects, i as u32, ep);
                    *st = reset_state(g, joints, p, i as u32, ep, st.bad_resets);
                    clear_springs(springs);
                }
            });
    }
}

impl EnvBatch for CpuEnvBatch {
    fn spec(&self) -> &EnvSpec {
        &self.model.spec
    }

    fn backend_name(&self) -> String {
        format!("cpu (rayon, {} threads)", rayon::current_num_threads())
    }

    fn reset_all(&mut self) -> Result<()> {
        self.reset_where(|_| Some(0));
        Ok(())
    }

    fn reset(&mut self, mask: &[bool]) -> Result<()> {
        ensure!(mask.len() == self.states.len(), "reset mask has {} entries for {} envs", mask.len(), self.states.len());
        self.reset_where(|i| if mask[i] { Some(u32::MAX) } else { None });
        Ok(())
    }

    fn step(&mut self, targets: &[Targets]) -> Result<()> {
        ensure!(targets.len() == self.states.len(), "{} targets for {} envs", targets.len(), self.states.len());
        let m = self.model.view();
        let per_env = self.model.globals.n_springs as usize;
        self.states
            .par_iter_mut()
            .zip(self.springs.par_chunks_mut(per_env.max(1)))
            .zip(self.params.par_iter_mut())
            .zip(self.stats.par_iter_mut())
            .zip(targets.par_iter())
            .enumerate()
            .for_each(|(i, ((((st, springs), p), stats), t))| env_step(i as u32, st, springs, p, t, &m, stats));
        Ok(())
    }

    fn states(&mut self) -> Result<Vec<EnvState>> {
        Ok(self.states.clone())
    }

    fn set_states(&mut self, states: &[EnvState]) -> Result<()> {
        ensure!(states.len() == self.states.len(), "{} states for {} envs", states.len(), self.states.len());
        self.states.copy_from_slice(states);
        Ok(())
    }

    fn springs(&mut self) -> Result<Vec<[f32; 4]>> {
        Ok(self.springs.clone())
    }

    fn set_springs(&mut self, springs: &[[f32; 4]]) -> Result<()> {
        ensure!(springs.len() == self.springs.len(), "{} contact springs for {} (N × n_springs)", springs.len(), self.springs.len());
        self.springs.copy_from_slice(springs);
        Ok(())
    }

    fn params(&mut self) -> Result<Vec<EnvParams>> {
        Ok(self.params.clone())
    }

    fn set_params(&mut self, params: &[EnvParams]) -> Result<()> {
        CpuEnvBatch::set_params(self, params)
    }

    fn stats(&mut self) -> Result<Vec<StepStats>> {
        Ok(self.stats.clone())
    }
}
