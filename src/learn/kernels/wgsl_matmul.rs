//! The GPU learner's matrix product of our own: `shaders/matmul.wgsl`, a tiled product with the
//! operands staged in workgroup memory, the `dextrain_tiled*` routines of `learn::kernels::gpu_matmul`.
//!
//! cubek's routines on WGSL adapters are unit routines (one thread per output tile, operands read
//! from global memory); its shared-memory routines need cooperative matrices. This kernel stages
//! the operands in workgroup memory as a plain WGSL kernel can, each thread accumulating a
//! TM × TN block in registers. The shader is a template: [`shader_source`] writes the tile shape
//! in and unrolls the per-thread accumulation (one named register per accumulator; an indexed
//! array could be left in slow per-thread memory by the driver's compiler).
//!
//! A product with few output tiles and a long k (a weight gradient over a batch's rows) is split
//! over k inside the kernel and its partials summed ([`plan`]); a dense layer's bias, and a hidden
//! layer's ELU, are applied as the product is written ([`Epilogue`], `affine.rs`). Measured on an
//! H200 against cubek's routines: BENCHMARKS.md, "dextrain's own matrix product on the H200".
//!
//! It is launched as a hand-written kernel of cubecl (`learn::kernels::wgsl_kernel`): on burn's own
//! command stream, between burn's kernels, with no flush or submission of ours, the launch's
//! constants ([`MatmulCfg`]) in the uniform cubecl binds after the buffers (and caches per value).

use anyhow::{Result, anyhow, ensure};
use burn::backend::Cube;
use burn::backend::tensor::FloatTensor;
use burn::backend::ops::FloatTensorOps;
use burn::tensor::{DType, FloatDType, Shape};
use burn_cubecl::kernel::matmul::init_matmul_output;

use crate::learn::kernels::wgsl_kernel::{WgslKernel, launch};

/// The template (`$NAME` markers filled in by [`shader_source`]).
const TEMPLATE: &str = include_str!("../../../shaders/matmul.wgsl");

/// The shader's entry point.
pub const ENTRY_POINT: &str = "matmul_tiled";

/// Threads per workgroup, every tile shape.
const THREADS: usize = 256;

/// Workgroups a product must fill before [`Tile::LARGE`] is taken over [`Tile::SMALL`]
/// ([`Tile::for_product`]): two per multiprocessor of an H100/H200 (132), so that larger tiles do
/// not leave most of the GPU idle on a product with few of them.
pub const LARGE_TILE_MIN_GROUPS: usize = 264;

/// Workgroups a product with few tiles of C is split over k to fill (four per multiprocessor of an
/// H100/H200): the weight gradients `xᵀ g` of the learner, [in, out] summed over a batch's rows.
pub const SPLIT_TARGET_GROUPS: usize = 528;

/// The least k per split of a product split over k.
pub const MIN_K_PER_SPLIT: usize = 256;

/// A tile shape of the kernel: what a workgroup and each of its threads compute.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Tile {
    /// C rows per workgroup (BM).
    pub rows: usize,
    /// C columns per workgroup (BN).
    pub cols: usize,
    /// k per slice staged in workgroup memory (BK).
    pub depth: usize,
    /// C rows per thread (TM, a multiple of 4).
    pub thread_rows: usize,
    /// C columns per thread (TN, a multiple of 4).
    pub thread_cols: usize,
}

