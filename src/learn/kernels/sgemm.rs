//! dextrain's own single-precision matrix product for AVX2 + FMA CPUs, for the products of the
//! dense layers whose left operand has contiguous rows: the forward `x W` and the input gradient
//! `g Wᵀ` (`learn::kernels::affine`). The weight gradient `xᵀ g` (left operand strided) stays with gemm.
//!
//! Why: the crate `gemm`'s AVX2 kernel packs both operands and loses up to a third of its speed on
//! the learners' short products (depth 96–256, 24,576 rows): on the 2-core Zen 4 VM, one thread,
//! `[24576, 96] · [96, 512]` ran at 65 GFLOP/s in gemm and 86 GFLOP/s here, `g Wᵀ` at `[24576,
//! 256] · [256, 512]` at 87 and 100 (BENCHMARKS.md, "an own AVX2 matrix product"). gemm's AVX-512
//! kernels are as fast as this one at these shapes, so this kernel runs only where the learner's
//! products would otherwise run gemm's AVX2 kernel ([`runs`]).
//!
//! The method (BLIS's, with the roles of A and B as the shapes here favour):
//! - C is cut into tiles of 6 rows × 16 columns, each held in 12 ymm accumulators; per step p of
//!   the depth, two vectors of B's row p and six broadcasts of A(i..i+6, p) give 12 FMAs;
//! - B is packed once per call (for up to [`PACKED_B_FLOATS`] of it at a time) into panels of 16
//!   columns, `[depth blocks][panels][kc][16]`, zero-padded to a multiple of 16 columns, so a
//!   tile's kc × 16 B values (16 KiB) are contiguous and stay in L1 whatever B's strides were;
//! - A is not packed: its six rows are read where they are (contiguous, so six sequential
//!   streams), and a block of 96 rows × kc stays in L2 while every panel of B passes over it;
//! - blocks of 96 rows of C are the rayon tasks (each writes its own rows).

use crate::learn::kernels::isa::{Isa, isa};

/// Rows of C per tile (six broadcasts of A per step).
const MR: usize = 6;
/// Columns of C per tile (two 8-lane vectors of B per step).
const NR: usize = 16;
/// Depth of one pass over a tile: the tile's B panel, KC × 16 floats (16 KiB), stays in L1.
const KC: usize = 256;
/// Rows of C per task: its A rows, MC × KC floats (96 KiB), stay in L2 across B's panels.
const MC: usize = 96;
/// Floats of packed B held at once (1 MiB): B is packed in slabs of depth up to this over all its
/// columns, each slab used by every row block before the next is packed.
const PACKED_B_FLOATS: usize = 1 << 18;

/// Whether the learner's dense-layer products with contiguous left rows run this kernel: where the
/// CPU kernels are AVX2 + FMA ([`isa`]: an AVX2-only CPU, or `DEXTRAIN_SIMD=avx2`), or where the
/// CPU has AVX-512 but this build lacks gemm's AVX-512 kernels (no `x86-v4` feature).
pub fn runs() -> bool {
    let isa = isa();
    isa >= Isa::Avx2 && !(cfg!(feature = "x86-v4") && isa == Isa::Avx512)
}

/// `C = (C if accumulate, else 0) + A B` for C [m, n] row-major (row stride n), A(i, p) at
/// `a[i·a_row + p]` and B(p, j) at `b[p·b_row + j·b_col]` (any non-negative strides), over the
/// rayon pool when `parallel`.
///
/// # Safety
/// The CPU has AVX2 and FMA (checked by [`runs`] or [`crate::learn::kernels::isa::detected_isa`]); `a`,
/// `b` and `c` point to live storage covering every element the strides above name, and C does not
/// overlap A or B.
#[allow(clippy::too_many_arguments)]
pub unsafe fn matmul(m: usize, n: usize, k: usize, a: *const f32, a_row: usize, b: *const f32, b_row: isize, b_col: isize, c: *mut f32, accumulate: bool, parallel: bool) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: forwarded from the caller
    unsafe {
        avx2::matmul(m, n, k, a, a_row, b, b_row, b_col, c, accumulate, parallel)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = (m, n, k, a, a_row, b, b_row, b_col, c, accumulate, parallel);
        unreachable!("learn::kernels::sgemm runs only on x86_64 (runs() is false elsewhere)");
    }
}

