//! The learner's matrix products on burn's wgpu backend, launched with a routine chosen by
//! measurement rather than the one burn takes by default: dextrain's own tiled kernel
//! (`learn::kernels::wgsl_matmul`, the default) or one of cubek's (burn's kernel library).
//!
//! Without its `autotune` feature (off here: autotune times every candidate in every process and
//! may pick another one in the next, so a run and its resume could differ in the last bits), burn
//! runs every product through cubek's `Auto` routine: cooperative matrices where the adapter has
//! them, else `SimpleUnit` (one thread per output tile, no shared-memory staging). On WGSL adapters
//! (no cooperative matrices) that is `SimpleUnit` everywhere; on an NVIDIA H200 it ran the PPO
//! update's products at ~1–5 TFLOP/s, 65 % of the update's GPU time (BENCHMARKS.md, issue 33). Here
//! the routine is a fixed choice per process, so the products are the same kernels run to run
//! (deterministic, as before) and the choice is measured, not guessed: `DEXTRAIN_GPU_MATMUL`
//! names another routine for a measurement (`GpuMatmul::NAMES`), `dextrain bench --matmul` times
//! them all. Measured on an H200 (2026-11-26, BENCHMARKS.md): one PPO minibatch's products took
//! 4.0 ms with `dextrain_tiled` against 28 ms with cubek's fastest (`simple_unit_small_tiles`), and
//! the PPO bench's update 99 against 145 ms device-resident; the plane routines need cooperative
//! matrices or subgroup features WGSL does not give here and fall back to burn's. On a hardware GPU
//! the default is `dextrain_tuned`: our kernel with its tile shape per product timed in the process
//! (`matmul_tuning.rs`), which changes which thread computes an entry but not its value, so it
//! keeps runs exact where burn's autotune would not.

use std::sync::OnceLock;
use std::sync::atomic::{AtomicU64, Ordering};

use anyhow::{Result, bail};
use burn::backend::Cube;
use burn::backend::tensor::FloatTensor;
use burn::backend::ops::FloatTensorOps;
use burn::tensor::DType;
use burn_cubecl::cubecl::ir::{ElemType, FloatKind};
use burn_cubecl::kernel::matmul::init_matmul_output;
use cubek::matmul::definition::{MatmulElems, MatmulGlobalElems};
use cubek::matmul::launch::launch_ref;
use cubek::matmul::multi_level::Strategy as Routine;
use cubek::matmul::multi_level::components::tile::TileMatmulKind;
use cubek::matmul::multi_level::routines::TileSizeSelection;
use cubek::matmul::multi_level::routines::batch::double_buffering::DoubleBufferingArgs;
use cubek::matmul::multi_level::routines::batch::double_unit::DoubleUnitSelectionArgs;
use cubek::matmul::multi_level::routines::batch::ordered_double_buffering::OrderedSelectionArgs;
use cubek::matmul::multi_level::routines::batch::simple::SimpleArgs;
use cubek::matmul::multi_level::routines::batch::simple_unit::SimpleUnitSelectionArgs;
use cubek::matmul::routine::BlueprintStrategy;
use cubek::matmul::strategy::Strategy;
use cubek::std::InputBinding;

use crate::learn::kernels::wgsl_matmul::{Epilogue, Tile, TileChoice};

/// The environment variable that names the routine for a measurement.
pub const ENV_VAR: &str = "DEXTRAIN_GPU_MATMUL";