impl Tile {
    /// 64 × 64 per workgroup, 4 × 4 per thread, 16 deep.
    pub const SMALL: Tile = Tile { rows: 64, cols: 64, depth: 16, thread_rows: 4, thread_cols: 4 };
    /// 128 × 128 per workgroup, 8 × 8 per thread, 8 deep.
    pub const LARGE: Tile = Tile { rows: 128, cols: 128, depth: 8, thread_rows: 8, thread_cols: 8 };
    /// 128 × 64 per workgroup, 8 × 4 per thread, 16 deep.
    pub const TALL: Tile = Tile { rows: 128, cols: 64, depth: 16, thread_rows: 8, thread_cols: 4 };
    /// 64 × 128 per workgroup, 4 × 8 per thread, 16 deep.
    pub const WIDE: Tile = Tile { rows: 64, cols: 128, depth: 16, thread_rows: 4, thread_cols: 8 };
    /// 128 × 128 per workgroup, 8 × 8 per thread, 16 deep (half the barriers of [`Tile::LARGE`]).
    pub const LARGE_DEEP: Tile = Tile { rows: 128, cols: 128, depth: 16, thread_rows: 8, thread_cols: 8 };
    /// 128 × 256 per workgroup, 8 × 16 per thread, 8 deep.
    pub const HUGE_WIDE: Tile = Tile { rows: 128, cols: 256, depth: 8, thread_rows: 8, thread_cols: 16 };
    /// 256 × 128 per workgroup, 16 × 8 per thread, 8 deep.
    pub const HUGE_TALL: Tile = Tile { rows: 256, cols: 128, depth: 8, thread_rows: 16, thread_cols: 8 };
    /// 256 × 16 per workgroup, 4 × 4 per thread, 16 deep: a product with few columns (a policy's
    /// actions, a critic's value) without a 64-wide tile's idle columns.
    pub const NARROW: Tile = Tile { rows: 256, cols: 16, depth: 16, thread_rows: 4, thread_cols: 4 };
    /// The shapes the shape rule uses ([`Tile::for_product`], [`plan`]).
    pub const ALL: [Tile; 3] = [Tile::SMALL, Tile::LARGE, Tile::TALL];
    /// The shapes [`TileChoice::Tuned`] times: every shape the template is written for.
    pub const CANDIDATES: [Tile; 8] =
        [Tile::SMALL, Tile::LARGE, Tile::TALL, Tile::WIDE, Tile::LARGE_DEEP, Tile::HUGE_WIDE, Tile::HUGE_TALL, Tile::NARROW];

    /// The shape's name in reports: `BMxBNxBK/TMxTN`.
    pub fn label(self) -> String {
        format!("{}x{}x{}/{}x{}", self.rows, self.cols, self.depth, self.thread_rows, self.thread_cols)
    }

    /// Threads along C's columns (TX) and rows (TY).
    fn threads(self) -> (usize, usize) {
        (self.cols / self.thread_cols, self.rows / self.thread_rows)
    }

    /// Workgroups for an m × n product of `batches` batches.
    pub fn groups(self, m: usize, n: usize, batches: usize) -> [usize; 3] {
        [n.div_ceil(self.cols), m.div_ceil(self.rows), batches]
    }

    /// The shape for an m × n product of `batches` batches: [`Tile::LARGE`] where it still fills
    /// [`LARGE_TILE_MIN_GROUPS`] workgroups, [`Tile::TALL`] where that does, else [`Tile::SMALL`].
    pub fn for_product(m: usize, n: usize, batches: usize) -> Tile {
        let fills = |t: Tile| t.groups(m, n, batches).iter().product::<usize>() >= LARGE_TILE_MIN_GROUPS;
        [Tile::LARGE, Tile::TALL].into_iter().find(|t| fills(*t)).unwrap_or(Tile::SMALL)
    }

    /// The shape for a product split over k (the splits fill the GPU, so the tile is the one
    /// that does the most work per value staged): 128 × 128 where C has 128 rows and columns,
    /// 128 × 64 where it has 128 rows, else 64 × 64.
    pub fn for_split(m: usize, n: usize) -> Tile {
        match (m >= 128, n >= 128) {
            (true, true) => Tile::LARGE,
            (true, false) => Tile::TALL,
            _ => Tile::SMALL,
        }
    }
}

