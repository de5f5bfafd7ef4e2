//! What the GPU is asked to do, counted on the thread that asks (docs/gpu.md "The GPU loop", "What the
//! GPU is asked to do"): kernels, queue submissions and host synchronisations, each by where it
//! comes from. The counts do not depend on the adapter (lavapipe counts what an H100 would run),
//! so they are the figures a 2-core machine without a GPU can improve.
//!
//! - **Kernels**: every launch of burn's wgpu runtime (cubecl's launch observer, named as the
//!   kernel names itself, shortened to its type name: `burn:MatmulEntry`, `burn:KernelBinop`, …;
//!   dextrain's own kernels launched on burn's stream name themselves `dextrain_<what>`),
//!   and every dispatch of dextrain's own shaders (`dextrain:<what>`, counted where the compute
//!   pass is recorded).
//! - **Submissions**: dextrain's own `queue.submit` calls by what they submit; the queue's total
//!   (dextrain's and burn's together: cubecl submits before each upload, at each read, at each
//!   flush and every few dozen kernels) is read from wgpu's submission index by
//!   [`queue_submissions`], which costs one empty submission per reading.
//! - **Host synchronisations**: `reads` (a blocking readback of device memory: burn's
//!   `into_data` through `learn::nets::to_host`, or dextrain's staging-buffer reads), `maps` (the
//!   staging buffers mapped by those reads) and `waits` (blocking `device.poll` calls). Uploads
//!   (`queue.write_buffer`, burn's `from_data`) are counted beside them: they do not wait, but each
//!   of burn's makes cubecl submit what it has recorded first.
//!
//! Counts are per thread (a run's loop is one thread; tests run runs side by side), read as a
//! [`GpuCounts`] snapshot; the difference of two snapshots is what happened between them.

use std::cell::RefCell;
use std::collections::BTreeMap;
use std::sync::{Arc, OnceLock};

/// The kinds of events counted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Event {
    /// A kernel launch (burn's) or a compute dispatch (dextrain's).
    Kernel,
    /// A `queue.submit` by dextrain.
    Submission,
    /// A blocking readback of device memory.
    Read,
    /// A staging buffer mapped for reading.
    Map,
    /// A blocking wait for the device (`device.poll(wait)`).
    Wait,
    /// A host → device write.
    Upload,
}

impl Event {
    /// Every kind, in report order.
    pub const ALL: [Event; 6] = [Event::Kernel, Event::Submission, Event::Read, Event::Map, Event::Wait, Event::Upload];

    /// The name in reports (`kernels`, `submissions`, …).
    pub fn name(self) -> &'static str {
        match self {
            Event::Kernel => "kernels",
            Event::Submission => "submissions",
            Event::Read => "reads",
            Event::Map => "maps",
            Event::Wait => "waits",
            Event::Upload => "uploads",
        }
    }
}

thread_local! {
    static COUNTS: RefCell<BTreeMap<(Event, String), u64>> = const { RefCell::new(BTreeMap::new()) };
}

/// Counts one event of `kind` from `source` on this thread.
pub fn add(kind: Event, source: &str) {
    add_n(kind, source, 1);
}

/// Counts `n` events of `kind` from `source` on this thread.
pub fn add_n(kind: Event, source: &str, n: u64) {
    if n == 0 {
        return;
    }
    COUNTS.with(|c| {
        let mut c = c.borrow_mut();
        match c.get_mut(&(kind, source.to_string())) {
            Some(v) => *v += n,
            None => {
                c.insert((kind, source.to_string()), n);
            }
        }
    });
}

/// A snapshot of this thread's counts (or the difference of two: [`GpuCounts::since`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GpuCounts {
    /// Events by (kind, source).
    pub by_source: BTreeMap<(Event, String), u64>,
}

impl GpuCounts {
    /// This thread's counts so far.
    pub fn now() -> GpuCounts {
        GpuCounts { by_source: COUNTS.with(|c| c.borrow().clone()) }
    }

    /// What was counted after `earlier` (a snapshot of the same thread).
    pub fn since(&self, earlier: &GpuCounts) -> GpuCounts {
        let mut by_source = BTreeMap::new();
        for (k, &v) in &self.by_source {
            let d = v - earlier.by_source.get(k).copied().unwrap_or(0);
            if d > 0 {
                by_source.insert(k.clone(), d);
            }
        }
        GpuCounts { by_source }
    }

    /// Events of `kind`, from every source.
    pub fn total(&self, kind: Event) -> u64 {
        self.by_source.iter().filter(|((k, _), _)| *k == kind).map(|(_, v)| v).sum()
    }

    /// Events of `kind` from sources that start with `prefix` (`"burn:"`, `"dextrain:"`).
    pub fn total_from(&self, kind: Event, prefix: &str) -> u64 {
        self.by_source.iter().filter(|((k, s), _)| *k == kind && s.starts_with(prefix)).map(|(_, v)| v).sum()
    }

    /// The queue's submissions, burn's included: wgpu's submission index advances between two
    /// [`queue_submissions`] readings less the map requests counted here, or, where the index was
    /// not read (`None`: a simulator without burn), dextrain's own submissions.
    pub fn queue_submissions(&self, index_advances: Option<u64>) -> u64 {
        index_advances.map_or(self.total(Event::Submission), |q| q.saturating_sub(self.map_requests()))
    }

    /// The staging-buffer map requests counted: dextrain's maps and burn's reads (cubecl maps one
    /// staging buffer per tensor read, and `learn::nets::to_host` reads one tensor a call).
    pub fn map_requests(&self) -> u64 {
        self.total(Event::Map) + self.total_from(Event::Read, "burn:")
    }

    /// Host synchronisations: the blocking reads (each of dextrain's readbacks maps its staging
    /// buffers and waits once inside it; burn's reads wait inside cubecl).
    pub fn host_syncs(&self) -> u64 {
        self.total(Event::Read)
    }

