//! A GPU learner's observations standardised on the device as one kernel of ours
//! (shaders/standardize.wgsl): `(x − μ) · s` per entry from the rows `[n, d]` and the
//! normaliser's statistics `[2, d]` (μ, then s = 1 / (√var + eps)). The tensor ops it replaces
//! sliced the statistics out of the rows' upload (three copy kernels: their offsets are not
//! aligned for views) and ran two element-wise kernels; the values are the same bit for bit.

use burn::backend::Cube;
use burn::backend::ops::FloatTensorOps;
use burn::prelude::Tensor;
use burn::tensor::{FloatDType, Shape};

use super::wgsl_kernel::{WgslKernel, launch, plain_primitive};

/// shaders/standardize.wgsl.
const SHADER: &str = include_str!("../../../shaders/standardize.wgsl");
/// Invocations per workgroup.
const WORKGROUP: u32 = 256;

/// The kernel's module (one variant).
pub fn standardize_source(_: ()) -> String {
    SHADER.to_string()
}

/// `(x − μ) · s` `[n, d]` from `x` `[n, d]` and `stats` `[2, d]`, as one kernel, where both are
/// contiguous f32 tensors of burn's wgpu device (not autodiff); None elsewhere.
pub fn standardize_on_gpu(x: &Tensor<2>, stats: &Tensor<2>) -> Option<Tensor<2>> {
    let [n, d] = x.dims();
    if n == 0 || d == 0 {
        return None;
    }
    let (xp, sp) = (plain_primitive(x, [n, d]).ok()?, plain_primitive(stats, [2, d]).ok()?);
    let entries = u32::try_from(n.checked_mul(d)?).ok()?;
    let (gx, gy) = crate::gpu::shaders::workgroups_of(entries, WORKGROUP);
    let out = Cube::float_empty(Shape::new([n, d]), &xp.device, FloatDType::F32); // written whole below
    let kernel = WgslKernel { name: "dextrain_standardize", key: (), source: standardize_source, entry_point: "standardize", workgroup: [WORKGROUP, 1] };
    launch(kernel, [gx, gy, 1], &[&xp, &sp, &out], &[entries, d as u32, gx * WORKGROUP, 0]);
    Some(Tensor::from_primitive::<Cube>(out))
}