/// How an m × n × k product of `batches` batches is launched: the tile shape (`forced`, or chosen
/// from the shape) and (splits, k per split). A single product whose tiles leave the GPU mostly
/// idle and whose k is long is split over k into about [`SPLIT_TARGET_GROUPS`] workgroups, at
/// least [`MIN_K_PER_SPLIT`] k each, each k per split a multiple of the tile's depth, with
/// [`Tile::for_split`]'s tile where those splits fill the GPU, else [`Tile::SMALL`]. The choice
/// depends on the shapes alone, so a run's products are the same kernels every time.
pub fn plan(m: usize, n: usize, k: usize, batches: usize, forced: Option<Tile>) -> (Tile, usize, usize) {
    let unsplit = forced.unwrap_or_else(|| Tile::for_product(m, n, batches));
    let groups = |t: Tile| t.groups(m, n, 1).iter().product::<usize>();
    if batches != 1 || k < 2 * MIN_K_PER_SPLIT || groups(unsplit) * batches >= SPLIT_TARGET_GROUPS {
        return (unsplit, 1, k.max(1));
    }
    // the larger tile where the splits its k allows still fill the GPU (a 24,576-row weight
    // gradient), else 64 × 64 (a 4,096-row one: measured faster on an H200)
    let most_splits = k / MIN_K_PER_SPLIT;
    let tile = forced.unwrap_or_else(|| {
        let larger = Tile::for_split(m, n);
        if groups(larger) * most_splits >= SPLIT_TARGET_GROUPS { larger } else { Tile::SMALL }
    });
    let wanted = SPLIT_TARGET_GROUPS.div_ceil(groups(tile)).min(k / MIN_K_PER_SPLIT).max(1);
    let chunk = k.div_ceil(wanted).next_multiple_of(tile.depth); // k per split
    (tile, k.div_ceil(chunk), chunk)
}

/// `MatmulCfg` of matmul.wgsl (keep in sync): sizes and strides in f32 elements.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct MatmulCfg {
    pub m: u32,
    pub n: u32,
    pub k: u32,
    pub batches: u32,
    pub a_row: u32,
    pub a_col: u32,
    pub a_batch: u32,
    pub b_row: u32,
    pub b_col: u32,
    pub b_batch: u32,
    pub c_batch: u32,
    pub k_splits: u32,
    pub k_chunk: u32,
    pub epilogue: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}

/// matmul.wgsl for `tile`: the template with the shape's numbers and the unrolled accumulation.
pub fn shader_source(tile: Tile) -> String {
    let Tile { rows, cols, depth, thread_rows, thread_cols } = tile;
    let (tx, ty) = tile.threads();
    assert!(
        thread_rows % 4 == 0 && thread_cols % 4 == 0 && tx * ty == THREADS && (depth * rows) % THREADS == 0 && (depth * cols) % THREADS == 0,
        "matmul.wgsl: tile {tile:?} does not give 256 threads whole vec4s and whole loads"
    );
    let (row_groups, col_groups) = (thread_rows / 4, thread_cols / 4);
    let lane = ["x", "y", "z", "w"];
    let mut decl = String::new();
    let mut fma = String::new();
    let mut store = String::new();
    // accumulator c{row}_{h}: this thread's row `row` (group row/4, lane row%4) at its column group h
    for row in 0..thread_rows {
        for h in 0..col_groups {
            decl += &format!("    var c{row}_{h} = vec4<f32>(0.0);\n");
        }
    }
    for g in 0..row_groups {
        fma += &format!("            let a{g} = mm_sa[d * (BM / 4u) + {g}u * TY + ty]; // rows ({g}·TY + ty)·4 .. +4 at k0 + d\n");
    }
    for h in 0..col_groups {
        fma += &format!("            let b{h} = mm_sb[d * (BN / 4u) + {h}u * TX + tx]; // columns ({h}·TX + tx)·4 .. +4\n");
    }
    for row in 0..thread_rows {
        let (g, i) = (row / 4, row % 4);
        for h in 0..col_groups {
            fma += &format!("            c{row}_{h} = fma(vec4<f32>(a{g}.{}), b{h}, c{row}_{h});\n", lane[i]);
        }
    }
    for row in 0..thread_rows {
        let (g, i) = (row / 4, row % 4);
        store += &format!("    r = row0 + ({g}u * TY + ty) * 4u + {i}u;\n    if r < mc.m {{\n");
        for h in 0..col_groups {
            store += &format!("        c = col0 + ({h}u * TX + tx) * 4u;\n");
            for (j, l) in lane.iter().enumerate() {
                store += &format!("        if c + {j}u < mc.n {{ mm_c[c_base + r * mc.n + c + {j}u] = finish(c{row}_{h}.{l}, c + {j}u); }}\n");
            }
        }
        store += "    }\n";
    }
    let number = |v: usize| v.to_string();
    TEMPLATE
        .replace("$ACC_DECL", decl.trim_end())
        .replace("$ACC_FMA", fma.trim_end())
        .replace("$ACC_STORE", store.trim_end())
        .replace("$BM", &number(rows))
        .replace("$BN", &number(cols))
        .replace("$BK", &number(depth))
        .replace("$TX", &number(tx))
        .replace("$TY", &number(ty))
        .replace("$THREADS", &number(THREADS))
        .replace("$A_LOADS", &number(depth * rows / THREADS))
        .replace("$B_LOADS", &number(depth * cols / THREADS))
        .replace("$SA_LEN", &number(depth * rows / 4))
        .replace("$SB_LEN", &number(depth * cols / 4))
}

