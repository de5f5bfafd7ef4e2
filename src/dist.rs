//! Data-parallel training across processes (issue 37): this process's rank in an MPI job and the
//! collectives the learners need (sum over ranks, broadcast from rank 0).
//!
//! Built with `--features mpi` and launched by `mpiexec -n N` (or SLURM's `srun`), [`init`] joins
//! the job; otherwise — the default build, or one process started without a launcher — there is
//! one rank and every collective leaves its buffer as it is. The collectives are called by every
//! rank in the same order with buffers of the same length (a rank that skips one deadlocks the job:
//! the callers keep their calls outside any rank-dependent branch).

#[cfg(feature = "mpi")]
use mpi::traits::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// This process's rank and the number of ranks, set once by [`init`] (rank 0 of 1 before), and
/// its rank among the ranks on its node (those that share its memory: `MPI_Comm_split_type`).
static RANK: AtomicUsize = AtomicUsize::new(0);
static SIZE: AtomicUsize = AtomicUsize::new(1);
static LOCAL_RANK: AtomicUsize = AtomicUsize::new(0);

/// Holds the MPI environment while it is alive: `main` keeps it until it returns (MPI is finalised
/// when it drops). Without MPI it holds nothing.
pub struct Guard {
    #[cfg(feature = "mpi")]
    _universe: Option<mpi::environment::Universe>,
}

/// Joins the MPI job this process was launched in (`--features mpi`), or stays rank 0 of 1.
/// Call once, first thing in `main`; keep the guard until the end.
///
/// Fails when the launcher declared a world of N processes (`PMI_SIZE`, `OMPI_COMM_WORLD_SIZE`) and
/// MPI made this process one of another number: MPICH's `MPI_Init` quietly starts a process alone
/// ("singleton") when it cannot reach its launcher (no `PMI_FD`/`PMI_PORT`, an `mpiexec` of another
/// MPI implementation, a launcher connection that failed), and N processes that each believed they
/// were rank 0 of 1 would all create the same run directory and train it at once.
pub fn init() -> anyhow::Result<Guard> {
    #[cfg(feature = "mpi")]
    {
        // a process that no launcher started runs alone: no MPI at all (tests, `dextrain check`)
        if !launched_by_mpi() {
            return Ok(Guard { _universe: None });
        }
        let universe = mpi::initialize();
        if let Some(u) = &universe {
            let w = u.world();
            let (rank, size) = (w.rank() as usize, w.size() as usize);
            if let Some((key, declared)) = launcher_world_size() {
                if declared != size {
                    anyhow::bail!(
                        "launched as one of {declared} MPI processes ({key}={declared}), but MPI_Init made this process rank {rank} of {size}: the MPI library did not join the launcher's job (an mpiexec of another MPI implementation than the one dextrain links, or a launcher connection that failed); nothing was written"
                    );
                }
            }
            RANK.store(rank, Ordering::Relaxed);
            SIZE.store(size, Ordering::Relaxed);
            // the ranks of this node, in world-rank order
            LOCAL_RANK.store(w.split_shared(w.rank()).rank() as usize, Ordering::Relaxed);
        }
        Ok(Guard { _universe: universe })
    }
    // a build without MPI started as one of N > 1 processes by a launcher would train N copies of
    // one run, each alone: it stops instead, saying how to build with MPI
    #[cfg(not(feature = "mpi"))]
    {
        if let Some((key, declared)) = launcher_world_size() {
            if declared > 1 {
                anyhow::bail!(
                    "launched as one of {declared} MPI processes ({key}={declared}), but this dextrain was built without MPI: build it with `cargo build --release --features mpi` (docs/mpi.md); nothing was written"
                );
            }
        }
        Ok(Guard {})
    }
}

/// The number of processes the launcher started this one among, where it says: MPICH's and Intel
/// MPI's (and SLURM's PMI) `PMI_SIZE`, Open MPI's `OMPI_COMM_WORLD_SIZE`; with the variable's name.
fn launcher_world_size() -> Option<(&'static str, usize)> {
    ["PMI_SIZE", "OMPI_COMM_WORLD_SIZE"].into_iter().find_map(|k| Some((k, std::env::var(k).ok()?.trim().parse().ok()?)))
}

/// True when an MPI launcher started this process (MPICH's and Intel MPI's `PMI_RANK`, Open MPI's
/// `OMPI_COMM_WORLD_RANK`, SLURM's `PMI_RANK`/`PMIX_RANK`).
#[cfg(feature = "mpi")]
fn launched_by_mpi() -> bool {
    ["PMI_RANK", "PMIX_RANK", "OMPI_COMM_WORLD_RANK", "MPI_LOCALRANKID"].iter().any(|k| std::env::var_os(k).is_some())
}

