//! Bytes moved between host memory and a GPU by dextrain's own calls, for the `time/host_bytes`
//! metric (docs/gpu.md "The GPU loop").
//!
//! Counted: every upload to and readback from the simulator's wgpu buffers (`env::gpu`, `gpu::context`; the action
//! noise's parameters included), every tensor that `learn::nets::to_tensor` puts on, or `to_host`
//! reads from, a GPU learner device, and the index tensors the PPO update uploads. Not counted:
//! what a CPU learner copies (host to host), and the few bytes of kernel arguments that burn's
//! runtime writes with each launch of its own kernels.
//!
//! The count is per thread (a run's loop is one thread; tests run runs side by side).

use std::cell::Cell;

thread_local! {
    static BYTES: Cell<u64> = const { Cell::new(0) };
}

/// Adds `bytes` moved across (either direction) by this thread.
pub fn add(bytes: u64) {
    BYTES.with(|b| b.set(b.get() + bytes));
}

/// Bytes this thread has moved so far (the difference of two readings is an interval's).
pub fn total() -> u64 {
    BYTES.with(|b| b.get())
}