/// A matmul routine for the learner's f32 products: burn's, cubek's or dextrain's own.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GpuMatmul {
    /// burn's own choice (`float_matmul`: cubek's `Auto`).
    Burn,
    /// One thread per output tile, the largest tile (what `Auto` runs on WGSL).
    SimpleUnit,
    /// One thread per output tile, the smallest tile, more tiles per workgroup.
    SimpleUnitSmallTiles,
    /// One thread per output tile, operands double-buffered through shared memory.
    DoubleUnit,
    /// `DoubleUnit` with the smallest tile.
    DoubleUnitSmallTiles,
    /// A subgroup (plane) per tile, register tile products, operands staged in shared memory.
    SimplePlane,
    /// `SimplePlane` double-buffered.
    DoublePlane,
    /// `DoublePlane` with ordered loading.
    OrderedDoublePlane,
    /// dextrain's own WGSL kernel (`learn::kernels::wgsl_matmul`: tiles staged in workgroup memory, on
    /// burn's command stream), the tile shape and any split over k per product (`wgsl_matmul::plan`).
    DextrainTiled,
    /// dextrain's kernel, 64 × 64 tiles (4 × 4 per thread) for every product.
    DextrainTiledSmall,
    /// dextrain's kernel, 128 × 128 tiles (8 × 8 per thread) for every product.
    DextrainTiledLarge,
    /// dextrain's kernel, 128 × 64 tiles (8 × 4 per thread) for every product.
    DextrainTiledTall,
    /// dextrain's kernel, its tile shape per product timed on the adapter at its first launch
    /// (`learn::kernels::matmul_tuning`), scalar reads; the same numbers as `DextrainTiled` bit for
    /// bit.
    DextrainTuned,
    /// `DextrainTuned` with vec4 reads of the operands among the candidates where their sizes
    /// allow (the same numbers again). Not the default: on an H200 it sped the PPO update up on
    /// some processes and slowed SAC's step on most, and it doubles the shaders a fresh machine
    /// compiles (BENCHMARKS.md).
    DextrainTunedVec4,
}

impl GpuMatmul {
    /// Every routine with its name (`DEXTRAIN_GPU_MATMUL`, the bench JSON).
    pub const NAMES: [(GpuMatmul, &'static str); 14] = [
        (GpuMatmul::Burn, "burn"),
        (GpuMatmul::SimpleUnit, "simple_unit"),
        (GpuMatmul::SimpleUnitSmallTiles, "simple_unit_small_tiles"),
        (GpuMatmul::DoubleUnit, "double_unit"),
        (GpuMatmul::DoubleUnitSmallTiles, "double_unit_small_tiles"),
        (GpuMatmul::SimplePlane, "simple_plane"),
        (GpuMatmul::DoublePlane, "double_plane"),
        (GpuMatmul::OrderedDoublePlane, "ordered_double_plane"),
        (GpuMatmul::DextrainTiled, "dextrain_tiled"),
        (GpuMatmul::DextrainTiledSmall, "dextrain_tiled_64"),
        (GpuMatmul::DextrainTiledLarge, "dextrain_tiled_128"),
        (GpuMatmul::DextrainTiledTall, "dextrain_tiled_128x64"),
        (GpuMatmul::DextrainTuned, "dextrain_tuned"),
        (GpuMatmul::DextrainTunedVec4, "dextrain_tuned_vec4"),
    ];

    /// The routine a run uses unless `DEXTRAIN_GPU_MATMUL` names another, on a software adapter
    /// (lavapipe: compiling every tile shape there costs seconds and timing them says little).
    pub const DEFAULT: GpuMatmul = GpuMatmul::DextrainTiled;

    /// The routine a run uses on a hardware GPU unless `DEXTRAIN_GPU_MATMUL` names another: the tile
    /// shapes timed per product (the same numbers as [`GpuMatmul::DEFAULT`]; on an H200 the PPO
    /// bench's device-resident update took 94 ms against 106–115 ms, BENCHMARKS.md).
    pub const DEFAULT_HARDWARE: GpuMatmul = GpuMatmul::DextrainTuned;

    /// The routine's name.
    pub fn name(self) -> &'static str {
        Self::NAMES.iter().find(|(m, _)| *m == self).map(|(_, n)| *n).unwrap_or("?")
    }

    /// The routine called `name`, or an error listing the names.
    pub fn parse(name: &str) -> Result<GpuMatmul> {
        match Self::NAMES.iter().find(|(_, n)| *n == name) {
            Some((m, _)) => Ok(*m),
            None => {
                let names: Vec<&str> = Self::NAMES.iter().map(|(_, n)| *n).collect();
                bail!("{ENV_VAR}={name:?}: expected one of {}", names.join(", "))
            }
        }
    }

    /// Whether the learner's dense layers run as `affine.rs`'s one op on the GPU, its weight gradient
    /// split inside it (over k by dextrain's kernel, over row slices with cubek's), rather than as
    /// burn's products of row slices (`nets::affine`): every routine but `Burn`, which keeps burn's
    /// products and their gradients.
    pub fn splits_inside(self) -> bool {
        self != GpuMatmul::Burn
    }