/// [`matmul`] over slices, checked: an error if the CPU lacks AVX2 + FMA or a slice is too short
/// for the shape and strides (for tests and benchmarks).
#[allow(clippy::too_many_arguments)]
pub fn matmul_slices(m: usize, n: usize, k: usize, a: &[f32], a_row: usize, b: &[f32], b_row: usize, b_col: usize, c: &mut [f32], accumulate: bool, parallel: bool) -> Result<(), String> {
    if crate::learn::kernels::isa::detected_isa() < Isa::Avx2 {
        return Err("this CPU has no AVX2 + FMA".into());
    }
    let last = |rows: usize, cols: usize, rs: usize, cs: usize| if rows == 0 || cols == 0 { 0 } else { (rows - 1) * rs + (cols - 1) * cs + 1 };
    if a.len() < last(m, k, a_row, 1) || b.len() < last(k, n, b_row, b_col) || c.len() < m * n {
        return Err(format!("slices too short for [{m}, {k}] · [{k}, {n}] with the strides given"));
    }
    // SAFETY: AVX2 + FMA checked above; every element the strides name lies inside the slices; c is
    // a distinct mutable slice
    unsafe { matmul(m, n, k, a.as_ptr(), a_row, b.as_ptr(), b_row as isize, b_col as isize, c.as_mut_ptr(), accumulate, parallel) };
    Ok(())
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::{KC, MC, MR, NR, PACKED_B_FLOATS};
    use rayon::prelude::*;
    use std::arch::x86_64::*;

    /// C[R×16] (+)= A[R×kc] · B[kc×16]: A(r, p) at `a + r·a_row + p`, B packed (B(p, 0..16) at
    /// `b + 16p`), C(r, 0..16) at `c + r·c_row`.
    #[inline(always)]
    unsafe fn tile<const R: usize>(kc: usize, a: *const f32, a_row: usize, b: *const f32, c: *mut f32, c_row: usize, accumulate: bool) {
        // SAFETY (whole body): the caller guarantees AVX2 + FMA and the extents above
        unsafe {
            let mut acc = [[_mm256_setzero_ps(); 2]; R]; // [R][2] × 8 lanes: the tile
            let (mut ap, mut bp) = (a, b);
            for _ in 0..kc {
                let b0 = _mm256_loadu_ps(bp); // B(p, 0..8)
                let b1 = _mm256_loadu_ps(bp.add(8)); // B(p, 8..16)
                for (r, row) in acc.iter_mut().enumerate() {
                    let av = _mm256_broadcast_ss(&*ap.add(r * a_row)); // A(r, p) in every lane
                    row[0] = _mm256_fmadd_ps(av, b0, row[0]); // C(r, 0..8) += A(r, p) B(p, 0..8)
                    row[1] = _mm256_fmadd_ps(av, b1, row[1]);
                }
                ap = ap.add(1);
                bp = bp.add(NR);
            }
            for (r, row) in acc.iter().enumerate() {
                let cp = c.add(r * c_row);
                if accumulate {
                    _mm256_storeu_ps(cp, _mm256_add_ps(_mm256_loadu_ps(cp), row[0]));
                    _mm256_storeu_ps(cp.add(8), _mm256_add_ps(_mm256_loadu_ps(cp.add(8)), row[1]));
                } else {
                    _mm256_storeu_ps(cp, row[0]);
                    _mm256_storeu_ps(cp.add(8), row[1]);
                }
            }
        }
    }

    /// [`tile`] for the 1–6 rows left at a block's end.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    unsafe fn tile_rows(rows: usize, kc: usize, a: *const f32, a_row: usize, b: *const f32, c: *mut f32, c_row: usize, accumulate: bool) {
        // SAFETY: forwarded
        unsafe {
            match rows {
                6 => tile::<6>(kc, a, a_row, b, c, c_row, accumulate),
                5 => tile::<5>(kc, a, a_row, b, c, c_row, accumulate),
                4 => tile::<4>(kc, a, a_row, b, c, c_row, accumulate),
                3 => tile::<3>(kc, a, a_row, b, c, c_row, accumulate),
                2 => tile::<2>(kc, a, a_row, b, c, c_row, accumulate),
                1 => tile::<1>(kc, a, a_row, b, c, c_row, accumulate),
                _ => unreachable!("a tile has 1 to {MR} rows"),
            }
        }
    }

    /// The operands of one call, as addresses (shared by the rayon tasks; each task writes only
    /// its own rows of C).
    #[derive(Clone, Copy)]
    struct Operands {
        m: usize,
        n: usize,
        a: usize,
        a_row: usize,
        c: usize,
        panels: usize,
    }

    /// Rows `i0 .. i0 + MC` of C over the depth slab `[p0, p0 + depth)` whose packed B is `packed`:
    /// for each depth block of KC, each B panel, each tile of 6 rows.
    #[target_feature(enable = "avx2,fma")]
    unsafe fn row_block(o: Operands, i0: usize, p0: usize, depth: usize, packed: &[f32], accumulate: bool) {
        let mc = MC.min(o.m - i0);
        let (a, c) = (o.a as *const f32, o.c as *mut f32);
        let mut edge = [0f32; MR * NR]; // a tile of the last, partial panel
        let mut kb = 0;
        while kb < depth {
            let kc = KC.min(depth - kb);
            let acc = accumulate || kb > 0; // later blocks add onto what the first wrote
            let slab = &packed[kb * o.panels * NR..(kb + kc) * o.panels * NR]; // [panels][kc][16]
            for jp in 0..o.panels {
                let j0 = jp * NR;
                let w = NR.min(o.n - j0);
                let bp = slab[jp * kc * NR..].as_ptr();
                let mut ir = 0;
                while ir < mc {
                    let rows = MR.min(mc - ir);
                    let i = i0 + ir;
                    // SAFETY: rows i..i+rows < m and columns p0+kb..+kc < k of A; the panel holds kc × 16
                    unsafe {
                        let ap = a.add(i * o.a_row + p0 + kb);
                        if w == NR {
                            tile_rows(rows, kc, ap, o.a_row, bp, c.add(i * o.n + j0), o.n, acc);
                        } else {
                            tile_rows(rows, kc, ap, o.a_row, bp, edge.as_mut_ptr(), NR, false);
                            for r in 0..rows {
                                let dst = c.add((i + r) * o.n + j0);
                                for (j, v) in edge[r * NR..r * NR + w].iter().enumerate() {
                                    *dst.add(j) = if acc { *dst.add(j) + v } else { *v };
                                }
                            }
                        }
                    }
                    ir += MR;
                }
            }
            kb += kc;
        }
    }

    #[allow(clippy::too_many_arguments)]
    pub unsafe fn matmul(m: usize, n: usize, k: usize, a: *const f32, a_row: usize, b: *const f32, b_row: isize, b_col: isize, c: *mut f32, accumulate: bool, parallel: bool) {
        if m == 0 || n == 0 {
            return;
        }
        if k == 0 {
            if !accumulate {
                // SAFETY: C holds m·n floats
                unsafe { std::ptr::write_bytes(c, 0, m * n) };
            }
            return;
        }
        let panels = n.div_ceil(NR);
        // depth of a slab: as much of B as PACKED_B_FLOATS holds, whole KC blocks, at least one
        let slab_depth = (PACKED_B_FLOATS / (panels * NR)).max(KC) / KC * KC;
        let mut packed = vec![0f32; slab_depth.min(k) * panels * NR];
        let o = Operands { m, n, a: a as usize, a_row, c: c as usize, panels };
        let mut p0 = 0;
        while p0 < k {
            let depth = slab_depth.min(k - p0);
            // pack B[p0 .. p0 + depth, :] as [KC blocks][panels][kc][16], zero-padded
            let mut kb = 0;
            while kb < depth {
                let kc = KC.min(depth - kb);
                let slab = &mut packed[kb * panels * NR..(kb + kc) * panels * NR];
                for (jp, panel) in slab.chunks_exact_mut(kc * NR).enumerate() {
                    let j0 = jp * NR;
                    let w = NR.min(n - j0);
                    for (p, dst) in panel.chunks_exact_mut(NR).enumerate() {
                        // SAFETY: B(p0 + kb + p, j0 + j) for j < w lies in B's storage
                        let src = unsafe { b.offset((p0 + kb + p) as isize * b_row + j0 as isize * b_col) };
                        for (j, d) in dst.iter_mut().enumerate() {
                            *d = if j < w { unsafe { *src.offset(j as isize * b_col) } } else { 0.0 };
                        }
                    }
                }
                kb += kc;
            }
            let acc = accumulate || p0 > 0;
            let blocks = m.div_ceil(MC);
            let packed = &packed[..depth * panels * NR];
            // SAFETY: the caller guarantees AVX2 + FMA and the extents; tasks write disjoint rows
            let run = |blk: usize| unsafe { row_block(o, blk * MC, p0, depth, packed, acc) };
            if parallel {
                (0..blocks).into_par_iter().for_each(run);
            } else {
                (0..blocks).for_each(run);
            }
            p0 += depth;
        }
    }
}
