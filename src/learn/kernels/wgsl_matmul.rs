//! The GPU learner's matrix product of our own: `shaders/matmul.wgsl`, a tiled product with the
//! operands staged in workgroup memory, the `dextrain_tiled*` and `dextrain_tuned*` routines of
//! `learn::kernels::gpu_matmul`.
//!
//! cubek's routines on WGSL adapters are unit routines (one thread per output tile, operands read
//! from global memory); its shared-memory routines need cooperative matrices. This kernel stages
//! the operands in workgroup memory as a plain WGSL kernel can, each thread accumulating a
//! TM × TN block in registers. The shader is a template: [`shader_source`] writes the tile shape
//! in, unrolls the per-thread accumulation (one named register per accumulator; an indexed
//! array could be left in slow per-thread memory by the driver's compiler) and writes how each
//! operand is read ([`Variant`]: one f32 at a time with any strides, or vec4s along its contiguous
//! dimension). Every variant sums an entry's k in the same order, so [`TileChoice::Tuned`] may run
//! whichever `matmul_tuning.rs` times fastest and still give the shape rule's bits.
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

/// How the kernel reads one operand from memory (matmul.wgsl's LOAD blocks).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Loads {
    /// One f32 at a time, with any strides.
    Scalar,
    /// A vec4 of four consecutive k (A: a row-major operand, k contiguous in a row; B: a
    /// transposed view, k contiguous in a column).
    Vec4AlongK,
    /// A vec4 of four consecutive rows of A, or columns of B, at one k (A: a transposed view; B:
    /// a row-major operand).
    Vec4Across,
}

impl Loads {
    /// Its tag in a variant's label.
    fn tag(self) -> &'static str {
        match self {
            Loads::Scalar => "1",
            Loads::Vec4AlongK => "4k",
            Loads::Vec4Across => "4x",
        }
    }
}

/// A compiled form of the kernel: the tile shape and how A and B are read. Every variant sums
/// each entry's k in the same order, so all give the same bits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Variant {
    /// The tile shape.
    pub tile: Tile,
    /// How A is read.
    pub a: Loads,
    /// How B is read.
    pub b: Loads,
}

impl Variant {
    /// The tile shape with scalar reads (the kernel as the shape rule runs it).
    pub fn scalar(tile: Tile) -> Variant {
        Variant { tile, a: Loads::Scalar, b: Loads::Scalar }
    }

    /// Its name in reports: the tile's label, then `A/B` reads (`1`: scalar, `4k` / `4x`: vec4
    /// along k / across rows or columns) where not both scalar.
    pub fn label(self) -> String {
        match (self.a, self.b) {
            (Loads::Scalar, Loads::Scalar) => self.tile.label(),
            (a, b) => format!("{} {}/{}", self.tile.label(), a.tag(), b.tag()),
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
    /// A's row of ones (its last; C's row there goes to the bias binding), or [`NO_ONES_ROW`].
    pub ones_row: u32,
    pub _pad2: u32,
}

/// `MatmulCfg::ones_row` of a product without one.
pub const NO_ONES_ROW: u32 = u32::MAX;

/// matmul.wgsl for `variant`: the template with the shape's numbers, the unrolled accumulation and
/// the operands' reads.
pub fn shader_source(variant: Variant) -> String {
    let tile = variant.tile;
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
                store += &format!("        if c + {j}u < mc.n {{ put(c_base, wg.z, r, c + {j}u, c{row}_{h}.{l}); }}\n");
            }
        }
        store += "    }\n";
    }
    let loads = load_blocks(variant);
    let number = |v: usize| v.to_string();
    TEMPLATE
        .replace("$LOAD_FUNCS", loads.funcs.trim_end())
        .replace("$LOAD_REGS", loads.regs.trim_end())
        .replace("$LOAD_FIRST", loads.first.trim_end())
        .replace("$LOAD_STAGE", loads.stage.trim_end())
        .replace("$LOAD_NEXT", loads.next.trim_end())
        .replace("$A_ELEM", if variant.a == Loads::Scalar { "f32" } else { "vec4<f32>" })
        .replace("$B_ELEM", if variant.b == Loads::Scalar { "f32" } else { "vec4<f32>" })
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