    /// The report: per kind the total and the sources (`{"kernels": {"total": 41, "by_source":
    /// {"burn:matmul_entry": 12, …}}, …}`), every count divided by `per` (e.g. the env steps the
    /// snapshot covers), `"queue_submissions"` ([`GpuCounts::queue_submissions`]) and
    /// `"queue_index_advances"` (wgpu's submission index between two [`queue_submissions`]
    /// readings, as read; null where not read).
    pub fn to_json(&self, per: f64, index_advances: Option<u64>) -> serde_json::Value {
        let per = per.max(1e-12);
        let mut out = serde_json::Map::new();
        for kind in Event::ALL {
            let sources: serde_json::Map<String, serde_json::Value> = self
                .by_source
                .iter()
                .filter(|((k, _), _)| *k == kind)
                .map(|((_, s), &v)| (s.clone(), serde_json::json!(v as f64 / per)))
                .collect();
            out.insert(kind.name().to_string(), serde_json::json!({ "total": self.total(kind) as f64 / per, "by_source": sources }));
        }
        out.insert("host_syncs".into(), serde_json::json!(self.host_syncs() as f64 / per));
        let per_json = |n: Option<u64>| n.map_or(serde_json::Value::Null, |q| serde_json::json!(q as f64 / per));
        out.insert("queue_index_advances".into(), per_json(index_advances));
        out.insert("queue_submissions".into(), serde_json::json!(self.queue_submissions(index_advances) as f64 / per));
        serde_json::Value::Object(out)
    }
}

/// wgpu's submission index on `queue` so far. It advances at every `queue.submit` on the device
/// (burn's included) and also at every `map_async` (wgpu-core 30 reserves an index to flush the
/// queue's pending writes to the buffer, and advances it whether or not it submits anything) and
/// `on_submitted_work_done`: the submissions between two readings are the advances less those
/// ([`GpuCounts::to_json`] takes off the map requests it counted). The reading itself submits an
/// empty command list, so the advances between two readings `a`, `b` are `b − a − 1`. None if
/// wgpu's index cannot be read (its only public form is its `Debug` text).
pub fn queue_submissions(queue: &wgpu::Queue) -> Option<u64> {
    let index = queue.submit(std::iter::empty());
    let text = format!("{index:?}"); // "SubmissionIndex { index: 42 }"
    let digits: String = text.chars().skip_while(|c| !c.is_ascii_digit()).take_while(|c| c.is_ascii_digit()).collect();
    digits.parse().ok()
}

/// wgpu's submission index advances between two [`queue_submissions`] readings `a` then `b` (the
/// second reading's own empty submission not counted): the submissions and map requests between.
pub fn submissions_between(a: Option<u64>, b: Option<u64>) -> Option<u64> {
    Some(b?.checked_sub(a?)?.saturating_sub(1))
}

/// burn's kernel names are Rust type names (`burn_cubecl::kernel::binary::BinaryOp<…>`, or a
/// fused kernel's id): the last path segment before any generic arguments.
fn short_kernel_name(name: &str) -> &str {
    let base = name.split('<').next().unwrap_or(name);
    base.rsplit("::").next().unwrap_or(base).trim()
}

/// cubecl's launch observer: counts each launch on the issuing thread.
struct CountLaunches;

impl cubecl_runtime::logging::LaunchObserver for CountLaunches {
    fn launched(&self, kernel: &'static str) {
        let name = short_kernel_name(kernel);
        match name.strip_prefix("dextrain_") {
            Some(ours) => add(Event::Kernel, &format!("dextrain:{ours}")), // dextrain's kernels on burn's stream
            None if count_call_sites() => add(Event::Kernel, &format!("burn:{name} @ {}", call_site())),
            None => add(Event::Kernel, &format!("burn:{name}")),
        }
    }
}

/// Whether burn's kernels are counted by the line of dextrain's code that launched them
/// (`DEXTRAIN_COUNT_CALL_SITES=1`: `burn:KernelBinop @ src/learn/sac/mod.rs:412`), a diagnosis of
/// where launches come from; each launch then captures a backtrace (milliseconds), so the
/// figures' times are not meant to be read.
fn count_call_sites() -> bool {
    static ON: OnceLock<bool> = OnceLock::new();
    *ON.get_or_init(|| std::env::var("DEXTRAIN_COUNT_CALL_SITES").is_ok_and(|v| v == "1"))
}

/// The innermost frame of dextrain's own code (`src/…:line`, this file's left out) on the stack
/// of a launch, or `?` where the backtrace has no line tables.
fn call_site() -> String {
    let trace = std::backtrace::Backtrace::force_capture().to_string();
    // frames print their location as `at <path>:<line>:<column>`
    trace
        .lines()
        .filter_map(|l| l.trim().strip_prefix("at "))
        .filter(|loc| !loc.contains("/.cargo/") && !loc.contains("/rustc/"))
        .filter_map(|loc| Some(&loc[loc.find("src/")?..]))
        .find(|loc| !loc.starts_with("src/gpu_counts.rs"))
        .map(|loc| loc.rsplit_once(':').map_or(loc, |(file_line, _column)| file_line).to_string())
        .unwrap_or_else(|| "?".into())
}

/// Installs the counter of burn's kernel launches (once per process; idempotent). Called where
/// burn's wgpu runtime is started (`learn::device`).
pub fn observe_burn_launches() {
    static INSTALLED: OnceLock<()> = OnceLock::new();
    INSTALLED.get_or_init(|| {
        // the observation lasts as long as the process: it is never dropped
        std::mem::forget(cubecl_runtime::logging::LaunchObservation::new(Arc::new(CountLaunches)));
    });
}
