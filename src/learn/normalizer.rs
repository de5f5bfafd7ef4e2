//! Empirical observation normalisation (rsl_rl's `EmpiricalNormalization`): running mean and
//! variance over every observation seen in training, `x̂ = (x − μ) / (σ + ε)`.
//!
//! The statistics are kept in f64 on the host and merged batch by batch with Chan et al.'s parallel
//! formula, so the result equals a two-pass mean/variance over all the data (tests/learn.rs checks
//! it). They are saved with the model: a policy is only meaningful with its normaliser.
//! [`DeviceNormalizer`] is the same merge in f32 tensors on the learner device, for the
//! device-resident rollouts (README "The GPU loop").

use anyhow::Result;
use burn::prelude::*;

use super::nets::{to_host, to_tensor};
use super::state::{LearnerState, TensorValues};

/// Running mean and (population) variance of a vector-valued observation.
#[derive(Clone, Debug, PartialEq)]
pub struct Normalizer {
    /// Observations merged so far.
    pub count: f64,
    /// Running mean of each component.
    pub mean: Vec<f64>,
    /// Σ (x − μ)² (the sum of squared deviations; variance = m2 / count).
    pub m2: Vec<f64>,
    /// ε added to σ in the denominator (rsl_rl: 1e-2).
    pub eps: f64,
}

impl Normalizer {
    /// Empty statistics for `dim` components.
    pub fn new(dim: usize) -> Normalizer {
        Normalizer { count: 0.0, mean: vec![0.0; dim], m2: vec![0.0; dim], eps: 1e-2 }
    }

    /// Number of components.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Merges a batch `x` ([rows, dim], row-major) into the statistics.
    pub fn update(&mut self, x: &[f32]) {
        let d = self.dim();
        if d == 0 || x.is_empty() {
            return;
        }
        let rows = x.len() / d;
        let nb = rows as f64;
        // batch mean and Σ(x − μ_b)², two passes over the batch
        let mut bmean = vec![0.0f64; d];
        for r in 0..rows {
            for (k, m) in bmean.iter_mut().enumerate() {
                *m += x[r * d + k] as f64;
            }
        }
        for m in &mut bmean {
            *m /= nb;
        }
        let mut bm2 = vec![0.0f64; d];
        for r in 0..rows {
            for k in 0..d {
                let e = x[r * d + k] as f64 - bmean[k];
                bm2[k] += e * e;
            }
        }
        // Chan: n = na + nb, δ = μb − μa, μ = μa + δ nb / n, M2 = M2a + M2b + δ² na nb / n
        let na = self.count;
        let n = na + nb;
        for k in 0..d {
            let delta = bmean[k] - self.mean[k];
            self.mean[k] += delta * nb / n;
            self.m2[k] += bm2[k] + delta * delta * na * nb / n;
        }
        self.count = n;
    }

    /// Population variance of each component (1 before any update, as rsl_rl starts).
    pub fn var(&self) -> Vec<f64> {
        self.m2.iter().map(|m| if self.count > 0.0 { m / self.count } else { 1.0 }).collect()
    }

    /// Normalises `x` ([rows, dim]) in place: (x − μ) / (σ + ε). Before any update, μ = 0, σ = 1.
    pub fn apply(&self, x: &mut [f32]) {
        let d = self.dim();
        if d == 0 {
            return;
        }
        let scale: Vec<f64> = self.var().iter().map(|v| 1.0 / (v.sqrt() + self.eps)).collect();
        for row in x.chunks_mut(d) {
            for k in 0..d {
                row[k] = ((row[k] as f64 - self.mean[k]) * scale[k]) as f32;
            }
        }
    }
}

impl Normalizer {
    /// A normalised copy of `x` ([rows, dim]) when `on`, else a plain copy (a learner with
    /// `policy.obs_normalization = false`).
    pub fn normalized(&self, x: &[f32], on: bool) -> Vec<f32> {
        let mut x = x.to_vec();
        if on {
            self.apply(&mut x);
        }
        x
    }

    /// Saves the statistics as `<prefix>.mean`, `.m2` ([dim] f64), `.count`, `.eps` ([1] f64) into
    /// file `file` of `state`.
    pub fn save(&self, prefix: &str, state: &mut LearnerState, file: &str) {
        state.push_tensor(file, &format!("{prefix}.mean"), vec![self.dim()], TensorValues::F64(self.mean.clone()));
        state.push_tensor(file, &format!("{prefix}.m2"), vec![self.dim()], TensorValues::F64(self.m2.clone()));
        state.push_tensor(file, &format!("{prefix}.count"), vec![1], TensorValues::F64(vec![self.count]));
        state.push_tensor(file, &format!("{prefix}.eps"), vec![1], TensorValues::F64(vec![self.eps]));
    }

