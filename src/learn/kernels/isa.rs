//! Which vector instruction set dextrain's own CPU kernels run (the fused ELU, the AVX2 matrix
//! product of `learn::kernels::sgemm`): the widest the CPU has, capped by `DEXTRAIN_SIMD`.

/// The vector instruction sets the CPU kernels here are compiled for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Isa {
    /// Plain Rust (whatever the target's baseline gives).
    Scalar,
    /// AVX2 + FMA (x86-64-v3).
    Avx2,
    /// AVX-512F (x86-64-v4).
    Avx512,
}

/// The widest [`Isa`] this CPU has, capped by the environment variable `DEXTRAIN_SIMD`
/// (`avx512`, `avx2` or `scalar`; another value is ignored with a warning): `DEXTRAIN_SIMD=avx2` runs the AVX2 kernels on an AVX-512 CPU,
/// which with a build without the `x86-v4` feature (gemm's AVX-512 kernels) is how an AVX2-only
/// CPU's learner is measured here (BENCHMARKS.md). Read once.
pub fn isa() -> Isa {
    static ISA: std::sync::OnceLock<Isa> = std::sync::OnceLock::new();
    *ISA.get_or_init(|| {
        let cap = match std::env::var("DEXTRAIN_SIMD").as_deref() {
            Ok("scalar") => Isa::Scalar,
            Ok("avx2") => Isa::Avx2,
            Ok("avx512") | Err(_) => Isa::Avx512,
            Ok(other) => {
                // a typo must not pass for a measured cap: say so once (bench prints what ran)
                eprintln!("dextrain: DEXTRAIN_SIMD={other} is not avx512, avx2 or scalar; ignored");
                Isa::Avx512
            }
        };
        detected_isa().min(cap)
    })
}

/// The widest [`Isa`] this CPU has.
pub fn detected_isa() -> Isa {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            return Isa::Avx512;
        }
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
            return Isa::Avx2;
        }
    }
    Isa::Scalar
}
