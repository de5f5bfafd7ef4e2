//! Empirical observation normalisation (rsl_rl's `EmpiricalNormalization`): running mean and
//! variance over every observation seen in training, `x̂ = (x − μ) / (σ + ε)`.
//!
//! The statistics are kept in f64 on the host and merged batch by batch with Chan et al.'s parallel
//! formula, so the result equals a two-pass mean/variance over all the data (tests/learn.rs checks
//! it). They are saved with the model: a policy is only meaningful with its normaliser.

use anyhow::Result;

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
