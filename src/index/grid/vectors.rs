//! The vector instructions the walks run on: the CPU's wider ones where it
//! has them, picked when a grid is built.
//!
//! The crate is built for x86-64-v2 (`.cargo/config.toml`), which every
//! x86-64 CPU since 2009 runs: SSE registers, two f64 or four f32 wide. A
//! packet's per-ray loops (its rays' set-up for each level, their limits,
//! the slab rectangles) and its 16-lane hit tests are loops the compiler
//! turns into SIMD, and with AVX2 the same loops run four f64 or eight f32
//! a register. So the kernels that pay for it are compiled twice from one
//! body, once for the build's own target and once with AVX2 enabled, and a
//! grid runs the one its CPU has (as Embree picks its kernels at run time).
//!
//! # Why the answers are the same bits
//! AVX2 widens the registers and adds no operation that rounds otherwise:
//! IEEE 754 addition, multiplication, division, square root and comparison
//! give the same bits in a lane of any width. The one instruction that
//! would change a result, a fused multiply-add, belongs to the FMA feature,
//! which the AVX2 instances do not enable, and Rust never contracts
//! `a·b + c` into one anyway. The exactness tests run both instances on
//! the same rays (`tests/grid_exactness.rs`), and a property test checks
//! the lane test compiled both ways bit for bit ([`crate::geometry::lanes`]).

/// The instructions a grid's kernels use: the build's own target, or AVX2
/// on an x86-64 CPU that has it.
///
/// Its field is private, so only [`Vectors::detect`] can make one that says
/// AVX2: a kernel may call its AVX2 instance wherever [`Vectors::avx2`]
/// says so, and that is the whole of the argument each such `unsafe` call
/// rests on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Vectors {
    avx2: bool,
}

impl Vectors {
    /// The widest this CPU runs.
    pub fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        let avx2 = std::arch::is_x86_feature_detected!("avx2");
        #[cfg(not(target_arch = "x86_64"))]
        let avx2 = false;
        Vectors { avx2 }
    }

    /// The build's own target, on any CPU.
    pub fn baseline() -> Self {
        Vectors { avx2: false }
    }

    /// Whether the CPU runs AVX2 (known, never assumed).
    #[inline(always)]
    pub fn avx2(self) -> bool {
        self.avx2
    }
}

impl std::fmt::Display for Vectors {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.avx2 { "avx2" } else { "baseline" })
    }
}
