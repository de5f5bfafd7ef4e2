//! A learner's checkpoint state as the algorithm hands it over: named tensors grouped into files, and
//! named scalars. `checkpoint.rs` writes and reads it without knowing the algorithm (PPO's networks,
//! Adam and normalisers today; SAC's targets and replay buffer, a student's GRU later).
//!
//! Files become `<file>.safetensors` in the checkpoint; `model` is the policy (what eval and export
//! load). Scalars go into `state.json`: an f64 is written as a JSON number for people to read and
//! as its exact bit pattern under `exact_f64` (a decimal round trip through JSON is not guaranteed to
//! give back the same bits), a `u64` as a number, a 64-bit pattern (an RNG state) as 16 hex digits.

use std::collections::BTreeMap;

use anyhow::{Result, anyhow, bail};

/// The values of one tensor, row-major.
#[derive(Clone, Debug, PartialEq)]
pub enum TensorValues {
    /// 32-bit floats (network parameters, optimiser moments, observations).
    F32(Vec<f32>),
    /// 64-bit floats (normaliser statistics, episode accumulators).
    F64(Vec<f64>),
    /// Raw bytes (an env batch's saved state).
    U8(Vec<u8>),
}

/// One named tensor.
#[derive(Clone, Debug, PartialEq)]
pub struct NamedTensor {
    /// Unique name inside its file, e.g. `actor.0.weight`.
    pub name: String,
    /// Shape, e.g. `[in, out]`; the product is the number of values.
    pub shape: Vec<usize>,
    /// The values.
    pub values: TensorValues,
}

/// One tensor file of a learner's state.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StateFile {
    /// File stem: the checkpoint writes `<name>.safetensors`.
    pub name: String,
    /// JSON metadata stored under the safetensors metadata key `dextrain` (the policy's dims…).
    pub info: Option<String>,
    /// The tensors, in the order they were pushed.
    pub tensors: Vec<NamedTensor>,
}

/// Everything a learner needs to continue exactly: tensor files and scalars.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LearnerState {
    /// Tensor files, in the order they were first used.
    pub files: Vec<StateFile>,
    /// Named scalars as they appear in `state.json` (numbers, or hex strings for bit patterns).
    pub scalars: BTreeMap<String, serde_json::Value>,
    /// Exact bit patterns (16 hex digits) of the f64 scalars, `exact_f64` in `state.json`.
    pub exact_f64: BTreeMap<String, String>,
}

impl LearnerState {
    /// Every number of its f32 and f64 tensors (f64 rounded to f32), file by file in order: what
    /// `crate::dist::max_deviation_from_root` compares over the ranks.
    pub fn flat_values(&self) -> Vec<f32> {
        let mut out = Vec::new();
        for t in self.files.iter().flat_map(|f| &f.tensors) {
            match &t.values {
                TensorValues::F32(v) => out.extend_from_slice(v),
                TensorValues::F64(v) => out.extend(v.iter().map(|x| *x as f32)),
                TensorValues::U8(_) => {}
            }
        }
        out
    }
}

/// A `u64` as 16 hex digits.
pub fn hex64(x: u64) -> String {
    format!("{x:016x}")
}

/// Parses 16 (or fewer) hex digits, with or without `0x`.
pub fn parse_hex64(s: &str) -> Option<u64> {
    u64::from_str_radix(s.trim_start_matches("0x"), 16).ok()
}

impl LearnerState {
    /// The file `name`, if the state has it.
    pub fn file(&self, name: &str) -> Option<&StateFile> {
        self.files.iter().find(|f| f.name == name)
    }

    fn file_mut(&mut self, name: &str) -> &mut StateFile {
        if let Some(k) = self.files.iter().position(|f| f.name == name) {
            return &mut self.files[k];
        }
        self.files.push(StateFile { name: name.to_string(), ..Default::default() });
        self.files.last_mut().expect("just pushed")
    }

    /// Appends a tensor to file `file` (made on first use).
    pub fn push_tensor(&mut self, file: &str, name: &str, shape: Vec<usize>, values: TensorValues) {
        self.file_mut(file).tensors.push(NamedTensor { name: name.to_string(), shape, values });
    }

