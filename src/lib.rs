//! dextrain: a batched simulator and trainer for dexterous robot hands.
//!
//! See README.md for the architecture; `env` holds the simulator (CPU and GPU backends behind
//! [`env::EnvBatch`]), `hand` the URDF loader, `object` the manipulated objects, `traj` reference trajectories, `record` MCAP rollouts.

pub mod bench;
pub mod bench_matmul;
pub mod checkpoint;
pub mod config;
pub mod console;
pub mod env;
pub mod eval;
pub mod export;
pub mod geom;
pub mod hand;
pub mod gpu_counts;
pub mod host_traffic;
pub mod learn;
pub mod mesh;
pub mod metrics;
pub mod object;
pub mod plot;
pub mod record;
pub mod replay;
pub mod run;
pub mod run_dir;
pub mod train;
pub mod task;
pub mod tensorboard;
pub mod traj;