/// What the kernel does to C's entries after the product (matmul.wgsl's `epilogue`).
#[derive(Clone, Copy, Debug)]
pub enum Epilogue<'a> {
    /// C = A · B.
    None,
    /// C = A · B + b for a bias b [1, N] (a dense layer).
    Bias(&'a FloatTensor<Cube>),
    /// C = ELU(A · B + b), α = 1 (a hidden layer with its activation).
    BiasElu(&'a FloatTensor<Cube>),
}

impl<'a> Epilogue<'a> {
    /// The bias it adds, if any.
    fn bias(self) -> Option<&'a FloatTensor<Cube>> {
        match self {
            Epilogue::None => None,
            Epilogue::Bias(b) | Epilogue::BiasElu(b) => Some(b),
        }
    }

    /// matmul.wgsl's code for it.
    fn code(self) -> u32 {
        match self {
            Epilogue::None => 0,
            Epilogue::Bias(_) => 1,
            Epilogue::BiasElu(_) => 2,
        }
    }
}

/// (rows, columns) of the operand as multiplied, its (row, column, batch) strides and its batch
/// count, for a rank-2 or rank-3 operand; a batch of one is broadcast (stride 0).
fn strides_of(t: &FloatTensor<Cube>) -> Result<([usize; 2], [usize; 3], usize)> {
    let shape = t.meta.shape().to_vec();
    let strides = t.meta.strides().to_vec();
    match shape.len() {
        2 => Ok(([shape[0], shape[1]], [strides[0], strides[1], 0], 1)),
        3 => Ok(([shape[1], shape[2]], [strides[1], strides[2], if shape[0] == 1 { 0 } else { strides[0] }], shape[0])),
        r => Err(anyhow!("matmul.wgsl takes rank-2 or rank-3 operands, not rank {r}")),
    }
}

/// Which tile shape a product runs with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TileChoice {
    /// Chosen from the product's shape ([`Tile::for_product`], [`plan`]).
    ByShape,
    /// This shape for every product, its splits over k planned for it ([`plan`]).
    Fixed(Tile),
    /// The fastest of [`Tile::CANDIDATES`] on this adapter, timed at the first product of each
    /// shape, strides and epilogue in the process and remembered for the rest of it. The splits
    /// over k are [`TileChoice::ByShape`]'s, and every shape sums each entry's k in the same order,
    /// so the results are [`TileChoice::ByShape`]'s bit for bit whichever shape wins: a run and its
    /// resume agree although each times the shapes anew.
    Tuned,
}

/// A product planned for the kernel: its launch constants, tile rule and splits over k.
struct Planned {
    m: usize,
    n: usize,
    batches: usize,
    /// The shape the rule picks ([`TileChoice::ByShape`], or the fixed one).
    rule_tile: Tile,
    /// Splits over k (1: none).
    splits: usize,
    cfg: MatmulCfg,
}

