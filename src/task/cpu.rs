//! The task on the CPU: a [`CpuEnvBatch`] and the twins of [`super::task`], rayon over envs, in
//! the GPU's order.

use anyhow::Result;
use rayon::prelude::*;

use super::setup::{TaskSetup, ref_model, task_setup};
use super::spec::TaskSpec;
use super::task::*;
use super::{StepBatch, TaskBatch, check_actions, check_targets, decode_snapshot, encode_snapshot};
use crate::config::Config;
use crate::env::cpu::CpuEnvBatch;
use crate::gpu::layout::*;
use super::layout::*;
use crate::task::reference::{RefFrame, RefGlobals, RefModel, ref_sample};
use crate::env::{EnvBatch, SimModel};
use crate::task::bank::RefBank;


/// The task on the CPU: a [`CpuEnvBatch`] and the twins above, rayon over envs, in the GPU's order.
pub struct CpuTaskBatch {
    env: CpuEnvBatch,
    spec: TaskSpec,
    tc: TaskGlobals,
    bank: Option<RefBank>,
    rg: RefGlobals,
    task: Vec<TaskState>,
    targets: Vec<Targets>,
    /// `[N, OUT_MISC]` output records of the last step.
    misc: Vec<f32>,
    /// Reset request per env (the GPU's reset_mask).
    mask: Vec<u32>,
    mask_bool: Vec<bool>,
    /// Observe the ending envs' final states (`set_final_observations`).
    final_obs: bool,
    batch: StepBatch,
}

impl CpuTaskBatch {
    /// Builds the env batch and the task, with every env at the start of episode 0 (`reset_all`
    /// returns the first observations).
    pub fn new(cfg: &Config, model: SimModel) -> Result<CpuTaskBatch> {
        let TaskSetup { spec, tc, bank, rg } = task_setup(cfg, &model)?;
        let mut model = model;
        if let Some(b) = &bank {
            // each env holds the object its reference names
            model.set_reference_objects(b.objects.clone());
        }
        let n = spec.num_envs;
        let targets = vec![model.default_targets(); n];
        let batch = StepBatch::new(&spec);
        let mut b = CpuTaskBatch {
            env: CpuEnvBatch::new(model),
            spec,
            tc,
            bank,
            rg,
            task: vec![TaskState::default(); n],
            targets,
            misc: vec![0.0; n * OUT_MISC],
            mask: vec![0; n],
            mask_bool: vec![false; n],
            final_obs: false,
            batch,
        };
        b.reset_all()?;
        Ok(b)
    }

    /// The task constants (as uploaded to the GPU by the GPU backend).
    pub fn task_globals(&self) -> &TaskGlobals {
        &self.tc
    }

    /// The per-env task states.
    pub fn task_states(&self) -> &[TaskState] {
        &self.task
    }

    /// The reference bank (reference kinds).
    pub fn bank(&self) -> Option<&RefBank> {
        self.bank.as_ref()
    }

    /// Reference kinds: env `env`'s (augmented) reference at env step `step + k` of its episode.
    pub fn reference_frame(&self, env: usize, step: u32, k: u32) -> Option<RefFrame> {
        let bank = self.bank.as_ref()?;
        let r = RefModel::new(self.env.model(), bank, &self.rg);
        Some(ref_sample(&r, &self.task[env].cursor, step, k))
    }

    /// `task_observe` for every env with reset requests `self.mask`.
    fn observe(&mut self) {
        let (model, states, params) = self.env.parts_mut();
        let m = model.view();
        let r = ref_model(model, self.bank.as_ref(), &self.rg);
        let tc = &self.tc;
        let mask = &self.mask;
        let (od, pd) = (self.spec.obs_dim, self.spec.priv_dim);
        self.task
            .par_iter_mut()
            .zip(states.par_iter_mut())
            .zip(self.batch.obs.par_chunks_mut(od))
            .zip(self.batch.priv_obs.par_chunks_mut(pd))
            .enumerate()
            .for_each(|(i, (((ts, st), obs), privo))| task_observe(i as u32, st, &params[i], ts, mask[i], &m, tc, &r, obs, privo));
    }
}

impl CpuTaskBatch {
    /// `task_observe_final` for every env with a reset request (before the resets).
    fn observe_final(&mut self) {
        let model = self.env.model();
        let m = model.view();
        let r = ref_model(model, self.bank.as_ref(), &self.rg);
        let tc = &self.tc;
        let (states, params) = (self.env.states_ref(), self.env.params_ref());
        let (mask, task) = (&self.mask, &self.task);
        let (od, pd) = (self.spec.obs_dim, self.spec.priv_dim);
        self.batch
            .final_obs
            .par_chunks_mut(od)
            .zip(self.batch.final_priv_obs.par_chunks_mut(pd))
            .enumerate()
            .filter(|(i, _)| mask[*i] != 0)
            .for_each(|(i, (obs, privo))| task_observe_final(i as u32, &states[i], &params[i], &task[i], &m, tc, &r, obs, privo));
    }
}

