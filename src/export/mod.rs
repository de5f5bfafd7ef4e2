//! Export: the deployable policy — the ONNX model and its contract `policy.json` (contract.rs).

pub mod contract;