    /// Reads what [`Normalizer::save`] wrote, for observations of `dim` components.
    pub fn load(prefix: &str, dim: usize, state: &LearnerState, file: &str) -> Result<Normalizer> {
        Ok(Normalizer {
            count: state.f64s(file, &format!("{prefix}.count"), Some(1))?[0],
            mean: state.f64s(file, &format!("{prefix}.mean"), Some(dim))?,
            m2: state.f64s(file, &format!("{prefix}.m2"), Some(dim))?,
            eps: state.f64s(file, &format!("{prefix}.eps"), Some(1))?[0],
        })
    }
}

/// [`Normalizer`]'s statistics on the device (device-resident rollouts): mean and Σ(x − μ)² as `[1, D]` f32 tensors; the count
/// (rows merged so far) on the host.
pub struct DeviceNormalizer {
    /// Rows merged so far.
    pub count: f64,
    /// Running mean `[1, D]`.
    pub mean: Tensor<2>,
    /// Σ (x − μ)² `[1, D]`.
    pub m2: Tensor<2>,
    /// ε added to σ in the denominator.
    pub eps: f64,
}

impl DeviceNormalizer {
    /// The host statistics `h` on `device`.
    pub fn from_host(h: &Normalizer, device: &Device) -> DeviceNormalizer {
        let d = h.dim();
        let f = |v: &[f64]| to_tensor(v.iter().map(|&x| x as f32).collect(), [1, d], device);
        DeviceNormalizer { count: h.count, mean: f(&h.mean), m2: f(&h.m2), eps: h.eps }
    }

    /// The statistics on the host (f32 values widened: a save and a load give them back exactly).
    pub fn to_host(&self) -> Result<Normalizer> {
        let f = |t: &Tensor<2>| -> Result<Vec<f64>> { Ok(to_host(t.clone())?.into_iter().map(|x| x as f64).collect()) };
        Ok(Normalizer { count: self.count, mean: f(&self.mean)?, m2: f(&self.m2)?, eps: self.eps })
    }

    /// Merges the rows of `x` `[B, D]` ([`Normalizer::update`] as tensor ops).
    pub fn update(&mut self, x: &Tensor<2>) {
        let [b, d] = x.dims();
        if b == 0 || d == 0 {
            return;
        }
        let nb = b as f64;
        // the batch mean about the first row, μ_b = x₀ + mean(x − x₀): exact for a constant column
        // (a drawn parameter without randomisation), whose normalised value must stay exactly 0 as
        // on the host (÷ (0 + ε) would blow an f32 rounding of its mean up 100 times)
        let first = x.clone().slice([0..1, 0..d]);
        let bmean = first.clone() + (x.clone() - first).mean_dim(0); // [1, D]
        let bm2 = (x.clone() - bmean.clone()).square().sum_dim(0); // Σ (x − μ_b)² [1, D]
        // Chan: n = na + nb, δ = μb − μa, μ = μa + δ nb / n, M2 = M2a + M2b + δ² na nb / n
        let na = self.count;
        let n = na + nb;
        let delta = bmean - self.mean.clone();
        self.mean = self.mean.clone() + delta.clone().mul_scalar(nb / n);
        self.m2 = self.m2.clone() + bm2 + delta.square().mul_scalar(na * nb / n);
        self.count = n;
    }

    /// `(x − μ) / (σ + ε)` of `x` `[B, D]` when `on` (μ = 0, σ = 1 before any update), else `x`.
    pub fn normalized(&self, x: Tensor<2>, on: bool) -> Tensor<2> {
        if !on || x.dims()[1] == 0 {
            return x;
        }
        let scale = if self.count > 0.0 {
            self.m2.clone().div_scalar(self.count).sqrt().add_scalar(self.eps).recip() // 1 / (√(M2 / n) + ε)
        } else {
            self.mean.ones_like().div_scalar(1.0 + self.eps)
        };
        (x - self.mean.clone()) * scale
    }
}

/// The actor's and the critic's [`DeviceNormalizer`]s of a device-resident learner (PPO's, SAC's).
pub struct DeviceNormalizers {
    /// Actor observations.
    pub obs: DeviceNormalizer,
    /// Critic observations.
    pub priv_obs: DeviceNormalizer,
}

impl DeviceNormalizers {
    /// The host statistics `obs` and `priv_obs` on `device`.
    pub fn from_host(obs: &Normalizer, priv_obs: &Normalizer, device: &Device) -> DeviceNormalizers {
        DeviceNormalizers { obs: DeviceNormalizer::from_host(obs, device), priv_obs: DeviceNormalizer::from_host(priv_obs, device) }
    }

    /// Both on the host (actor's, critic's).
    pub fn to_host(&self) -> Result<(Normalizer, Normalizer)> {
        Ok((self.obs.to_host()?, self.priv_obs.to_host()?))
    }
}
