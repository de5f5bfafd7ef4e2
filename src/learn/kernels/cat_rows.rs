//! `Tensor::cat(parts, 0)` on burn's wgpu runtime in a few kernels of ours (`shaders/cat_rows.wgsl`,
//! a template): burn's cat launches one copy kernel per part, so a device-resident PPO rollout of
//! T steps stacked its seven per-step tensors (the observations, the critic's, the actions, μ, the
//! log-probabilities, the values, the rewards and done flags) in 7 T launches per update (168 for
//! the shipped 24-step configs). Here each launch binds up to G parts beside the output — G the
//! device's storage buffers per kernel less one (lavapipe binds 32; NVIDIA's driver far more),
//! at most [`MAX_PARTS`] — and copies them whole: ⌈T / G⌉ launches per tensor. The same values
//! (a copy), so the same bits.

use burn::backend::Cube;
use burn::backend::tensor::FloatTensor;
use burn::backend::ops::FloatTensorOps;
use burn::prelude::Tensor;
use burn::tensor::{FloatDType, Shape};

use crate::gpu::shaders::workgroups_of;
use crate::learn::kernels::wgsl_kernel::{WgslKernel, indexed_getter, launch, plain_primitive};

/// Invocations per workgroup (cat_rows.wgsl's `CAT_WORKGROUP`): each copies one entry.
const CAT_WORKGROUP: u32 = 256;

/// The most parts one launch takes (its constants: 16 bytes a part in a uniform).
pub const MAX_PARTS: usize = 256;

/// shaders/cat_rows.wgsl.
const TEMPLATE: &str = include_str!("../../../shaders/cat_rows.wgsl");

/// The WGSL of a launch over `group` parts: the template with a binding per part, the output and
/// the constants, and the accessor that reads part k's entry i.
pub fn shader_source(group: u32) -> String {
    let group = group.max(1);
    let mut bindings = String::new();
    for k in 0..group {
        bindings += &format!("@group(0) @binding({k}) var<storage, read_write> cat_part_{k}: array<f32>;\n");
    }
    bindings += &format!("@group(0) @binding({group}) var<storage, read_write> cat_out: array<f32>; // [Σ n_k, D]\n");
    bindings += &format!("@group(0) @binding({}) var<uniform> cl: CatLaunch;", group + 1);
    let accessors = indexed_getter("cat_part", "cat_part", group);
    TEMPLATE.replace("$GROUP", &group.to_string()).replace("$BINDINGS", &bindings).replace("$ACCESSORS", &accessors)
}

/// `Tensor::cat(parts, 0)` for `[n_k, D]` tensors of burn's wgpu device (autodiff stripped; the
/// result has none), with at most `max_storage_buffers` storage buffers bound per kernel (the
/// device's limit): ⌈P / G⌉ launches of ours, G = min(max − 1, [`MAX_PARTS`]). None where a part is
/// not a contiguous f32 tensor of that device, the widths differ, there is no part, or the device
/// binds fewer than two (the caller cats).
pub fn cat_rows(parts: &[Tensor<2>], max_storage_buffers: u32) -> Option<Tensor<2>> {
    let width = parts.first()?.dims()[1];
    let group = (max_storage_buffers as usize).saturating_sub(1).min(MAX_PARTS);
    if group == 0 || parts.iter().any(|p| p.dims()[1] != width) {
        return None;
    }
    let prims = parts.iter().map(|p| plain_primitive(&p.clone().inner(), p.dims()).ok()).collect::<Option<Vec<FloatTensor<Cube>>>>()?;
    let rows: usize = parts.iter().map(|p| p.dims()[0]).sum();
    // every index the kernel forms stays under 2^32
    u32::try_from(rows * width + CAT_WORKGROUP as usize).ok()?;
    let out = Cube::float_empty(Shape::new([rows, width]), &prims[0].device, FloatDType::F32); // written whole below
    let mut first_entry = 0u32;
    for chunk in prims.chunks(group) {
        // CatLaunch: per part (entries, first entry in out, first workgroup, 0)
        let mut words = Vec::with_capacity(4 * chunk.len());
        let mut workgroups = 0u32;
        for p in chunk {
            let entries = (p.meta.shape().num_elements()) as u32;
            words.extend([entries, first_entry, workgroups, 0]);
            first_entry += entries;
            workgroups += entries.div_ceil(CAT_WORKGROUP);
        }
        if workgroups == 0 {
            continue; // empty parts only
        }
        let mut buffers: Vec<&FloatTensor<Cube>> = chunk.iter().collect();
        buffers.push(&out);
        let (x, y) = workgroups_of(workgroups * CAT_WORKGROUP, CAT_WORKGROUP);
        let kernel = WgslKernel { name: "dextrain_cat_rows", key: chunk.len() as u32, source: shader_source, entry_point: "cat_rows", workgroup: [CAT_WORKGROUP, 1] };
        launch(kernel, [x, y, 1], &buffers, &words);
    }
    Some(Tensor::from_primitive::<Cube>(out))
}