impl Planned {
    /// The plan of `lhs · rhs` with `epilogue` (unsplit with one), with `forced` as the tile where
    /// fixed; an error where the operands do not fit the kernel.
    fn new(lhs: &FloatTensor<Cube>, rhs: &FloatTensor<Cube>, forced: Option<Tile>, epilogue: Epilogue<'_>) -> Result<Planned> {
        ensure!(lhs.dtype == DType::F32 && rhs.dtype == DType::F32, "matmul.wgsl multiplies f32 tensors");
        let (([m, k], [a_row, a_col, a_batch], a_batches), ([k2, n], [b_row, b_col, b_batch], b_batches)) = (strides_of(lhs)?, strides_of(rhs)?);
        ensure!(k == k2 && (a_batches == b_batches || a_batches == 1 || b_batches == 1), "matmul.wgsl: shapes do not multiply");
        let batches = a_batches.max(b_batches);
        if let Some(b) = epilogue.bias() {
            let (shape, strides) = (b.meta.shape().to_vec(), b.meta.strides().to_vec());
            let columns_ok = shape.last() == Some(&n) && strides.last() == Some(&1) && shape.iter().rev().skip(1).all(|&d| d == 1);
            ensure!(b.dtype == DType::F32 && columns_ok && batches == 1, "matmul.wgsl: a bias of shape {shape:?} for {n} columns");
        }
        // with an epilogue, unsplit (it applies to the sums)
        let (rule_tile, splits, k_chunk) = if epilogue.bias().is_some() {
            (forced.unwrap_or_else(|| Tile::for_product(m, n, batches)), 1, k.max(1))
        } else {
            plan(m, n, k, batches, forced)
        };
        let fits = |v: usize| u32::try_from(v).map_err(|_| anyhow!("matmul.wgsl: {v} does not fit 32 bits"));
        // every index the kernel forms stays under 2^32
        fits(a_batch * batches + a_row * m + a_col * k)?;
        fits(b_batch * batches + b_row * k + b_col * n)?;
        fits(m * n * batches * splits)?;
        ensure!(m * n > 0 && k > 0, "matmul.wgsl: an empty product");
        let cfg = MatmulCfg {
            m: fits(m)?,
            n: fits(n)?,
            k: fits(k)?,
            batches: fits(batches)?,
            a_row: fits(a_row)?,
            a_col: fits(a_col)?,
            a_batch: fits(a_batch)?,
            b_row: fits(b_row)?,
            b_col: fits(b_col)?,
            b_batch: fits(b_batch)?,
            c_batch: fits(m * n)?,
            k_splits: fits(splits)?,
            k_chunk: fits(k_chunk)?,
            epilogue: epilogue.code(),
            _pad1: 0,
            _pad2: 0,
        };
        let planned = Planned { m, n, batches, rule_tile, splits, cfg };
        ensure!(planned.grid(rule_tile).is_some(), "matmul.wgsl: too many workgroups for {m} × {n} × {batches}");
        Ok(planned)
    }

    /// Workgroups with `tile`, None past the 65,535 per dimension a dispatch takes.
    fn grid(&self, tile: Tile) -> Option<[u32; 3]> {
        let [gx, gy, gz] = tile.groups(self.m, self.n, self.batches * self.splits);
        (gx <= 65_535 && gy <= 65_535 && gz <= 65_535).then_some([gx as u32, gy as u32, gz as u32])
    }

    /// The output the kernel writes whole: [(S,) M, N], or the partials [splits, M, N].
    fn output(&self, lhs: &FloatTensor<Cube>, rhs: &FloatTensor<Cube>) -> FloatTensor<Cube> {
        if self.splits == 1 {
            init_matmul_output(lhs, rhs, DType::F32)
        } else {
            Cube::float_empty(Shape::new([self.splits, self.m, self.n]), &lhs.device, FloatDType::F32)
        }
    }

    /// Launches the kernel in `tile` into `out` (a tile [`Planned::grid`] takes).
    fn launch(&self, tile: Tile, lhs: &FloatTensor<Cube>, rhs: &FloatTensor<Cube>, out: &FloatTensor<Cube>, epilogue: Epilogue<'_>) {
        let groups = self.grid(tile).expect("a tile whose grid fits");
        let (tx, ty) = tile.threads();
        let kernel = WgslKernel { name: "dextrain_matmul", key: tile, source: shader_source, entry_point: ENTRY_POINT, workgroup: [tx as u32, ty as u32] };
        // (counted by gpu_counts' launch observer as `dextrain:matmul`)
        let constants: &[u32] = bytemuck::cast_slice(std::slice::from_ref(&self.cfg));
        launch(kernel, groups, &[lhs, rhs, out, epilogue.bias().unwrap_or(lhs)], constants); // (the bias is read only with an epilogue)
    }

