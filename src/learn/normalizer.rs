//! Empirical observation normalisation (rsl_rl's `EmpiricalNormalization`): running mean and
//! variance over every observation seen in training, `x̂ = (x − μ) / (σ + ε)`.
//!
//! The statistics are kept in f64 on the host and merged batch by batch with Chan et al.'s parallel
//! formula, so the result equals a two-pass mean/variance over all the data (tests/learn.rs checks
//! it). They are saved with the model: a policy is only meaningful with its normaliser.
//! [`DeviceNormalizer`] is the same merge in f32 tensors on the learner device, for the
//! device-resident rollouts (docs/gpu.md "The GPU loop").

use anyhow::Result;
use burn::prelude::*;

use super::kernels::fused_normalizer;
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
    /// The statistics as a GPU learner last uploaded them (not part of the statistics).
    pub uploaded: UploadedStats,
}

/// The statistics `[2, dim]` (μ, then s = 1 / (σ + ε), f32) that [`Normalizer::upload_normalized`]
/// last sent to the device, kept there while they stand: an inference, or a SAC batch on the host
/// path, then uploads its rows alone (one upload and one cubecl write where it made two, and
/// SAC's batch four fewer). Keyed by the f32 values themselves and the device, so any change of the
/// statistics — a merge, a load, a field set by hand — uploads them again. It is no part of
/// the statistics: a clone starts empty and any two compare equal.
#[derive(Default)]
pub struct UploadedStats(std::sync::Mutex<Option<(Vec<f32>, Tensor<2>)>>);

impl Clone for UploadedStats {
    fn clone(&self) -> UploadedStats {
        UploadedStats::default()
    }
}

impl PartialEq for UploadedStats {
    fn eq(&self, _: &UploadedStats) -> bool {
        true
    }
}

impl std::fmt::Debug for UploadedStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("UploadedStats")
    }
}

impl UploadedStats {
    /// `stats` `[2, dim]` as a tensor on `device`: the one kept if it holds these values on
    /// this device, else a fresh upload, kept for the next call.
    fn tensor(&self, stats: Vec<f32>, dim: usize, device: &Device) -> Tensor<2> {
        let mut kept = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((values, t)) = kept.as_ref()
            && *values == stats
            && t.device() == *device
        {
            return t.clone();
        }
        let t = to_tensor(stats.clone(), [2, dim], device);
        *kept = Some((stats, t.clone()));
        t
    }
}

impl Normalizer {
    /// Empty statistics for `dim` components.
    pub fn new(dim: usize) -> Normalizer {
        Normalizer { count: 0.0, mean: vec![0.0; dim], m2: vec![0.0; dim], eps: 1e-2, uploaded: UploadedStats::default() }
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
        // batch mean and Σ(x − μ_b)², two passes over the batch; in a data-parallel job
        // (`crate::dist`) the batch is every rank's rows: the count and sums, then the squared
        // deviations from the common mean, summed over the ranks (each rank then merges the same
        // batch statistics)
        let mut bmean = vec![0.0f64; d + 1];
        for r in 0..rows {
            for (k, m) in bmean[..d].iter_mut().enumerate() {
                *m += x[r * d + k] as f64;
            }
        }
        bmean[d] = rows as f64;
        crate::dist::sum_f64(&mut bmean);
        let nb = bmean.pop().unwrap_or(0.0);
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
        crate::dist::sum_f64(&mut bm2);
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
    /// `rows` `[n, dim]` uploaded and normalised on `device`, `(x − μ) · s` with μ and
    /// s = 1 / (σ + ε) `[1, dim]` worked out on the host in f64 and rounded to f32, when `on`;
    /// else the rows as they are. On burn's wgpu runtime the rows are written straight into a
    /// fresh tensor's memory (`nets::upload`: no host copy of them), the statistics go up as one
    /// `[2, dim]` tensor when they changed since the last call ([`UploadedStats`]), and one
    /// kernel of ours applies them (`kernels::standardize`); elsewhere
    /// two element-wise tensor ops, the same f32 arithmetic. The host's [`Normalizer::apply`]
    /// rounds once, at the end: the two differ by an f32 rounding.
    pub fn upload_normalized(&self, rows: &[f32], n: usize, device: &Device, on: bool) -> Tensor<2> {
        let d = self.dim();
        if !on || d == 0 {
            return to_tensor(rows.to_vec(), [n, d], device);
        }
        let mut stats = Vec::with_capacity(2 * d);
        stats.extend(self.mean.iter().map(|&m| m as f32)); // row 0: μ
        stats.extend(self.var().iter().map(|v| (1.0 / (v.sqrt() + self.eps)) as f32)); // row 1: s
        let inner = device.clone().inner();
        let stats = self.uploaded.tensor(stats, d, &inner); // uploaded once while they stand
        // the rows written straight into a fresh tensor's memory (`nets::upload`), then one kernel of
        // ours; the tensor ops where the kernel does not apply
        if let Ok(x) = super::nets::upload(rows, [n, d], &inner)
            && let Some(out) = super::kernels::standardize::standardize_on_gpu(&x, &stats)
        {
            return if device.is_autodiff() { out.autodiff() } else { out };
        }
        let x = to_tensor(rows.to_vec(), [n, d], device);
        let stats = if device.is_autodiff() { stats.autodiff() } else { stats };
        (x - stats.clone().narrow(0, 0, 1)) * stats.narrow(0, 1, 1)
    }

    /// `rows` `[n, dim]` normalised (when `on`) as a tensor on `device`: on a GPU normalised there
    /// ([`Normalizer::upload_normalized`]), on the CPU on the host in f64 ([`Normalizer::normalized`]).
    pub fn normalized_tensor(&self, rows: &[f32], n: usize, device: &Device, on: bool) -> Tensor<2> {
        if super::nets::is_gpu(device) {
            self.upload_normalized(rows, n, device, on)
        } else {
            to_tensor(self.normalized(rows, on), [n, self.dim()], device)
        }
    }

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
            uploaded: UploadedStats::default(),
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
    /// 1 / (√(M2 / n) + ε) `[1, D]` as of the last merge (normalizer.wgsl's `norm_apply` reads it).
    pub scale: Tensor<2>,
    /// ε added to σ in the denominator.
    pub eps: f64,
}

impl DeviceNormalizer {
    /// The host statistics `h` on `device`.
    pub fn from_host(h: &Normalizer, device: &Device) -> DeviceNormalizer {
        let d = h.dim();
        let f = |v: &[f64]| to_tensor(v.iter().map(|&x| x as f32).collect(), [1, d], device);
        let mean = f(&h.mean);
        let m2 = f(&h.m2);
        let scale = DeviceNormalizer::scale_of(&m2, h.count, h.eps);
        DeviceNormalizer { count: h.count, mean, m2, scale, eps: h.eps }
    }

