//! A GPU learner's observations standardised on the device as one kernel of ours
//! (shaders/standardize.wgsl): `(x − μ) · s` per entry from the rows `[n, d]` and the
//! normaliser's statistics `[2, d]` (μ, then s = 1 / (√var + eps)). The tensor ops it replaces
//! sliced the statistics out of the rows' upload (three copy kernels: their offsets are not
//! aligned for views) and ran two element-wise kernels; the values are the same bit for bit.

use burn::backend::Cube;
use burn::backend::TensorMetadata;
use burn::backend::ops::FloatTensorOps;
use burn::backend::tensor::FloatTensor;
use burn::prelude::Tensor;
use burn::tensor::{DType, FloatDType, Shape};

use super::wgsl_kernel::{WgslKernel, launch};

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
    let xp = x.clone().try_into_primitive::<Cube>().ok()?;
    let sp = stats.clone().try_into_primitive::<Cube>().ok()?;
    let plain = |t: &FloatTensor<Cube>, shape: [usize; 2]| t.dtype == DType::F32 && t.is_contiguous() && t.shape().to_vec() == shape;
    if n == 0 || d == 0 || !plain(&xp, [n, d]) || !plain(&sp, [2, d]) {
        return None;
    }
    let entries = u32::try_from(n.checked_mul(d)?).ok()?;
    let (gx, gy) = crate::gpu::shaders::workgroups_of(entries, WORKGROUP);
    let out = Cube::float_empty(Shape::new([n, d]), &xp.device, FloatDType::F32); // written whole below
    let kernel = WgslKernel { name: "dextrain_standardize", key: (), source: standardize_source, entry_point: "standardize", workgroup: [WORKGROUP, 1] };
    launch(kernel, [gx, gy, 1], &[&xp, &sp, &out], &[entries, d as u32, gx * WORKGROUP, 0]);
    Some(Tensor::from_primitive::<Cube>(out))
}