    /// Whether the routine splits a product with a long k and few output tiles over k itself
    /// (dextrain's kernel, `wgsl_matmul::plan`), so the weight gradient needs no row slices.
    pub fn splits_k_itself(self) -> bool {
        self.ours().is_some()
    }

    /// Whether the routine is dextrain's own kernel (whose sums `mlp_forward.wgsl` repeats).
    pub fn is_ours(self) -> bool {
        self.ours().is_some()
    }

    /// Whether the routine is dextrain's own kernel, and how it picks the tile shape.
    fn ours(self) -> Option<TileChoice> {
        match self {
            GpuMatmul::DextrainTiled => Some(TileChoice::ByShape),
            GpuMatmul::DextrainTiledSmall => Some(TileChoice::Fixed(Tile::SMALL)),
            GpuMatmul::DextrainTiledLarge => Some(TileChoice::Fixed(Tile::LARGE)),
            GpuMatmul::DextrainTiledTall => Some(TileChoice::Fixed(Tile::TALL)),
            GpuMatmul::DextrainTuned => Some(TileChoice::Tuned { vector_reads: false }),
            GpuMatmul::DextrainTunedVec4 => Some(TileChoice::Tuned { vector_reads: true }),
            _ => None,
        }
    }

    /// cubek's strategy for the routine (None: burn's own `float_matmul`, or ours).
    fn strategy(self) -> Option<Strategy> {
        let unit = |tile_size| SimpleUnitSelectionArgs { tile_size };
        let double_unit = |tile_size| DoubleUnitSelectionArgs { tile_size };
        let routine = match self {
            GpuMatmul::Burn
            | GpuMatmul::DextrainTiled
            | GpuMatmul::DextrainTiledSmall
            | GpuMatmul::DextrainTiledLarge
            | GpuMatmul::DextrainTiledTall
            | GpuMatmul::DextrainTuned
            | GpuMatmul::DextrainTunedVec4 => return None,
            GpuMatmul::SimpleUnit => Routine::SimpleUnit(BlueprintStrategy::Inferred(unit(TileSizeSelection::MaxTileSize))),
            GpuMatmul::SimpleUnitSmallTiles => {
                Routine::SimpleUnit(BlueprintStrategy::Inferred(unit(TileSizeSelection::MinTileSize)))
            }
            GpuMatmul::DoubleUnit => Routine::DoubleUnit(BlueprintStrategy::Inferred(double_unit(TileSizeSelection::MaxTileSize))),
            GpuMatmul::DoubleUnitSmallTiles => {
                Routine::DoubleUnit(BlueprintStrategy::Inferred(double_unit(TileSizeSelection::MinTileSize)))
            }
            GpuMatmul::SimplePlane => Routine::SimpleCyclicCmma(BlueprintStrategy::Inferred(SimpleArgs {
                tile_matmul: TileMatmulKind::Register,
                multi_rows: false,
            })),
            GpuMatmul::DoublePlane => Routine::DoubleCyclicCmma(BlueprintStrategy::Inferred(DoubleBufferingArgs {
                tile_matmul: TileMatmulKind::Register,
                specialized: false,
            })),
            GpuMatmul::OrderedDoublePlane => Routine::OrderedDoubleCmma(BlueprintStrategy::Inferred(OrderedSelectionArgs {
                tile_matmul: TileMatmulKind::Register,
                ..Default::default()
            })),
        };
        Some(Strategy::MultiLevel(routine))
    }
}

/// The routine of this process (read from `DEXTRAIN_GPU_MATMUL` once).
static CHOSEN: OnceLock<GpuMatmul> = OnceLock::new();

/// Products that fell back to burn's own routine because the chosen one refused their shape or
/// the adapter (cubek's `MatmulSetupError`).
static FALLBACKS: AtomicU64 = AtomicU64::new(0);

/// Reads `DEXTRAIN_GPU_MATMUL` (once per process): the routine, or an error naming the variable and
/// the routines there are; without it [`GpuMatmul::DEFAULT_HARDWARE`] on a hardware GPU and
/// [`GpuMatmul::DEFAULT`] on a `software` adapter. Called where a GPU learner device is set up, so
/// that a wrong name stops the command with a one-line error before anything runs.
pub fn configure(software: bool) -> Result<GpuMatmul> {
    if let Some(m) = CHOSEN.get() {
        return Ok(*m);
    }
    let m = match std::env::var(ENV_VAR) {
        Ok(name) if !name.is_empty() => GpuMatmul::parse(&name)?,
        _ if software => GpuMatmul::DEFAULT,
        _ => GpuMatmul::DEFAULT_HARDWARE,
    };
    Ok(*CHOSEN.get_or_init(|| m))
}

