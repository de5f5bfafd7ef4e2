//! The integration tests, folded into one test binary (linking a binary against burn and wgpu
//! dominates the build: one binary links once). One module per area; `cargo test --release
//! --test suite <module>::` runs one area.

mod common;
mod cli;
mod config;
mod contract;
mod distill;
mod docs;
mod encoder;
mod export;
mod grasp;
mod hand;
mod ik;
mod journeys;
mod layers;
mod learn;
mod live;
mod mesh;
mod objects;
mod metrics;
mod mpi;
mod parity;
mod perturb;
mod physics;
mod play;
mod record;
mod reference;
mod retarget;
mod sac;
mod shaders;
mod starter;
mod task;
mod track;
mod train;
mod traj;
mod video;
