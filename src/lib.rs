//! dextrain: a batched simulator and trainer for dexterous robot hands.
//!
//! See README.md for the architecture; `env` holds the simulator (CPU and GPU backends behind
//! [`env::EnvBatch`]), `hand` the URDF loader, `traj` reference trajectories, `record` MCAP rollouts.

pub mod bench;
pub mod config;
pub mod env;
pub mod geom;
pub mod hand;
pub mod record;
pub mod replay;
pub mod traj;
