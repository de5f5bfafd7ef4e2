//! Rollout storage and generalised advantage estimation (GAE), on the host.
//!
//! One rollout is `T` env steps of `N` envs. Row `t * N + i` of every array is env `i` at step `t`.
//! Observations are stored already normalised (with the statistics in force when the action was
//! taken), together with the action, its log-probability, the policy mean and std (for the KL of the
//! adaptive learning rate), the value estimate, the reward and the done flags.

/// A rollout of `steps × envs` transitions.
#[derive(Clone, Debug)]
pub struct RolloutStorage {
    pub steps: usize,
    pub envs: usize,
    pub obs_dim: usize,
    pub priv_dim: usize,
    pub act_dim: usize,
    /// [T·N, obs_dim] normalised actor observations.
    pub obs: Vec<f32>,
    /// [T·N, priv_dim] normalised critic observations.
    pub priv_obs: Vec<f32>,
    /// [T·N, act_dim] sampled actions (before clipping).
    pub actions: Vec<f32>,
    /// [T·N, act_dim] policy mean and standard deviation at acting time.
    pub mu: Vec<f32>,
    pub sigma: Vec<f32>,
    /// [T·N] log π(a|s) at acting time.
    pub log_prob: Vec<f32>,
    /// [T·N] V(s) at acting time.
    pub values: Vec<f32>,
    /// [T·N] rewards, with time-out bootstrapping already added (r += γ V(s) on a time-out).
    pub rewards: Vec<f32>,
    /// [T·N] 1 where the episode ended after this step (termination or time-out).
    pub dones: Vec<f32>,
    /// [T·N] filled by `compute_returns`.
    pub returns: Vec<f32>,
    pub advantages: Vec<f32>,
    /// Transitions added so far in this rollout.
    pub len: usize,
}

impl RolloutStorage {
    pub fn new(steps: usize, envs: usize, obs_dim: usize, priv_dim: usize, act_dim: usize) -> RolloutStorage {
        let n = steps * envs;
        RolloutStorage {
            steps,
            envs,
            obs_dim,
            priv_dim,
            act_dim,
            obs: vec![0.0; n * obs_dim],
            priv_obs: vec![0.0; n * priv_dim],
            actions: vec![0.0; n * act_dim],
            mu: vec![0.0; n * act_dim],
            sigma: vec![0.0; n * act_dim],
            log_prob: vec![0.0; n],
            values: vec![0.0; n],
            rewards: vec![0.0; n],
            dones: vec![0.0; n],
            returns: vec![0.0; n],
            advantages: vec![0.0; n],
            len: 0,
        }
    }

    /// Number of transitions in a full rollout.
    pub fn capacity(&self) -> usize {
        self.steps * self.envs
    }

    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// GAE(γ, λ) over the whole rollout, bootstrapping from `last_values` ([N], V of the
    /// observation after the last step). Advantages are then normalised over the rollout
    /// (zero mean, unit std), as rsl_rl does.
    pub fn compute_returns(&mut self, last_values: &[f32], gamma: f32, lam: f32) {
        gae(&self.rewards, &self.values, &self.dones, last_values, self.envs, gamma, lam, &mut self.advantages, &mut self.returns);
        // over every rank's rollout in a data-parallel job (`crate::dist`): the count and sum,
        // then the squared deviations from the common mean, summed over the ranks
        let mut first = [self.advantages.len() as f64, self.advantages.iter().map(|&a| a as f64).sum::<f64>()];
        crate::dist::sum_f64(&mut first);
        let [n, sum] = first;
        let mean = sum / n;
        // unbiased std, as torch's .std()
        let mut dev = [self.advantages.iter().map(|&a| (a as f64 - mean).powi(2)).sum::<f64>()];
        crate::dist::sum_f64(&mut dev);
        let var = dev[0] / (n - 1.0).max(1.0);
        let inv = 1.0 / (var.sqrt() + 1e-8);
        for a in &mut self.advantages {
            *a = ((*a as f64 - mean) * inv) as f32;
        }
    }
}

/// Generalised advantage estimation, backwards in time for `n` envs:
/// `δ_t = r_t + γ V(s_{t+1}) (1 − d_t) − V(s_t)`, `A_t = δ_t + γλ (1 − d_t) A_{t+1}`,
/// `R_t = A_t + V(s_t)`. `V(s_T)` is `last_values`. Time-outs are not special here: their
/// bootstrap `γ V(s_t)` is already in `r_t` (rsl_rl's convention).
#[allow(clippy::too_many_arguments)]
pub fn gae(
    rewards: &[f32],
    values: &[f32],
    dones: &[f32],
    last_values: &[f32],
    n: usize,
    gamma: f32,
    lam: f32,
    advantages: &mut [f32],
    returns: &mut [f32],
) {
    let t_len = rewards.len() / n;
    let mut next_adv = vec![0.0f32; n];
    for t in (0..t_len).rev() {
        for i in 0..n {
            let k = t * n + i;
            let next_value = if t + 1 == t_len { last_values[i] } else { values[k + n] };
            let not_done = 1.0 - dones[k];
            let delta = rewards[k] + gamma * next_value * not_done - values[k]; // δ = r + γV(s') − V(s)
            let adv = delta + gamma * lam * not_done * next_adv[i]; // A = δ + γλ A'
            next_adv[i] = adv;
            advantages[k] = adv;
            returns[k] = adv + values[k];
        }
    }
}
