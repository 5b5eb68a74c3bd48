//! Run-time choice of the instruction set.
//!
//! The hot loops are written once, lane by lane, and marked `#[inline(always)]`; each public
//! query has an entry point compiled with `#[target_feature(enable = "avx2,fma")]` that the
//! loops inline into (so they use 8-wide AVX registers) and a portable one (SSE2 on x86-64,
//! whatever the target has elsewhere). `is_x86_feature_detected!` picks at run time, so one
//! binary runs on CPUs with and without AVX2.

/// An instruction set for the hot loops.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Simd {
    /// Baseline code for the target (SSE2 on x86-64).
    Portable,
    /// AVX2 and FMA (x86-64 only).
    Avx2,
}

impl Simd {
    /// The best set this CPU supports.
    pub fn detect() -> Simd {
        #[cfg(target_arch = "x86_64")]
        if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
            return Simd::Avx2;
        }
        Simd::Portable
    }

    /// `self` if this CPU supports it, else [`Simd::Portable`]: requesting AVX2 on a CPU
    /// without it is safe.
    pub fn usable(self) -> Simd {
        match self {
            Simd::Avx2 if Simd::detect() == Simd::Avx2 => Simd::Avx2,
            _ => Simd::Portable,
        }
    }
}
