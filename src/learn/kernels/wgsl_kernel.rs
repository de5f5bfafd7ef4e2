//! dextrain's own WGSL kernels on burn's command stream: a hand-written cubecl kernel
//! (`CubeKernel::source`) launched by burn's client between burn's kernels, with no flush or
//! submission of ours. cubecl binds the buffers in the order given, then the launch's constants as a
//! uniform (cached per value); the kernel's id covers its text through `key`, so each variant of a
//! template compiles once per process. Used by `wgsl_matmul.rs` and `elu.rs`.

use std::fmt::Debug;
use std::hash::Hash;

use burn::backend::tensor::FloatTensor;
use burn::backend::{Cube, TensorMetadata};
use burn::prelude::Tensor;
use burn_cubecl::cubecl::ir::metadata::Info;
use burn_cubecl::cubecl::ir::settings::{Dim3, ExecutionMode, KernelSettings};
use burn_cubecl::cubecl::ir::{AddressType, ElemType, Scope, UIntKind};
use cubecl_runtime::id::KernelId;
use cubecl_runtime::kernel::{CubeKernel, KernelDefinition, KernelMetadata, PrecompiledSource};
use cubecl_runtime::server::{CubeCount, KernelArguments, MetadataBindingInfo};

/// A WGSL kernel of ours: `source(key)` is its text (a template's variant), `name` begins with
/// `dextrain_` (gpu_counts counts it as `dextrain:<rest>`).
pub struct WgslKernel<K: Copy + Eq + Hash + Debug + Send + Sync + 'static> {
    /// The kernel's name (`dextrain_<what>`).
    pub name: &'static str,
    /// The variant of the text.
    pub key: K,
    /// The text of a variant.
    pub source: fn(K) -> String,
    /// The `@compute` function.
    pub entry_point: &'static str,
    /// Its `@workgroup_size` (x, y).
    pub workgroup: [u32; 2],
}

impl<K: Copy + Eq + Hash + Debug + Send + Sync + 'static> KernelMetadata for WgslKernel<K> {
    fn name(&self) -> &'static str {
        self.name
    }

    fn id(&self) -> KernelId {
        // unchecked: no loop-bound guards added by naga
        KernelId::new::<Self>()
            .info((self.name, self.key))
            .cube_dim(Dim3::new_2d(self.workgroup[0], self.workgroup[1]))
            .mode(ExecutionMode::Unchecked)
    }

    fn address_type(&self) -> ElemType {
        ElemType::UInt(UIntKind::U32)
    }
}

impl<K: Copy + Eq + Hash + Debug + Send + Sync + 'static> CubeKernel for WgslKernel<K> {
    fn define(&self) -> KernelDefinition {
        // nothing to compile (the source is the kernel); what the launch path reads
        let settings = KernelSettings::new(Dim3::new_2d(self.workgroup[0], self.workgroup[1]), ExecutionMode::Unchecked, AddressType::U32);
        KernelDefinition { body: Scope::root(settings.clone()), settings, info: Info::default() }
    }

    fn source(&self) -> Option<PrecompiledSource> {
        Some(PrecompiledSource { source: (self.source)(self.key), entrypoint_name: self.entry_point.to_string(), lang: "wgsl" })
    }
}

/// Launches `kernel` on `groups` workgroups with `buffers` bound in order (bindings 0, 1, …) and
/// `constants` (a multiple of two u32, as the WGSL struct lays them out) as the uniform after them,
/// on the client of the first buffer.
pub fn launch<K: Copy + Eq + Hash + Debug + Send + Sync + 'static>(
    kernel: WgslKernel<K>,
    groups: [u32; 3],
    buffers: &[&FloatTensor<Cube>],
    constants: &[u32],
) {
    assert!(constants.len() % 2 == 0 && !buffers.is_empty(), "wgsl_kernel: constants in pairs of u32, one buffer at least");
    // cubecl stages u64 words: two u32 fields per word, in memory order on a little-endian host and GPU
    let words: Vec<u64> = constants.chunks_exact(2).map(|p| u64::from(p[0]) | (u64::from(p[1]) << 32)).collect();
    let args = buffers
        .iter()
        .fold(KernelArguments::new(), |args, t| args.with_buffer(t.handle.clone().binding()))
        .with_info(MetadataBindingInfo::custom(words));
    buffers[0].client.launch(Box::new(kernel), CubeCount::Static(groups[0], groups[1], groups[2]), args);
}

/// WGSL of `fn {name}(k: u32, i: u32) -> f32`: entry i of the binding `{prefix}_{k}`, k < `group`,
/// picked by a switch on k (0.0 past the group) — how a template that binds one tensor per slot
/// (adam.wgsl's parameters, cat_rows.wgsl's blocks) reads slot k, with k the same across a
/// workgroup (no divergence).
pub fn indexed_getter(name: &str, prefix: &str, group: u32) -> String {
    let mut f = format!("fn {name}(k: u32, i: u32) -> f32 {{\n    var x = 0.0;\n    switch k {{\n");
    for k in 0..group {
        f += &format!("        case {k}u: {{ x = {prefix}_{k}[i]; }}\n");
    }
    f + "        default: {}\n    }\n    return x;\n}\n"
}

/// WGSL of `fn {name}(k: u32, i: u32, x: f32)`: writes x to entry i of the binding `{prefix}_{k}`
/// (nothing past the group) — [`indexed_getter`]'s twin for the slots a template writes.
pub fn indexed_setter(name: &str, prefix: &str, group: u32) -> String {
    let mut f = format!("fn {name}(k: u32, i: u32, x: f32) {{\n    switch k {{\n");
    for k in 0..group {
        f += &format!("        case {k}u: {{ {prefix}_{k}[i] = x; }}\n");
    }
    f + "        default: {}\n    }\n}\n"
}

/// The text of a template's module for one entry point: its common text and the sections marked
/// for `entry` (`//@entry NAMES` … `//@end`, NAMES the entry points a section belongs to), other
/// sections left out — so that each entry point's module declares the bindings it uses alone,
/// numbered as a launch passes its tensors (cubecl binds them in order, then the constants).
pub fn entry_module(template: &str, entry: &str) -> String {
    let mut kept = String::new();
    let mut keep = true;
    for line in template.lines() {
        if let Some(names) = line.strip_prefix("//@entry ") {
            keep = names.split_whitespace().any(|n| n == entry);
            continue;
        }
        if line == "//@end" {
            keep = true;
            continue;
        }
        if keep {
            kept += line;
            kept.push('\n');
        }
    }
    kept
}

/// Whether `t` is a contiguous row-major f32 tensor of `shape` (what our kernels bind).
pub fn is_plain(t: &FloatTensor<Cube>, shape: [usize; 2]) -> bool {
    t.dtype == burn::tensor::DType::F32 && t.is_contiguous() && t.shape().to_vec() == shape
}

/// `t`'s primitive on burn's wgpu device, checked to be a contiguous f32 tensor of `shape`; an
/// error saying which it is not. An autodiff tensor is refused (callers strip it with `inner()`
/// where they want its memory).
pub fn plain_primitive(t: &Tensor<2>, shape: [usize; 2]) -> anyhow::Result<FloatTensor<Cube>> {
    let p = t.clone().try_into_primitive::<Cube>().map_err(|e| anyhow::anyhow!("not a tensor of burn's wgpu device: {e:?}"))?;
    anyhow::ensure!(is_plain(&p, shape), "a {:?} {:?} tensor, not a contiguous f32 {shape:?}", p.shape().to_vec(), p.dtype);
    Ok(p)
}