    /// Sets the JSON metadata of file `file`.
    pub fn set_info(&mut self, file: &str, info: String) {
        self.file_mut(file).info = Some(info);
    }

    /// The tensor `name` of file `file`, with `len` values if given (errors name the file and tensor).
    pub fn tensor(&self, file: &str, name: &str, len: Option<usize>) -> Result<&TensorValues> {
        let f = self.file(file).ok_or_else(|| anyhow!("{file}.safetensors is missing"))?;
        let t = f.tensors.iter().find(|t| t.name == name).ok_or_else(|| anyhow!("{file}.safetensors: tensor `{name}` is missing"))?;
        let n = match &t.values {
            TensorValues::F32(v) => v.len(),
            TensorValues::F64(v) => v.len(),
            TensorValues::U8(v) => v.len(),
        };
        if let Some(len) = len
            && n != len
        {
            bail!("{file}.safetensors: tensor `{name}` has {n} values, expected {len} (a checkpoint of another config?)");
        }
        Ok(&t.values)
    }

    /// An f32 tensor's values.
    pub fn f32s(&self, file: &str, name: &str, len: Option<usize>) -> Result<Vec<f32>> {
        match self.tensor(file, name, len)? {
            TensorValues::F32(v) => Ok(v.clone()),
            _ => bail!("{file}.safetensors: tensor `{name}` is not F32"),
        }
    }

    /// An f64 tensor's values.
    pub fn f64s(&self, file: &str, name: &str, len: Option<usize>) -> Result<Vec<f64>> {
        match self.tensor(file, name, len)? {
            TensorValues::F64(v) => Ok(v.clone()),
            _ => bail!("{file}.safetensors: tensor `{name}` is not F64"),
        }
    }

    /// A byte tensor's values.
    pub fn bytes(&self, file: &str, name: &str) -> Result<Vec<u8>> {
        match self.tensor(file, name, None)? {
            TensorValues::U8(v) => Ok(v.clone()),
            _ => bail!("{file}.safetensors: tensor `{name}` is not U8"),
        }
    }

    /// Sets an f64 scalar (kept exactly: its bit pattern goes beside the decimal).
    pub fn set_f64(&mut self, name: &str, x: f64) {
        self.scalars.insert(name.to_string(), serde_json::json!(x));
        self.exact_f64.insert(name.to_string(), hex64(x.to_bits()));
    }

    /// An f64 scalar: from its bit pattern when the state has one, else from the decimal.
    pub fn f64(&self, name: &str) -> Result<f64> {
        if let Some(h) = self.exact_f64.get(name) {
            return parse_hex64(h).map(f64::from_bits).ok_or_else(|| anyhow!("`exact_f64.{name}` = {h:?} is not 16 hex digits"));
        }
        self.scalars.get(name).and_then(|v| v.as_f64()).ok_or_else(|| anyhow!("`{name}` is missing or not a number"))
    }

    /// Sets a u64 scalar (a JSON integer).
    pub fn set_u64(&mut self, name: &str, x: u64) {
        self.scalars.insert(name.to_string(), serde_json::json!(x));
    }

    /// A u64 scalar.
    pub fn u64(&self, name: &str) -> Result<u64> {
        self.scalars.get(name).and_then(|v| v.as_u64()).ok_or_else(|| anyhow!("`{name}` is missing or not an unsigned integer"))
    }

    /// Sets a 64-bit pattern (an RNG state), written as 16 hex digits so that JSON keeps every bit.
    pub fn set_bits(&mut self, name: &str, x: u64) {
        self.scalars.insert(name.to_string(), serde_json::json!(hex64(x)));
    }

    /// A 64-bit pattern written by [`LearnerState::set_bits`].
    pub fn bits(&self, name: &str) -> Result<u64> {
        let v = self.scalars.get(name).ok_or_else(|| anyhow!("`{name}` is missing"))?;
        v.as_str().and_then(parse_hex64).ok_or_else(|| anyhow!("`{name}` = {v} is not a hex u64"))
    }
}
