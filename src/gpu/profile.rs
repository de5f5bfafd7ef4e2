//! Where a GPU's time goes: the device time of each of dextrain's kernels and of the stretches of
//! burn's work between them, from wgpu timestamp queries (`train --gpu-profile`,
//! `bench --gpu-profile`; docs/gpu.md "Where a GPU's time goes").
//!
//! With profiling asked for ([`request`], on the thread that then makes the GPU context) and an adapter that writes
//! timestamps in compute passes and between commands (`TIMESTAMP_QUERY` and
//! `TIMESTAMP_QUERY_INSIDE_ENCODERS`: NVIDIA's, AMD's and Mesa's Vulkan drivers, lavapipe
//! included), each [`GpuContext`] keeps a [`GpuProfiler`]:
//!
//! - every dispatch that `GpuContext::encode_dispatches` records runs in a compute pass of its own
//!   with a timestamp at its start and its end, named `kernel:<entry point>` (the simulator's
//!   `step_main`, the task layer's `task_act`, …);
//! - [`around_burn`] stamps the queue before and after a stretch of the learner's work (burn's
//!   kernels and the kernels of ours launched on burn's stream, which cubecl records and submits
//!   itself): `burn:<what>`, the device time between the two stamps (the GPU's gaps between
//!   those kernels included);
//! - each optimiser step (`learn/kernels/fused_adam.rs`, kernels of ours on burn's stream) is
//!   `burn:adam`; each PPO minibatch's forward pass with its loss and its backward pass are
//!   `burn:ppo forward and loss` and `burn:ppo backward`.
//!
//! A span inside a bracket (an optimiser step or a minibatch's passes inside `burn:update`, the
//! rollout's noise kernel inside `burn:act`) is counted in both. The stamps
//! are read back when [`GpuContext::profile_read`] is called (an iteration's end, a bench chunk's)
//! or when the query set is full, and summed per name. Profiling changes what it measures a
//! little (a pass per dispatch, two submissions per bracket, one read per reading): its figures say
//! where the time goes, the unprofiled run says how long it takes.

use std::cell::Cell;
use std::collections::BTreeMap;

use anyhow::Result;
use burn::prelude::Device;

use super::context::GpuContext;

thread_local! {
    /// Per thread: a run makes its GPU contexts on its own thread, and tests run runs side by side.
    static REQUESTED: Cell<bool> = const { Cell::new(false) };
}

/// Asks every GPU context this thread makes from now on to profile, or not (`--gpu-profile`).
pub fn request(on: bool) {
    REQUESTED.with(|r| r.set(on));
}

/// Whether this thread asked for profiling.
pub fn requested() -> bool {
    REQUESTED.with(|r| r.get())
}

/// The timestamps a profiler holds between two readings (begin and end of 2,048 spans).
pub const CAPACITY: u32 = 4096;

/// The features a profile needs.
pub const FEATURES: wgpu::Features = wgpu::Features::TIMESTAMP_QUERY.union(wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS);

/// The device time of the spans of one name.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SpanTotal {
    /// Spans read.
    pub calls: u64,
    /// Their summed device time (ns).
    pub total_ns: f64,
    /// The longest (ns).
    pub max_ns: f64,
}

/// A query set of [`CAPACITY`] timestamps and what has been read from it.
pub struct GpuProfiler {
    query_set: wgpu::QuerySet,
    /// `QUERY_RESOLVE | COPY_SRC`, 8 bytes a timestamp.
    resolve: wgpu::Buffer,
    /// The host-mappable copy of `resolve`.
    staging: wgpu::Buffer,
    /// ns per timestamp tick.
    period_ns: f64,
    /// Timestamps reserved since the last reading.
    used: u32,
    /// The spans reserved since the last reading: (name, index of its first timestamp; the second
    /// follows it).
    pending: Vec<(String, u32)>,
    /// What has been read, by name.
    totals: BTreeMap<String, SpanTotal>,
    /// Spans not timed because the query set was full.
    dropped: u64,
}