/// The LOAD blocks of matmul.wgsl for a variant.
#[derive(Default)]
struct LoadBlocks {
    /// Functions the reads use.
    funcs: String,
    /// The registers that hold the next slice.
    regs: String,
    /// The first slice (at k_begin) into the registers.
    first: String,
    /// The registers into workgroup memory.
    stage: String,
    /// The next slice (at k1) into the registers.
    next: String,
}

/// Scalar reads of A: the tile position of each staged value, and the value (0 outside A).
const SCALAR_A_FUNCS: &str = include_str!("../../../shaders/matmul_read_a.wgsl");

/// Scalar reads of B, likewise.
const SCALAR_B_FUNCS: &str = include_str!("../../../shaders/matmul_read_b.wgsl");

/// matmul.wgsl's reads of A and B for `variant` (the operand's letter, its registers `ra`/`rb`,
/// its tile extent BM/BN, staged in `mm_sa`/`mm_sb` as [BK][extent / 4] vec4s).
fn load_blocks(variant: Variant) -> LoadBlocks {
    let mut out = LoadBlocks::default();
    for (op, loads, extent) in [('a', variant.a, variant.tile.rows), ('b', variant.b, variant.tile.cols)] {
        let (up, reg, smem, ext, limit) = if op == 'a' { ("A", "ra", "mm_sa", "BM", "mc.m") } else { ("B", "rb", "mm_sb", "BN", "mc.n") };
        let first_of = if op == 'a' { "row0" } else { "col0" };
        if loads == Loads::Scalar {
            out.funcs += if op == 'a' { SCALAR_A_FUNCS } else { SCALAR_B_FUNCS };
            out.funcs += "\n";
            let fast = if op == 'a' { "let a_rows_fast = mc.a_row == 1u && mc.a_col != 1u;" } else { "let b_cols_fast = mc.b_col == 1u || mc.b_row != 1u;" };
            let fast_name = if op == 'a' { "a_rows_fast" } else { "b_cols_fast" };
            out.regs += &format!("    {fast}\n    var {reg}: array<f32, {up}_LOADS>; // this thread's share of the next {up} slice\n");
            let fetch = |k0: &str, indent: &str| {
                format!("{indent}for (var s = 0u; s < {up}_LOADS; s++) {{\n{indent}    {reg}[s] = {op}_value({op}_slot(tid + s * THREADS, {fast_name}), {first_of}, {k0}, k_end, {op}_base);\n{indent}}}\n")
            };
            out.first += &fetch("k_begin", "    ");
            out.next += &fetch("k1", "            ");
            out.stage += &format!(
                "        for (var s = 0u; s < {up}_LOADS; s++) {{\n            let p = {op}_slot(tid + s * THREADS, {fast_name});\n            {smem}[p.y * ({ext} / 4u) + p.x / 4u][p.x % 4u] = {reg}[s];\n        }}\n"
            );
            continue;
        }
        let vecs = variant.tile.depth * extent / 4 / THREADS; // vec4s each thread reads per slice
        for q in 0..vecs {
            out.regs += &format!("    var {reg}{q} = vec4<f32>(0.0); // this thread's vec4 {q} of the next {up} slice\n");
        }
        // (tile position p, k offset d in the slice, global index of the vec4) per variant; the
        // operand's sizes and strides are multiples of 4 (`Planned::loads`), so a vec4 is wholly
        // inside the operand or wholly outside it
        let fetch = |k0: &str, indent: &str| {
            let mut f = String::new();
            for q in 0..vecs {
                f += &format!("{indent}{{\n{indent}    let e = tid + {q}u * THREADS;\n");
                match (op, loads) {
                    ('a', Loads::Vec4AlongK) => f += &format!("{indent}    let r = row0 + e / (BK / 4u);\n{indent}    let k = {k0} + (e % (BK / 4u)) * 4u;\n{indent}    let at = (a_base + r * mc.a_row + k) / 4u; // A[r, k .. k + 4]\n"),
                    ('a', _) => f += &format!("{indent}    let r = row0 + (e % (BM / 4u)) * 4u;\n{indent}    let k = {k0} + e / (BM / 4u);\n{indent}    let at = (a_base + r + k * mc.a_col) / 4u; // A[r .. r + 4, k]\n"),
                    (_, Loads::Vec4AlongK) => f += &format!("{indent}    let r = col0 + e / (BK / 4u);\n{indent}    let k = {k0} + (e % (BK / 4u)) * 4u;\n{indent}    let at = (b_base + k + r * mc.b_col) / 4u; // B[k .. k + 4, r]\n"),
                    _ => f += &format!("{indent}    let r = col0 + (e % (BN / 4u)) * 4u;\n{indent}    let k = {k0} + e / (BN / 4u);\n{indent}    let at = (b_base + k * mc.b_row + r) / 4u; // B[k, r .. r + 4]\n"),
                }
                // A's row of ones (a multiple of 4 where A is read as vec4s: `Planned::vector_variant`)
                // is a vec4 of ones: four k of the row, or the row and three past C's last
                let ones = if op == 'a' { format!("{indent}    if r == mc.ones_row && k < k_end {{\n{indent}        {reg}{q} = vec4<f32>(1.0);\n{indent}    }} else ") } else { format!("{indent}    ") };
                f += &format!("{ones}if r < {limit} && k < k_end {{\n{indent}        {reg}{q} = mm_{op}[at];\n{indent}    }} else {{\n{indent}        {reg}{q} = vec4<f32>(0.0);\n{indent}    }}\n{indent}}}\n");
            }
            f
        };
        out.first += &fetch("k_begin", "    ");
        out.next += &fetch("k1", "            ");
        for q in 0..vecs {
            if loads == Loads::Vec4Across {
                // [BK][extent / 4] vec4s in the order the threads read them
                out.stage += &format!("        {smem}[tid + {q}u * THREADS] = {reg}{q};\n");
            } else {
                out.stage += &format!(
                    "        {{\n            let e = tid + {q}u * THREADS;\n            let r = e / (BK / 4u); // the tile's row (A) or column (B)\n            let k = (e % (BK / 4u)) * 4u;\n"
                );
                for (j, lane) in ["x", "y", "z", "w"].iter().enumerate() {
                    out.stage += &format!("            {smem}[(k + {j}u) * ({ext} / 4u) + r / 4u][r % 4u] = {reg}{q}.{lane};\n");
                }
                out.stage += "        }\n";
            }
        }
    }
    out
}