/// The routine the learner's products run with.
pub fn chosen() -> GpuMatmul {
    *CHOSEN.get().unwrap_or(&GpuMatmul::DEFAULT)
}

/// How many products fell back to burn's routine so far.
pub fn fallbacks() -> u64 {
    FALLBACKS.load(Ordering::Relaxed)
}

/// `lhs · rhs` for f32 lhs [m, k], rhs [k, n] (either may be a strided view, e.g. a transpose) on
/// burn's wgpu backend, with the chosen routine → [m, n].
pub fn matmul(lhs: FloatTensor<Cube>, rhs: FloatTensor<Cube>) -> FloatTensor<Cube> {
    matmul_with(chosen(), lhs, rhs)
}

/// `lhs · rhs` as [`matmul`] with `routine` (the matmul bench compares the routines in one process).
pub fn matmul_with(routine: GpuMatmul, lhs: FloatTensor<Cube>, rhs: FloatTensor<Cube>) -> FloatTensor<Cube> {
    if let Some(tile) = routine.ours() {
        return match crate::learn::kernels::wgsl_matmul::matmul(&lhs, &rhs, tile) {
            Ok(out) => out,
            Err(_) => fall_back(lhs, rhs), // shapes or a device the kernel does not take
        };
    }
    let strategy = match routine.strategy() {
        Some(s) if lhs.dtype == DType::F32 && rhs.dtype == DType::F32 && lhs.qparams.is_none() && rhs.qparams.is_none() => s,
        _ => return Cube::float_matmul(lhs, rhs),
    };
    let out = init_matmul_output(&lhs, &rhs, DType::F32);
    let f32_elem = ElemType::Float(FloatKind::F32);
    let mut dtypes = MatmulElems::from_globals(&MatmulGlobalElems { lhs: f32_elem, rhs: f32_elem, out: f32_elem });
    let client = out.client.clone();
    let launched = launch_ref(
        &strategy,
        &client,
        InputBinding::new(lhs.clone().binding(), f32_elem),
        InputBinding::new(rhs.clone().binding(), f32_elem),
        out.clone().binding(),
        &mut dtypes,
    );
    match launched {
        Ok(()) => out,
        Err(_) => fall_back(lhs, rhs), // the routine does not take this shape or adapter (nothing was launched)
    }
}

/// `lhs · rhs` with an epilogue (a dense layer's bias, and its ELU) in the same kernel, where the
/// chosen routine is dextrain's kernel and it takes the operands; None otherwise (the caller adds
/// the epilogue with tensor ops).
pub fn matmul_then(lhs: &FloatTensor<Cube>, rhs: &FloatTensor<Cube>, epilogue: Epilogue<'_>) -> Option<FloatTensor<Cube>> {
    let tile = chosen().ours()?;
    crate::learn::kernels::wgsl_matmul::matmul_then(lhs, rhs, tile, epilogue).ok()
}

/// `lhs · rhs` and `1ᵀ rhs` (rhs's column sums) in one product, where the chosen routine is
/// dextrain's kernel and it takes the operands (`wgsl_matmul::matmul_and_column_sums`); None
/// otherwise.
pub fn matmul_and_column_sums(lhs: &FloatTensor<Cube>, rhs: &FloatTensor<Cube>) -> Option<(FloatTensor<Cube>, FloatTensor<Cube>)> {
    let tile = chosen().ours()?;
    crate::learn::kernels::wgsl_matmul::matmul_and_column_sums(lhs, rhs, tile).ok()
}

/// burn's own product, for one the chosen routine did not take (counted in [`fallbacks`]).
fn fall_back(lhs: FloatTensor<Cube>, rhs: FloatTensor<Cube>) -> FloatTensor<Cube> {
    FALLBACKS.fetch_add(1, Ordering::Relaxed);
    Cube::float_matmul(lhs, rhs)
}