impl GpuProfiler {
    /// A profiler on `device`, or None when the device lacks [`FEATURES`].
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue) -> Option<GpuProfiler> {
        if !device.features().contains(FEATURES) {
            return None;
        }
        let query_set = device.create_query_set(&wgpu::QuerySetDescriptor { label: Some("gpu profile"), ty: wgpu::QueryType::Timestamp, count: CAPACITY });
        let bytes = 8 * CAPACITY as u64;
        let resolve = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("gpu profile resolve"),
            size: bytes,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("gpu profile staging"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Some(GpuProfiler {
            query_set,
            resolve,
            staging,
            period_ns: queue.get_timestamp_period() as f64,
            used: 0,
            pending: Vec::new(),
            totals: BTreeMap::new(),
            dropped: 0,
        })
    }

    /// Reserves the two timestamps of a span `name`: the index of the first, or None when the
    /// query set is full (the span is then not timed, and counted as dropped).
    pub fn reserve(&mut self, name: &str) -> Option<u32> {
        if self.used + 2 > CAPACITY {
            self.dropped += 1;
            return None;
        }
        let first = self.used;
        self.used += 2;
        self.pending.push((name.to_string(), first));
        Some(first)
    }

    /// The timestamp writes of a compute pass that is span `first`.
    pub fn pass_writes(&self, first: u32) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites { query_set: &self.query_set, beginning_of_pass_write_index: Some(first), end_of_pass_write_index: Some(first + 1) }
    }

    /// Writes timestamp `index` between the commands of `enc`.
    pub fn stamp(&self, enc: &mut wgpu::CommandEncoder, index: u32) {
        enc.write_timestamp(&self.query_set, index);
    }

    /// Whether the query set is more than three quarters used (time to read it).
    pub fn nearly_full(&self) -> bool {
        self.used > CAPACITY / 4 * 3
    }

    /// Whether spans wait to be read.
    pub fn has_pending(&self) -> bool {
        self.used > 0
    }

    /// Records the resolve of the reserved timestamps and their copy to the staging buffer in
    /// `enc`: the staging buffer then holds `bytes()` bytes to hand to [`GpuProfiler::take`].
    pub fn encode_resolve(&self, enc: &mut wgpu::CommandEncoder) {
        enc.resolve_query_set(&self.query_set, 0..self.used, &self.resolve, 0);
    }

    /// The resolve buffer, read through the staging buffer (`GpuContext::profile_read`).
    pub fn buffers(&self) -> (&wgpu::Buffer, &wgpu::Buffer, u64) {
        (&self.resolve, &self.staging, 8 * self.used as u64)
    }

    /// Adds the spans whose timestamps `bytes` holds (the resolved u64s, in order) to the totals
    /// and starts afresh. A span whose end is not after its start (never written: an encoder
    /// dropped unsubmitted) is left out.
    pub fn take(&mut self, bytes: &[u8]) {
        let ticks: Vec<u64> = bytes.chunks_exact(8).map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes"))).collect();
        for (name, first) in self.pending.drain(..) {
            let (Some(&a), Some(&b)) = (ticks.get(first as usize), ticks.get(first as usize + 1)) else { continue };
            if b <= a {
                continue;
            }
            let ns = (b - a) as f64 * self.period_ns;
            let t = self.totals.entry(name).or_default();
            t.calls += 1;
            t.total_ns += ns;
            t.max_ns = t.max_ns.max(ns);
        }
        self.used = 0;
    }

    /// Forgets what has been read (and the dropped spans): the profile starts here.
    pub fn clear(&mut self) {
        self.totals.clear();
        self.dropped = 0;
    }

    /// The report: per name the calls, the total and mean device time and the longest span, the
    /// names by total time (largest first), and the dropped spans.
    pub fn to_json(&self) -> serde_json::Value {
        let mut names: Vec<(&String, &SpanTotal)> = self.totals.iter().collect();
        names.sort_by(|a, b| b.1.total_ns.total_cmp(&a.1.total_ns));
        let spans: Vec<serde_json::Value> = names
            .iter()
            .map(|(n, t)| {
                serde_json::json!({ "name": n, "calls": t.calls, "total_ms": t.total_ns / 1e6, "mean_us": t.total_ns / 1e3 / t.calls.max(1) as f64, "max_us": t.max_ns / 1e3 })
            })
            .collect();
        serde_json::json!({ "spans": spans, "dropped_spans": self.dropped })
    }
}

/// Runs `f` (which records learner work on burn's `device`) between two stamps of the queue when
/// `ctx` profiles, as span `burn:<what>`: burn's earlier work is submitted first, then a stamp,
/// then `f`'s work, then a stamp. Without a profiler `f` alone.
pub fn around_burn<T>(ctx: Option<&GpuContext>, device: &Device, what: &str, f: impl FnOnce() -> Result<T>) -> Result<T> {
    let Some(ctx) = ctx.filter(|c| c.profiles()) else { return f() };
    super::io::flush(device)?;
    let first = ctx.profile_stamp(None, &format!("burn:{what}"))?;
    let out = f()?;
    super::io::flush(device)?;
    if let Some(first) = first {
        ctx.profile_stamp(Some(first), "")?;
    }
    Ok(out)
}