/// This process's rank (0 without MPI).
pub fn rank() -> usize {
    RANK.load(Ordering::Relaxed)
}

/// This process's rank among the ranks on its node (0 without MPI): which of the node's GPUs it
/// takes (`gpu::context`).
pub fn local_rank() -> usize {
    LOCAL_RANK.load(Ordering::Relaxed)
}

/// The number of ranks (1 without MPI).
pub fn size() -> usize {
    SIZE.load(Ordering::Relaxed)
}

/// Replaces `buf` on every rank by its element-wise sum over the ranks (f32).
pub fn sum_f32(buf: &mut [f32]) {
    sum_over_ranks(buf);
}

/// Replaces `buf` on every rank by its element-wise sum over the ranks (f64).
pub fn sum_f64(buf: &mut [f64]) {
    sum_over_ranks(buf);
}

/// The element-wise sum over the ranks, in place (one all-reduce; nothing with one rank).
#[cfg(feature = "mpi")]
fn sum_over_ranks<T: mpi::datatype::Equivalence + Copy>(buf: &mut [T]) {
    if size() == 1 {
        return;
    }
    let send = buf.to_vec();
    mpi::topology::SimpleCommunicator::world().all_reduce_into(&send[..], buf, mpi::collective::SystemOperation::sum());
}

/// Without MPI there is one rank: the sum is the buffer itself.
#[cfg(not(feature = "mpi"))]
fn sum_over_ranks<T>(_buf: &mut [T]) {}

/// Replaces `buf` on every rank by its element-wise mean over the ranks (f32): the sum, divided by
/// the number of ranks.
pub fn mean_f32(buf: &mut [f32]) {
    if size() == 1 {
        return;
    }
    sum_f32(buf);
    let inv = 1.0 / size() as f32;
    for x in buf.iter_mut() {
        *x *= inv;
    }
}

/// Gives every rank rank 0's `buf`.
pub fn broadcast_f32(buf: &mut [f32]) {
    if size() == 1 {
        return;
    }
    // without MPI there is one rank, and the return above is taken
    #[cfg(not(feature = "mpi"))]
    let _ = buf;
    #[cfg(feature = "mpi")]
    mpi::topology::SimpleCommunicator::world().process_at_rank(0).broadcast_into(buf);
}

/// The largest |x − x₀| over the ranks and elements, x₀ being rank 0's `buf` (0 with one rank):
/// how far the ranks' copies of something that should be identical have drifted apart.
pub fn max_deviation_from_root(buf: &[f32]) -> f32 {
    if size() == 1 {
        return 0.0;
    }
    let mut root = buf.to_vec();
    broadcast_f32(&mut root);
    let mine = buf.iter().zip(&root).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    // the maximum over the ranks (an f32 is exact as an f64)
    gather_f64(mine as f64).into_iter().fold(0.0f64, f64::max) as f32
}

/// Every rank's `x`, in rank order, on every rank (`[x]` with one rank): a sum of one-hot slots.
pub fn gather_f64(x: f64) -> Vec<f64> {
    let mut slots = vec![0.0f64; size()];
    slots[rank()] = x;
    sum_f64(&mut slots);
    slots
}

/// True on every rank when `flag` is true on any rank (a sum of flags; `flag` itself with one rank).
pub fn any(flag: bool) -> bool {
    if size() == 1 {
        return flag;
    }
    let mut v = [if flag { 1.0f64 } else { 0.0 }];
    sum_f64(&mut v);
    v[0] > 0.0
}

/// Gives every rank rank 0's string (at most 4,096 bytes).
pub fn broadcast_string(s: &str) -> String {
    if size() == 1 {
        return s.to_string();
    }
    let mut buf = [0.0f32; 4097];
    let bytes = s.as_bytes();
    let n = bytes.len().min(4096);
    buf[0] = n as f32;
    for (b, x) in bytes[..n].iter().zip(&mut buf[1..]) {
        *x = *b as f32;
    }
    broadcast_f32(&mut buf);
    let n = buf[0] as usize;
    let out: Vec<u8> = buf[1..=n.min(4096)].iter().map(|x| *x as u8).collect();
    String::from_utf8_lossy(&out).into_owned()
}

/// Ends every rank of the job with exit code `code` (after this rank printed why): a rank that
/// failed alone would leave the others waiting in their next collective. Returns with one rank.
pub fn abort_job(code: i32) {
    if size() == 1 {
        return;
    }
    // without MPI there is one rank, and the return above is taken
    #[cfg(not(feature = "mpi"))]
    let _ = code;
    #[cfg(feature = "mpi")]
    {
        // the launcher forwards this rank's last lines (its error) before the abort ends it
        std::thread::sleep(std::time::Duration::from_millis(300));
        mpi::topology::SimpleCommunicator::world().abort(code);
    }
}