/// What the kernel does besides the product (matmul.wgsl's `epilogue` on C's entries, or its row
/// of ones).
#[derive(Clone, Copy, Debug)]
pub enum Epilogue<'a> {
    /// C = A · B.
    None,
    /// C = A · B + b for a bias b [1, N] (a dense layer).
    Bias(&'a FloatTensor<Cube>),
    /// C = ELU(A · B + b), α = 1 (a hidden layer with its activation).
    BiasElu(&'a FloatTensor<Cube>),
    /// C = (A · B) · min(y + 1, 1) for y [M, N] contiguous: ELU's gradient (α = 1) through a
    /// layer's output y, applied to the input gradient g Wᵀ of the layer after it
    /// (elu_backward.wgsl's expression: the same bits as the product then that kernel).
    EluGrad(&'a FloatTensor<Cube>),
    /// C = A · B and, a second output, 1ᵀ B [1, N] (B's column sums): A read with a row of ones
    /// after its last, C's entries there written apart. A dense layer's weight and bias gradients,
    /// xᵀ g and 1ᵀ g, in one product ([`matmul_and_column_sums`]).
    ColumnSums,
}

impl<'a> Epilogue<'a> {
    /// The tensor it reads at the bias binding (a bias, or ELU's output), if any.
    fn operand(self) -> Option<&'a FloatTensor<Cube>> {
        match self {
            Epilogue::None | Epilogue::ColumnSums => None,
            Epilogue::Bias(b) | Epilogue::BiasElu(b) | Epilogue::EluGrad(b) => Some(b),
        }
    }

    /// matmul.wgsl's code for what it does to C's entries (0 for the row of ones: C's entries
    /// are the product's).
    pub fn code(self) -> u32 {
        match self {
            Epilogue::None | Epilogue::ColumnSums => 0,
            Epilogue::Bias(_) => 1,
            Epilogue::BiasElu(_) => 2,
            Epilogue::EluGrad(_) => 3,
        }
    }

    /// Whether A is read with a row of ones.
    pub fn ones_row(self) -> bool {
        matches!(self, Epilogue::ColumnSums)
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

/// Which form of the kernel a product runs with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TileChoice {
    /// The tile chosen from the product's shape ([`Tile::for_product`], [`plan`]), scalar reads.
    ByShape,
    /// This tile for every product, its splits over k planned for it ([`plan`]), scalar reads.
    Fixed(Tile),
    /// The fastest variant on this adapter — each of [`Tile::CANDIDATES`] with scalar reads and,
    /// with `vector_reads` where the operands allow, with vec4 reads — timed at the first product
    /// of each shape, strides and epilogue in the process and remembered for the rest of it. The
    /// splits over k are [`TileChoice::ByShape`]'s, and every variant sums each entry's k in the
    /// same order, so the results are [`TileChoice::ByShape`]'s bit for bit whichever wins: a run
    /// and its resume agree although each times the variants anew.
    Tuned {
        /// Whether vec4 reads are among the candidates.
        vector_reads: bool,
    },
}

/// A product planned for the kernel: its launch constants, tile rule and splits over k.
struct Planned {
    /// C's rows as the kernel counts them (A's rows, and its row of ones where it has one).
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
        match epilogue {
            Epilogue::Bias(b) | Epilogue::BiasElu(b) => {
                let (shape, strides) = (b.meta.shape().to_vec(), b.meta.strides().to_vec());
                let columns_ok = shape.last() == Some(&n) && strides.last() == Some(&1) && shape.iter().rev().skip(1).all(|&d| d == 1);
                ensure!(b.dtype == DType::F32 && columns_ok && batches == 1, "matmul.wgsl: a bias of shape {shape:?} for {n} columns");
            }
            Epilogue::EluGrad(y) => {
                let (shape, strides) = (y.meta.shape().to_vec(), y.meta.strides().to_vec());
                ensure!(y.dtype == DType::F32 && shape == [m, n] && strides == [n, 1] && batches == 1, "matmul.wgsl: ELU's output of shape {shape:?} (strides {strides:?}) for a [{m}, {n}] product");
            }
            Epilogue::ColumnSums => ensure!(batches == 1, "matmul.wgsl: column sums of a batched product"),
            Epilogue::None => {}
        }
        // A's rows as the kernel counts them: its row of ones after its last
        let (a_rows, m) = (m, m + usize::from(epilogue.ones_row()));
        // with an epilogue on C's entries, unsplit (it applies to the sums)
        let (rule_tile, splits, k_chunk) = if epilogue.code() != 0 {
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
            c_batch: fits(a_rows * n)?,
            k_splits: fits(splits)?,
            k_chunk: fits(k_chunk)?,
            epilogue: epilogue.code(),
            ones_row: if epilogue.ones_row() { fits(a_rows)? } else { NO_ONES_ROW },
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

    /// A's rows (C's, less the row of ones where A has one).
    fn a_rows(&self) -> usize {
        self.cfg.c_batch as usize / self.n
    }

    /// The outputs the kernel writes whole: C [(S,) M, N], or the partials [splits, M, N]; and
    /// with a row of ones its sums [splits, N].
    fn outputs(&self, lhs: &FloatTensor<Cube>, rhs: &FloatTensor<Cube>) -> (FloatTensor<Cube>, Option<FloatTensor<Cube>>) {
        let c = if self.splits == 1 {
            init_matmul_output(lhs, rhs, DType::F32)
        } else {
            Cube::float_empty(Shape::new([self.splits, self.a_rows(), self.n]), &lhs.device, FloatDType::F32)
        };
        let sums = (self.cfg.ones_row != NO_ONES_ROW).then(|| Cube::float_empty(Shape::new([self.splits, self.n]), &lhs.device, FloatDType::F32));
        (c, sums)
    }

    /// How `tile` may read A and B: as vec4s along the operand's contiguous dimension where its
    /// size there, its other strides and the k per split are multiples of 4 (so a vec4 is wholly
    /// inside the operand or wholly outside it, and aligned: cubecl binds every tensor at an
    /// aligned offset) and the tile's slice is a whole number of vec4s per thread; else scalar.
    fn vector_variant(&self, tile: Tile) -> Variant {
        let c = &self.cfg;
        let whole = |extent: usize| (tile.depth * extent / 4) % THREADS == 0 && tile.depth * extent >= 4 * THREADS;
        let four = |v: u32| v % 4 == 0;
        let a = if !whole(tile.rows) {
            Loads::Scalar
        } else if c.a_col == 1 && four(c.k) && four(c.k_chunk) && four(c.a_row) && four(c.a_batch) {
            Loads::Vec4AlongK
        } else if c.a_row == 1 && four(self.a_rows() as u32) && four(c.a_col) && four(c.a_batch) {
            Loads::Vec4Across
        } else {
            Loads::Scalar
        };
        let b = if !whole(tile.cols) {
            Loads::Scalar
        } else if c.b_col == 1 && four(c.n) && four(c.b_row) && four(c.b_batch) {
            Loads::Vec4Across
        } else if c.b_row == 1 && four(c.k) && four(c.k_chunk) && four(c.b_col) && four(c.b_batch) {
            Loads::Vec4AlongK
        } else {
            Loads::Scalar
        };
        Variant { tile, a, b }
    }

    /// The variants the tuner times: every candidate tile shape that takes the product, with
    /// scalar reads and, with `vector_reads` where the operands allow, with vec4 reads.
    fn candidates(&self, vector_reads: bool) -> Vec<Variant> {
        let mut out = Vec::new();
        for tile in Tile::CANDIDATES.into_iter().filter(|t| self.grid(*t).is_some()) {
            out.push(Variant::scalar(tile));
            let v = self.vector_variant(tile);
            if vector_reads && v != Variant::scalar(tile) {
                out.push(v);
            }
        }
        out
    }

    /// Launches the kernel as `variant` into `out` and, with a row of ones, `sums` (a tile
    /// [`Planned::grid`] takes).
    fn launch(&self, variant: Variant, lhs: &FloatTensor<Cube>, rhs: &FloatTensor<Cube>, (out, sums): (&FloatTensor<Cube>, Option<&FloatTensor<Cube>>), epilogue: Epilogue<'_>) {
        let tile = variant.tile;
        let groups = self.grid(tile).expect("a tile whose grid fits");
        let (tx, ty) = tile.threads();
        let kernel = WgslKernel { name: "dextrain_matmul", key: variant, source: shader_source, entry_point: ENTRY_POINT, workgroup: [tx as u32, ty as u32] };
        // (counted by gpu_counts' launch observer as `dextrain:matmul`)
        let constants: &[u32] = bytemuck::cast_slice(std::slice::from_ref(&self.cfg));
        // binding 3: the epilogue's operand, or the sums of the row of ones (else unused)
        let third = sums.or(epilogue.operand()).unwrap_or(lhs);
        launch(kernel, groups, &[lhs, rhs, out, third], constants);
    }

    /// The product, and the sums of the row of ones, from the kernel's outputs: the partials
    /// summed where split (one kernel of ours for both, [`sum_splits`]).
    fn finish(&self, (out, sums): (FloatTensor<Cube>, Option<FloatTensor<Cube>>)) -> (FloatTensor<Cube>, Option<FloatTensor<Cube>>) {
        if self.splits == 1 {
            return (out, sums.map(|s| Cube::float_reshape(s, Shape::new([1, self.n]))));
        }
        let (c, s) = sum_splits(&out, sums.as_ref(), self.splits);
        (Cube::float_reshape(c, Shape::new([self.a_rows(), self.n])), s.map(|s| Cube::float_reshape(s, Shape::new([1, self.n]))))
    }
}

/// shaders/sum_splits.wgsl.
const SHADER_SUM_SPLITS: &str = include_str!("../../../shaders/sum_splits.wgsl");

/// The text of shaders/sum_splits.wgsl (the kernel has one variant).
pub fn sum_splits_source(_: ()) -> String {
    SHADER_SUM_SPLITS.to_string()
}

/// `SumSplitsCfg` of sum_splits.wgsl (keep in sync).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SumSplitsCfg {
    /// Entries of one partial product.
    pub len_c: u32,
    /// Entries of one partial of the row of ones' sums (0: none).
    pub len_s: u32,
    /// Partials.
    pub splits: u32,
    /// Entries per row of the launch's 2-D grid (workgroups along x × 256).
    pub row: u32,
}

/// The partials of a product split over k, [S, M, N], and of its row of ones' sums, [S, N],
/// each summed over S in increasing s from 0 → ([M · N], [N]) in one kernel of ours.
fn sum_splits(partials: &FloatTensor<Cube>, sums: Option<&FloatTensor<Cube>>, splits: usize) -> (FloatTensor<Cube>, Option<FloatTensor<Cube>>) {
    use burn::backend::TensorMetadata;
    let len_c = partials.shape().num_elements() / splits;
    let len_s = sums.map_or(0, |s| s.shape().num_elements() / splits);
    let c = Cube::float_empty(Shape::new([len_c]), &partials.device, FloatDType::F32); // written whole below
    let s = sums.map(|_| Cube::float_empty(Shape::new([len_s]), &partials.device, FloatDType::F32));
    let count = (len_c + len_s) as u32; // (Planned::new checked M · N · S under 2^32)
    let (gx, gy) = crate::gpu::shaders::workgroups_of(count, 256);
    let kernel = WgslKernel { name: "dextrain_sum_splits", key: (), source: sum_splits_source, entry_point: "sum_splits", workgroup: [256, 1] };
    let cfg = SumSplitsCfg { len_c: len_c as u32, len_s: len_s as u32, splits: splits as u32, row: gx * 256 };
    // (without sums, the partials stand in at their bindings, never read or written there)
    launch(kernel, [gx, gy, 1], &[partials, sums.unwrap_or(partials), &c, s.as_ref().unwrap_or(&c)], bytemuck::cast_slice(std::slice::from_ref(&cfg)));
    (c, s)
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
    ensure!(!epilogue.ones_row(), "matmul.wgsl: column sums are a second output (matmul_and_column_sums)");
    Ok(run(lhs, rhs, choice, epilogue)?.0)
}

/// `lhs · rhs` [M, N] and `1ᵀ rhs` [1, N] (rhs's column sums) in one launch of the kernel (and,
/// split over k, one of [`sum_splits`]): a dense layer's weight gradient xᵀ g and bias gradient
/// 1ᵀ g, lhs = xᵀ, rhs = g ([`Epilogue::ColumnSums`]). Each sum adds the rows in increasing k with
/// fused multiply-adds by 1 (plain additions), per split, then the splits in order.
pub fn matmul_and_column_sums(lhs: &FloatTensor<Cube>, rhs: &FloatTensor<Cube>, choice: TileChoice) -> Result<(FloatTensor<Cube>, FloatTensor<Cube>)> {
    let (c, sums) = run(lhs, rhs, choice, Epilogue::ColumnSums)?;
    Ok((c, sums.ok_or_else(|| anyhow!("matmul.wgsl: no column sums written"))?))
}

/// The product with `epilogue`, in the tile `choice` gives: C, and the row of ones' sums where
/// the epilogue asks for them.
fn run(lhs: &FloatTensor<Cube>, rhs: &FloatTensor<Cube>, choice: TileChoice, epilogue: Epilogue<'_>) -> Result<(FloatTensor<Cube>, Option<FloatTensor<Cube>>)> {
    let forced = match choice {
        TileChoice::Fixed(t) => Some(t),
        TileChoice::ByShape | TileChoice::Tuned { .. } => None,
    };
    let planned = Planned::new(lhs, rhs, forced, epilogue)?;
    let out = planned.outputs(lhs, rhs);
    let variant = match choice {
        TileChoice::Tuned { vector_reads } => {
            // (the candidates are listed only where the product is not tuned yet)
            let candidates = || planned.candidates(vector_reads);
            crate::learn::kernels::matmul_tuning::tuned_variant(&planned_key(&planned, vector_reads), Variant::scalar(planned.rule_tile), candidates, |v| {
                planned.launch(v, lhs, rhs, (&out.0, out.1.as_ref()), epilogue)
            }, || {
                let _ = burn_cubecl::cubecl::future::block_on(lhs.client.sync()); // (a failure surfaces at the next read)
            })
        }
        TileChoice::ByShape | TileChoice::Fixed(_) => Variant::scalar(planned.rule_tile),
    };
    planned.launch(variant, lhs, rhs, (&out.0, out.1.as_ref()), epilogue);
    Ok(planned.finish(out))
}

/// The variants [`TileChoice::Tuned`] times for `lhs · rhs` (with `epilogue`): every candidate
/// tile shape, with scalar reads and, where the operands allow, vec4 reads.
pub fn candidate_variants(lhs: &FloatTensor<Cube>, rhs: &FloatTensor<Cube>, epilogue: Epilogue<'_>) -> Result<Vec<Variant>> {
    Ok(Planned::new(lhs, rhs, None, epilogue)?.candidates(true))
}

/// `lhs · rhs` (with `epilogue`) planned by shape ([`TileChoice::ByShape`]'s splits over k) but
/// run as `variant` (one of [`candidate_variants`]): what [`TileChoice::Tuned`] times for each
/// candidate (a test compares them). C, and the row of ones' sums with [`Epilogue::ColumnSums`].
pub fn matmul_as_planned_in(lhs: &FloatTensor<Cube>, rhs: &FloatTensor<Cube>, variant: Variant, epilogue: Epilogue<'_>) -> Result<(FloatTensor<Cube>, Option<FloatTensor<Cube>>)> {
    let planned = Planned::new(lhs, rhs, None, epilogue)?;
    ensure!(planned.candidates(true).contains(&variant), "matmul.wgsl: {} does not take this product", variant.label());
    let out = planned.outputs(lhs, rhs);
    planned.launch(variant, lhs, rhs, (&out.0, out.1.as_ref()), epilogue);
    Ok(planned.finish(out))
}

/// What identifies a product for the tuner: its sizes, strides, splits and epilogue (the launch
/// constants), and whether vec4 reads are candidates.
fn planned_key(p: &Planned, vector_reads: bool) -> crate::learn::kernels::matmul_tuning::ShapeKey {
    let c = &p.cfg;
    crate::learn::kernels::matmul_tuning::ShapeKey {
        sizes: [c.m, c.n, c.k, c.batches],
        a_strides: [c.a_row, c.a_col, c.a_batch],
        b_strides: [c.b_row, c.b_col, c.b_batch],
        splits: c.k_splits,
        epilogue: c.epilogue,
        ones_row: c.ones_row != NO_ONES_ROW,
        vector_reads,
    }
}
