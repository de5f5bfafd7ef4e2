//! dextrain: a batched simulator and trainer for dexterous robot hands.
//!
//! See docs/architecture.md for the layout and docs/design.md §11 for the layers; `env` holds the simulator (CPU and GPU backends behind
//! [`env::EnvBatch`]), `hand` the URDF loader, `object` the manipulated objects, `traj` reference trajectories, `record` MCAP rollouts.

// The modules by layer, lowest first (docs/design.md §11; tests/suite/layers.rs enforces it).

// base helpers
pub mod text;
pub mod files;
pub mod rng;
pub mod console;
pub mod run_dir;
pub mod gpu_counts;
pub mod host_traffic;
pub mod dist;
pub mod tensorboard;
pub mod metrics;
pub mod plot;
// geometry and meshes
pub mod geom;
pub mod mesh;
// the config: plain data
pub mod config;
// models: the hand, objects, reference trajectories, recordings
pub mod hand;
pub mod object;
pub mod traj;
pub mod record;
// the GPU context and the shader ABI
pub mod gpu;
// rendered videos of rollouts (wgpu, headless) and their encoders
pub mod video;
// the simulator
pub mod env;
// the task layer
pub mod task;
// the live view (Foxglove WebSocket)
pub mod live;
// the learners
pub mod learn;
// export, eval (with play), the runner
pub mod export;
pub mod eval;
pub mod run;
// commands
pub mod replay;
pub mod retarget;
pub mod synth;
pub mod starter;
pub mod bench_contacts;
pub mod bench_matmul;
pub mod bench;
pub mod train;
