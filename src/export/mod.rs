//! Export: the deployable policy — the ONNX model (onnx.rs), its contract `policy.json`
//! (contract.rs) and the `dextrain export` command (command.rs); and the other side, a robot's
//! controller built from those files alone (controller.rs), which `dextrain play` (play.rs) runs
//! on the simulator.

pub mod command;
pub mod contract;
pub mod controller;
pub mod onnx;