    /// The product from the kernel's output: the partials summed where split.
    fn finish(&self, out: FloatTensor<Cube>) -> FloatTensor<Cube> {
        if self.splits == 1 {
            return out;
        }
        Cube::float_reshape(Cube::float_sum_dim(out, 0), Shape::new([self.m, self.n])) // Σ_s partial_s: [M, N]
    }
}

/// `lhs · rhs` for f32 lhs [(S,) M, K], rhs [(S,) K, N] (any strides) with matmul.wgsl in the
/// tile `choice` gives → [(S,) M, N] row-major; an error where the operands do not fit it (the
/// caller falls back to another routine). A product split over k ([`plan`]) writes its partial
/// sums [splits, M, N] and sums them with burn's `sum_dim` (a fixed order).
pub fn matmul(lhs: &FloatTensor<Cube>, rhs: &FloatTensor<Cube>, choice: TileChoice) -> Result<FloatTensor<Cube>> {
    matmul_then(lhs, rhs, choice, Epilogue::None)
}

/// [`matmul`] with an epilogue on C's entries (the product is not split over k then): a dense
/// layer `x W + b`, or with its ELU, in one kernel. The bias must be f32 [1, N] or [N] with
/// contiguous columns.
pub fn matmul_then(lhs: &FloatTensor<Cube>, rhs: &FloatTensor<Cube>, choice: TileChoice, epilogue: Epilogue<'_>) -> Result<FloatTensor<Cube>> {
    let forced = match choice {
        TileChoice::Fixed(t) => Some(t),
        TileChoice::ByShape | TileChoice::Tuned => None,
    };
    let planned = Planned::new(lhs, rhs, forced, epilogue)?;
    let out = planned.output(lhs, rhs);
    let tile = match choice {
        TileChoice::Tuned => crate::learn::kernels::matmul_tuning::tuned_tile(&planned_key(&planned), planned.rule_tile, |tile| {
            planned.grid(tile).is_some().then(|| planned.launch(tile, lhs, rhs, &out, epilogue))
        }, || {
            let _ = burn_cubecl::cubecl::future::block_on(lhs.client.sync()); // (a failure surfaces at the next read)
        }),
        TileChoice::ByShape | TileChoice::Fixed(_) => planned.rule_tile,
    };
    planned.launch(tile, lhs, rhs, &out, epilogue);
    Ok(planned.finish(out))
}

/// `lhs · rhs` (with `epilogue`) planned by shape ([`TileChoice::ByShape`]'s splits over k) but
/// run in `tile`: what [`TileChoice::Tuned`] times for each candidate (a test compares them).
pub fn matmul_as_planned_in(lhs: &FloatTensor<Cube>, rhs: &FloatTensor<Cube>, tile: Tile, epilogue: Epilogue<'_>) -> Result<FloatTensor<Cube>> {
    let planned = Planned::new(lhs, rhs, None, epilogue)?;
    ensure!(planned.grid(tile).is_some(), "matmul.wgsl: too many workgroups in {tile:?}");
    let out = planned.output(lhs, rhs);
    planned.launch(tile, lhs, rhs, &out, epilogue);
    Ok(planned.finish(out))
}

/// What identifies a product for the tuner: its sizes, strides, splits and epilogue (the launch
/// constants).
fn planned_key(p: &Planned) -> crate::learn::kernels::matmul_tuning::ShapeKey {
    let c = &p.cfg;
    crate::learn::kernels::matmul_tuning::ShapeKey {
        sizes: [c.m, c.n, c.k, c.batches],
        a_strides: [c.a_row, c.a_col, c.a_batch],
        b_strides: [c.b_row, c.b_col, c.b_batch],
        splits: c.k_splits,
        epilogue: c.epilogue,
    }
}
