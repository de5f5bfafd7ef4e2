//! The form of dextrain's matrix product (`wgsl_matmul.rs`) measured on the adapter at hand:
//! [`tuned_variant`] times every tile shape of `Tile::CANDIDATES`, with scalar reads and, where
//! the operands allow, vec4 reads (`wgsl_matmul::Variant`), at the first product of each size,
//! strides, splits and epilogue in the process, and the fastest runs that product for the rest of
//! the process.
//!
//! Why this keeps runs exact, where burn's autotune would not (gpu_matmul.rs): every tile shape
//! sums each entry's k in increasing order with the same fused multiply-adds, and the splits over
//! k are planned from the shape alone (`wgsl_matmul::plan`), so a shape, or reading four values
//! at a time, changes which thread computes an entry and how its operands arrive, never its value. A run and its resume, or two machines that time the shapes
//! differently, compute the same numbers (a test compares every shape bit for bit).
//!
//! The cost: one warm-up launch (the variant's pipeline compiled by the driver, once per process),
//! then each variant timed over ~2 ms of launches between two host waits, in three rounds over all
//! variants in turn (a drift of the card's clock weighs on all alike), its best round counting; the
//! waits are counted (`dextrain:matmul_tuning`), in the first update of a run only. What each
//! variant measured is kept for the benches' JSON ([`report`]).

use std::collections::HashMap;
use std::sync::{Mutex, PoisonError};
use std::time::Instant;

use serde_json::json;

use crate::learn::kernels::wgsl_matmul::Variant;

/// A product as the tuner tells products apart: its launch constants but the tile.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ShapeKey {
    /// m, n, k and batches.
    pub sizes: [u32; 4],
    /// A's row, column and batch strides.
    pub a_strides: [u32; 3],
    /// B's likewise.
    pub b_strides: [u32; 3],
    /// Splits over k (1: none).
    pub splits: u32,
    /// matmul.wgsl's epilogue code (0: none, 1: bias, 2: bias and ELU, 3: ELU's gradient).
    pub epilogue: u32,
    /// Whether A is read with a row of ones (its sums a second output).
    pub ones_row: bool,
    /// Whether vec4 reads were among the candidates.
    pub vector_reads: bool,
}

/// One tuned product: what each shape took and which won.
#[derive(Clone, Debug)]
pub struct TuningRecord {
    /// The product.
    pub key: ShapeKey,
    /// The shape the shape rule picks (scalar reads).
    pub rule: Variant,
    /// The fastest variant, which runs the product from now on.
    pub chosen: Variant,
    /// Each variant timed and its µs per launch (host-timed: launches between two waits).
    pub micros: Vec<(Variant, f64)>,
    /// Milliseconds the timing took (compiles included).
    pub tuning_ms: f64,
}

/// The shape each product runs with, once timed.
static TUNED: Mutex<Option<HashMap<ShapeKey, Variant>>> = Mutex::new(None);

/// Every product timed so far, in order.
static REPORT: Mutex<Vec<TuningRecord>> = Mutex::new(Vec::new());

/// Host-timed launches of one variant per round, at least this long.
const ROUND_SECONDS: f64 = 2e-3;

/// Rounds over all variants; a variant's time is its best round's.
const ROUNDS: usize = 3;

/// The variant for the product `key`: the remembered one, or the fastest of `candidates()` timed
/// now, `rule` where none was timed. `launch(variant)` launches the product as `variant` into its
/// output; `wait()` waits for the device.
pub fn tuned_variant(key: &ShapeKey, rule: Variant, candidates: impl FnOnce() -> Vec<Variant>, mut launch: impl FnMut(Variant), mut wait: impl FnMut()) -> Variant {
    if let Some(v) = TUNED.lock().unwrap_or_else(PoisonError::into_inner).get_or_insert_with(HashMap::new).get(key) {
        return *v;
    }
    let candidates = candidates();
    let started = Instant::now();
    // each variant's pipeline compiled (a warm-up launch), and its launches per round from one
    // timed launch
    let mut reps = Vec::with_capacity(candidates.len());
    for &variant in &candidates {
        launch(variant);
        wait();
        let t = Instant::now();
        launch(variant);
        wait();
        let once = t.elapsed().as_secs_f64();
        reps.push((ROUND_SECONDS / once.max(1e-6)).ceil().clamp(2.0, 64.0) as usize);
    }
    // rounds over all variants in turn, so that a drift of the card's clock (rising from idle at a
    // process's start) weighs on every variant alike; each variant's best round counts
    let mut best = vec![f64::INFINITY; candidates.len()];
    for _ in 0..ROUNDS {
        for (i, &variant) in candidates.iter().enumerate() {
            let t = Instant::now();
            for _ in 0..reps[i] {
                launch(variant);
            }
            wait();
            best[i] = best[i].min(t.elapsed().as_secs_f64() / reps[i] as f64);
        }
    }
    let micros: Vec<(Variant, f64)> = candidates.iter().zip(&best).map(|(v, s)| (*v, s * 1e6)).collect();
    // two waits per variant to compile and size it, one per round
    crate::gpu_counts::add_n(crate::gpu_counts::Event::Wait, "dextrain:matmul_tuning", ((2 + ROUNDS) * candidates.len()) as u64);
    let chosen = micros.iter().min_by(|a, b| a.1.total_cmp(&b.1)).map_or(rule, |(v, _)| *v);
    TUNED.lock().unwrap_or_else(PoisonError::into_inner).get_or_insert_with(HashMap::new).insert(*key, chosen);
    let record = TuningRecord { key: *key, rule, chosen, micros, tuning_ms: started.elapsed().as_secs_f64() * 1e3 };
    REPORT.lock().unwrap_or_else(PoisonError::into_inner).push(record);
    chosen
}

/// Every product tuned so far in this process.
pub fn records() -> Vec<TuningRecord> {
    REPORT.lock().unwrap_or_else(PoisonError::into_inner).clone()
}

/// The tuned products as JSON (the benches' `matmul_tuning`): per product its sizes, the rule's
/// and the chosen shape, each shape's µs, and the time tuning took in all.
pub fn report() -> serde_json::Value {
    let records = records();
    let total_ms: f64 = records.iter().map(|r| r.tuning_ms).sum();
    let products: Vec<serde_json::Value> = records
        .iter()
        .map(|r| {
            let [m, n, k, batches] = r.key.sizes;
            let rule_us = r.micros.iter().find(|(v, _)| *v == r.rule).map(|(_, us)| *us);
            let chosen_us = r.micros.iter().find(|(v, _)| *v == r.chosen).map(|(_, us)| *us);
            json!({
                "m": m, "n": n, "k": k, "batches": batches, "splits": r.key.splits, "epilogue": r.key.epilogue, "ones_row": r.key.ones_row, "vector_reads": r.key.vector_reads,
                "a_strides": r.key.a_strides, "b_strides": r.key.b_strides,
                "rule": r.rule.label(), "chosen": r.chosen.label(), "rule_us": rule_us, "chosen_us": chosen_us,
                "us": r.micros.iter().map(|(v, us)| (v.label(), json!(us))).collect::<serde_json::Map<_, _>>(),
            })
        })
        .collect();
    json!({ "products": products.len(), "tuning_ms": total_ms, "per_product": products })
}