    /// 1 / (√(M2 / n) + ε) `[1, D]` (1 / (1 + ε) before any merge: n = 0).
    fn scale_of(m2: &Tensor<2>, count: f64, eps: f64) -> Tensor<2> {
        if count > 0.0 {
            m2.clone().div_scalar(count).sqrt().add_scalar(eps).recip()
        } else {
            m2.ones_like().div_scalar(1.0 + eps)
        }
    }

    /// The statistics on the host (f32 values widened: a save and a load give them back exactly).
    pub fn to_host(&self) -> Result<Normalizer> {
        let f = |t: &Tensor<2>| -> Result<Vec<f64>> { Ok(to_host(t.clone())?.into_iter().map(|x| x as f64).collect()) };
        Ok(Normalizer { count: self.count, mean: f(&self.mean)?, m2: f(&self.m2)?, eps: self.eps, uploaded: UploadedStats::default() })
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
        self.scale = DeviceNormalizer::scale_of(&self.m2, self.count, self.eps);
    }

    /// `(x − μ) / (σ + ε)` of `x` `[B, D]` when `on` (μ = 0, σ = 1 before any update), else `x`.
    pub fn normalized(&self, x: Tensor<2>, on: bool) -> Tensor<2> {
        if !on || x.dims()[1] == 0 {
            return x;
        }
        (x - self.mean.clone()) * self.scale.clone() // scale = 1 / (√(M2 / n) + ε)
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

    /// An env step's observations `obs` `[N, O]` and `priv_obs` `[N, P]`: merged into the
    /// statistics, then normalised with them (when `on`; else returned as they are). On burn's wgpu
    /// runtime normalizer.wgsl's two kernels on burn's stream (`fused_normalizer.rs`), else
    /// [`DeviceNormalizer::update`] and [`DeviceNormalizer::normalized`].
    pub fn update_and_normalize(&mut self, obs: &Tensor<2>, priv_obs: &Tensor<2>, on: bool) -> Result<(Tensor<2>, Tensor<2>)> {
        if !on {
            return Ok((obs.clone(), priv_obs.clone()));
        }
        let mut work: Vec<(&mut DeviceNormalizer, &Tensor<2>)> = Vec::with_capacity(2);
        if obs.dims()[1] > 0 {
            work.push((&mut self.obs, obs));
        }
        if priv_obs.dims()[1] > 0 {
            work.push((&mut self.priv_obs, priv_obs));
        }
        let max_buffers = super::device::gpu_context_of(&obs.device()).map(|c| c.device.limits().max_storage_buffers_per_shader_stage);
        if let Some(max_buffers) = max_buffers
            && let Some(mut out) = fused_normalizer::update_and_normalize(&mut work, max_buffers)?
        {
            // (an empty observation is its own normalised value)
            let p = if priv_obs.dims()[1] > 0 { out.pop().expect("one output per normaliser") } else { priv_obs.clone() };
            let o = if obs.dims()[1] > 0 { out.pop().expect("one output per normaliser") } else { obs.clone() };
            return Ok((o, p));
        }
        self.obs.update(obs);
        self.priv_obs.update(priv_obs);
        Ok((self.obs.normalized(obs.clone(), true), self.priv_obs.normalized(priv_obs.clone(), true)))
    }

    /// Both on the host (actor's, critic's).
    pub fn to_host(&self) -> Result<(Normalizer, Normalizer)> {
        Ok((self.obs.to_host()?, self.priv_obs.to_host()?))
    }
}
