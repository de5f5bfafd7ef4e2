//! Export: the deployable policy — the ONNX model (onnx.rs), its contract `policy.json`
//! (contract.rs) and the `dextrain export` command (command.rs).

pub mod command;
pub mod contract;
pub mod onnx;