impl TaskBatch for CpuTaskBatch {
    fn spec(&self) -> &TaskSpec {
        &self.spec
    }

    fn backend_name(&self) -> String {
        self.env.backend_name()
    }

    fn env(&mut self) -> &mut dyn EnvBatch {
        &mut self.env
    }

    fn gpu_context(&self) -> Option<&crate::gpu::context::GpuContext> {
        None
    }

    fn reset_all(&mut self) -> Result<&StepBatch> {
        self.env.reset_all()?;
        // the GPU's reset_mask after reset_all: 2 (episode 0) everywhere
        self.mask.fill(2);
        self.observe();
        self.batch.clear_misc();
        Ok(&self.batch)
    }

    fn step(&mut self, actions: &[f32]) -> Result<&StepBatch> {
        self.step_inner(actions, None)
    }

    fn set_final_observations(&mut self, on: bool) -> Result<()> {
        self.final_obs = on;
        Ok(())
    }

    fn step_with_targets(&mut self, actions: &[f32], targets: &[Targets]) -> Result<&StepBatch> {
        check_targets(&self.spec, targets)?;
        self.step_inner(actions, Some(targets))
    }

    fn reference_frames(&mut self, k: u32) -> Result<Option<Vec<RefFrame>>> {
        let states = self.env.states_ref();
        Ok(self.bank.is_some().then(|| (0..self.spec.num_envs).filter_map(|i| self.reference_frame(i, states[i].step, k)).collect()))
    }

    fn targets(&mut self) -> Result<Vec<Targets>> {
        Ok(self.task.iter().map(|t| t.targets).collect())
    }

    fn reference_now(&mut self, env: usize) -> Result<Option<RefFrame>> {
        let step = self.env.states_ref()[env].step;
        Ok(self.reference_frame(env, step, 0))
    }

    fn save_state(&mut self) -> Result<Vec<u8>> {
        Ok(encode_snapshot(self.env.states_ref(), self.env.springs_ref(), self.env.params_ref(), &self.task))
    }

    fn load_state(&mut self, state: &[u8]) -> Result<()> {
        let (env, task) = decode_snapshot(state, self.spec.num_envs, self.env.model().globals.n_springs as usize)?;
        self.env.set_states(&env.states)?;
        self.env.set_springs(&env.springs)?;
        self.env.set_params(&env.params)?;
        self.task.copy_from_slice(&task);
        Ok(())
    }
}

impl CpuTaskBatch {
    /// One step (see [`TaskBatch::step`]); `given`: targets that replace the mapped ones.
    fn step_inner(&mut self, actions: &[f32], given: Option<&[Targets]>) -> Result<&StepBatch> {
        check_actions(&self.spec, actions)?;
        let na = self.spec.action_dim;
        {
            let model = self.env.model();
            let m = model.view();
            let r = ref_model(model, self.bank.as_ref(), &self.rg);
            let tc = &self.tc;
            let states = self.env.states_ref();
            self.task
                .par_iter_mut()
                .zip(self.targets.par_iter_mut())
                .zip(actions.par_chunks(na))
                .enumerate()
                .for_each(|(i, ((ts, t), a))| *t = task_act(a, &states[i], ts, &m, tc, &r));
        }
        if let Some(given) = given {
            self.targets.copy_from_slice(given);
            for (ts, t) in self.task.iter_mut().zip(given) {
                ts.targets = *t;
            }
        }
        self.env.step(&self.targets)?;
        {
            let model = self.env.model();
            let m = model.view();
            let r = ref_model(model, self.bank.as_ref(), &self.rg);
            let tc = &self.tc;
            let (states, params, stats) = (self.env.states_ref(), self.env.params_ref(), self.env.stats_ref());
            self.task
                .par_iter_mut()
                .zip(self.misc.par_chunks_mut(OUT_MISC))
                .zip(self.mask.par_iter_mut())
                .enumerate()
                .for_each(|(i, ((ts, out), mask))| *mask = task_reward(&states[i], &params[i], &stats[i], ts, &m, tc, &r, out));
        }
        for (b, &m) in self.mask_bool.iter_mut().zip(&self.mask) {
            *b = m != 0;
        }
        if self.final_obs && self.mask_bool.iter().any(|&b| b) {
            self.observe_final();
        }
        if self.mask_bool.iter().any(|&b| b) {
            self.env.reset(&self.mask_bool)?;
        }
        self.observe();
        self.batch.fill_misc(&self.misc);
        Ok(&self.batch)
    }
}
