//! `dextrain bench --matmul --device gpu`: the GPU learner's matrix products at the PPO bench's
//! shapes, timed with each matmul routine of `learn::kernels::gpu_matmul` in one process, so that the
//! routine a run uses is chosen by measurement on the adapter at hand (BENCHMARKS.md).
//!
//! The products are those of one PPO minibatch (rows = envs × 24 steps / 4 minibatches) through
//! the peer benchmark's actor [96, 512, 256, 128, 22] and critic [130, 512, 256, 128, 1]: per layer
//! the forward `x W`, the weight gradient `xᵀ g` and, past the first layer, the input gradient
//! `g Wᵀ` (the transposes are strided views, as in the update). Each routine's products are
//! checked against burn's own routine (largest difference relative to the largest entry).

use anyhow::{Result, anyhow};
use burn::backend::Cube;
use burn::prelude::{Device, Tensor};
use burn::tensor::Distribution;
use serde_json::json;

use crate::learn::kernels::gpu_matmul::{self, GpuMatmul};
use crate::learn::nets::to_host;

/// The actor's layer widths of the peer benchmark.
const ACTOR: [usize; 5] = [96, 512, 256, 128, 22];
/// The critic's layer widths of the peer benchmark.
const CRITIC: [usize; 5] = [130, 512, 256, 128, 1];

/// One product `lhs · rhs` of the update: its name and operands.
struct Product {
    name: String,
    /// [m, k] (a transposed view where the update multiplies by a transpose).
    lhs: Tensor<2>,
    /// [k, n] (likewise).
    rhs: Tensor<2>,
}

impl Product {
    /// Multiply-adds × 2.
    fn flops(&self) -> f64 {
        let [m, k] = self.lhs.dims();
        let [_, n] = self.rhs.dims();
        2.0 * m as f64 * n as f64 * k as f64
    }
}

/// The products of one minibatch of `rows` rows through both networks.
fn products(rows: usize, device: &Device) -> Vec<Product> {
    let normal = |shape: [usize; 2]| Tensor::<2>::random(shape, Distribution::Normal(0.0, 1.0), device);
    let mut out = Vec::new();
    for (net, dims) in [("actor", ACTOR), ("critic", CRITIC)] {
        for l in 0..dims.len() - 1 {
            let (i, o) = (dims[l], dims[l + 1]);
            let x = normal([rows, i]); // [R, in]
            let w = normal([i, o]); // [in, out]
            let g = normal([rows, o]); // [R, out]
            out.push(Product { name: format!("{net}{l} x·W [{rows}×{i}]·[{i}×{o}]"), lhs: x.clone(), rhs: w.clone() });
            out.push(Product { name: format!("{net}{l} xᵀ·g [{i}×{rows}]·[{rows}×{o}]"), lhs: x.transpose(), rhs: g.clone() });
            if l > 0 {
                out.push(Product { name: format!("{net}{l} g·Wᵀ [{rows}×{o}]·[{o}×{i}]"), lhs: g, rhs: w.transpose() });
            }
        }
    }
    out
}

/// `lhs · rhs` with `routine`.
fn product_with(routine: GpuMatmul, lhs: &Tensor<2>, rhs: &Tensor<2>) -> Result<Tensor<2>> {
    let prim = |t: &Tensor<2>| t.clone().try_into_primitive::<Cube>().map_err(|e| anyhow!("not a tensor of burn's wgpu device: {e:?}"));
    Ok(Tensor::from_primitive::<Cube>(gpu_matmul::matmul_with(routine, prim(lhs)?, prim(rhs)?)))
}

/// Waits for the device by reading one entry of `t`.
fn wait_for(t: &Tensor<2>) -> Result<f32> {
    Ok(to_host(t.clone().slice([0..1, 0..1]))?[0])
}

/// Times each routine of `which` on the products of one minibatch of `rows` rows: per routine the
/// minibatch's product time (median of `rounds` rounds of `reps` launches per product), its
/// TFLOP/s, the products that fell back to burn's routine and the largest relative difference
/// from burn's results; and the fastest routine that ran without falling back.
pub fn run_matmul_bench(rows: usize, reps: usize, rounds: usize, which: &[GpuMatmul], device: Device, device_name: &str) -> Result<serde_json::Value> {
    let device = device.clone().inner();
    let prods = products(rows, &device);
    let flops: f64 = prods.iter().map(Product::flops).sum();
    // burn's results, the reference
    let reference: Vec<Tensor<2>> = prods.iter().map(|p| product_with(GpuMatmul::Burn, &p.lhs, &p.rhs)).collect::<Result<_>>()?;
    let scale: Vec<f32> = reference
        .iter()
        .map(|r| to_host(r.clone().abs().max()).map(|v| v[0]))
        .collect::<Result<_>>()?;
    let mut routines = Vec::new();
    let mut best: Option<(f64, &str)> = None;
    for (routine, name) in GpuMatmul::NAMES.into_iter().filter(|(r, _)| which.contains(r)) {
        let fallbacks_before = gpu_matmul::fallbacks();
        let mut worst_diff = 0.0f32;
        for (p, (r, s)) in prods.iter().zip(reference.iter().zip(&scale)) {
            let out = product_with(routine, &p.lhs, &p.rhs)?;
            let d = to_host((out - r.clone()).abs().max())?[0];
            worst_diff = worst_diff.max(d / s.max(f32::MIN_POSITIVE));
        }
        let mut per_product = Vec::new();
        let mut total_ms = 0.0;
        for p in &prods {
            let mut times = Vec::new();
            for _ in 0..rounds.max(1) {
                let start = std::time::Instant::now();
                let mut last = None;
                for _ in 0..reps.max(1) {
                    last = Some(product_with(routine, &p.lhs, &p.rhs)?);
                }
                if let Some(t) = &last {
                    wait_for(t)?;
                }
                times.push(1e3 * start.elapsed().as_secs_f64() / reps.max(1) as f64);
            }
            times.sort_by(f64::total_cmp);
            let ms = times[times.len() / 2];
            total_ms += ms;
            per_product.push(json!({ "product": p.name, "ms": ms, "tflops": p.flops() / (ms * 1e-3) / 1e12 }));
        }
        let fell_back = gpu_matmul::fallbacks() - fallbacks_before;
        if fell_back == 0 && best.is_none_or(|(t, _)| total_ms < t) {
            best = Some((total_ms, name));
        }
        crate::console::status(&format!("  {name}: {total_ms:.2} ms per minibatch's products, {:.1} TFLOP/s, {fell_back} fell back, worst relative difference {worst_diff:.1e}", flops / (total_ms * 1e-3) / 1e12));
        routines.push(json!({
            "routine": name,
            "minibatch_products_ms": total_ms,
            "tflops": flops / (total_ms * 1e-3) / 1e12,
            "fallbacks": fell_back,
            "worst_relative_difference": worst_diff,
            "products": per_product,
        }));
    }
    Ok(json!({
        "bench": "dextrain_matmul_bench",
        "device": device_name,
        "rows": rows,
        "reps": reps,
        "rounds": rounds,
        "minibatch_gflop": flops / 1e9,
        "default_routine": GpuMatmul::DEFAULT.name(),
        "fastest_routine": best.map(|(_, n)| n),
        "routines": routines,
        // `dextrain_tuned`'s timing of every tile shape per product
        "matmul_tuning": crate::learn::kernels::matmul_tuning::report(),
    }))
}
