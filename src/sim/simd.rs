//! Small helpers for the simulation's hot loops: runtime CPU dispatch and vectorizable
//! reductions. Nothing here changes results beyond the usual floating-point reassociation of
//! a reduction's order (maxima are exact whatever the order).
//!
//! # Runtime dispatch ([`multiversion!`](crate::sim::simd::multiversion))
//! The crate is built for the baseline `x86_64` (SSE2) so it runs everywhere; no
//! `target-cpu=native`. A hot loop written with [`multiversion!`](crate::sim::simd::multiversion)
//! is compiled three times: for the baseline, with `avx2,fma` (8-wide vectors), and with
//! AVX-512 (`avx512f,avx512vl,avx512bw,avx512dq` on top of those: 16-wide vectors and masked
//! operations), and each call runs the best copy the CPU supports ([`simd_level`], a cached
//! feature test). The body must be safe Rust (it is compiled under `deny(unsafe_code)`); the
//! only `unsafe` is the call into a feature-enabled copy, whose one requirement (the CPU has
//! the features) is checked right before it. Every copy does the same IEEE operations on each
//! element (Rust never contracts `a * b + c` into a fused multiply-add, and the reductions
//! below keep a fixed lane count), so the copies give the same bits; the tests run them all
//! (`with_simd_level`).
//!
//! The AVX-512 copies took about 11 % off the 32×32 torso's wall time on an AMD EPYC with
//! AVX-512 (docs/simulate.md, "AVX-512 copies"); on an older machine the same change measured
//! about 3 %.
//!
//! ```
//! leman::sim::simd::multiversion! {
//!     /// `y += k · x` element-wise (over the common length).
//!     pub fn axpy(k: f32, x: &[f32], y: &mut [f32]) {
//!         for (y, x) in y.iter_mut().zip(x) {
//!             *y += k * x;
//!         }
//!     }
//! }
//!
//! let mut y = vec![1.0f32; 5];
//! axpy(2.0, &[1.0, 2.0, 3.0, 4.0, 5.0], &mut y);
//! assert_eq!(y, [3.0, 5.0, 7.0, 9.0, 11.0]);
//! ```
//!
//! Rules for bodies: arguments are plain `name: Type` (no patterns, no generics); write the body
//! so LLVM can vectorize it (zipped slices or slices re-sliced to one length, no bounds checks,
//! no loop-carried scalar reductions: use [`MaxLanes`] / `[f32; LANES]` accumulators; helpers
//! as `#[inline(always)]` fns, not closures, which may stay out of line without the AVX2
//! features). Do not call `f32::mul_add` in a body: without FMA the baseline copy turns it into
//! a slow libm call; plain `a * b + c` is exact IEEE in both copies (Rust never contracts it).
//!
//! # Reductions ([`MaxLanes`])
//! `m = m.max(d)` over a slice is a loop-carried dependency LLVM will not reorder, so it runs
//! one element per max latency. [`MaxLanes`] keeps [`LANES`] independent maxima (one per
//! position in a `chunks_exact(LANES)` chunk), which LLVM turns into vector maxima, and a
//! "poison" lane sum that becomes NaN as soon as any pushed value is NaN or infinite, so
//! non-finite values are never lost (a plain vector max would drop NaN).

#![allow(unsafe_code)] // only the dispatch call in `multiversion!` (see its SAFETY comment)

/// Vector width (in `f32`) the reductions and chunked loops are written for (one AVX register).
pub const LANES: usize = 8;

/// The widest vector instruction set a [`multiversion!`](crate::sim::simd::multiversion)
/// function may use, in increasing order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum SimdLevel {
    /// The `x86_64` baseline (SSE2), or any other architecture.
    Baseline,
    /// AVX2 with FMA.
    Avx2Fma,
    /// AVX-512 F, VL, BW and DQ (with AVX2 and FMA).
    Avx512,
}

impl SimdLevel {
    /// Every level, lowest first.
    pub const ALL: [SimdLevel; 3] = [SimdLevel::Baseline, SimdLevel::Avx2Fma, SimdLevel::Avx512];

    /// A short name for reports: `baseline`, `avx2+fma` or `avx512`.
    pub fn name(self) -> &'static str {
        match self {
            SimdLevel::Baseline => "baseline",
            SimdLevel::Avx2Fma => "avx2+fma",
            SimdLevel::Avx512 => "avx512",
        }
    }
}

#[cfg(test)]
thread_local! {
    /// Unit tests: the highest level this thread's calls may take (see [`with_simd_level`]).
    static LEVEL_CAP: std::cell::Cell<SimdLevel> = const { std::cell::Cell::new(SimdLevel::Avx512) };
}

/// Unit tests: runs `f` with every [`multiversion!`](crate::sim::simd::multiversion) function
/// on this thread taking the copy for `level` or, if the CPU lacks it, the best one below, so
/// all copies can be compared on one machine.
#[cfg(test)]
pub fn with_simd_level<R>(level: SimdLevel, f: impl FnOnce() -> R) -> R {
    let before = LEVEL_CAP.with(|c| c.replace(level));
    let out = f();
    LEVEL_CAP.with(|c| c.set(before));
    out
}

/// The best level the CPU running this supports: the feature tests run once, and every call
/// after that is one atomic load (every `multiversion!` call dispatches through this, so it is
/// on the simulation's hot path).
#[inline]
pub fn simd_level() -> SimdLevel {
    static DETECTED: std::sync::OnceLock<SimdLevel> = std::sync::OnceLock::new();
    let detected = *DETECTED.get_or_init(detected_level);
    #[cfg(test)]
    let detected = detected.min(LEVEL_CAP.with(|c| c.get()));
    detected
}

/// The feature tests behind [`simd_level`].
fn detected_level() -> SimdLevel {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::is_x86_feature_detected as has;
        if !(has!("avx2") && has!("fma")) {
            SimdLevel::Baseline
        } else if has!("avx512f") && has!("avx512vl") && has!("avx512bw") && has!("avx512dq") {
            SimdLevel::Avx512
        } else {
            SimdLevel::Avx2Fma
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        SimdLevel::Baseline
    }
}

/// Defines a function whose body is compiled three times, for the baseline CPU, with
/// `avx2,fma` and with AVX-512, and that runs the copy [`simd_level`] picks. See the
/// [module docs](self) for an example and the rules for bodies.
#[macro_export]
macro_rules! multiversion {
    (
        $(#[$meta:meta])*
        $vis:vis fn $name:ident ( $($arg:ident : $ty:ty),* $(,)? ) $(-> $ret:ty)? $body:block
    ) => {
        $(#[$meta])*
        #[allow(unsafe_code)] // only the dispatch below; the body is `deny(unsafe_code)`
        #[allow(clippy::too_many_arguments)] // bodies take their slices one by one
        $vis fn $name($($arg: $ty),*) $(-> $ret)? {
            #[inline(always)]
            #[deny(unsafe_code)]
            #[allow(clippy::too_many_arguments)] // as many as the function it implements
            fn body($($arg: $ty),*) $(-> $ret)? $body

            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2,fma")]
            #[allow(clippy::too_many_arguments)]
            fn avx2($($arg: $ty),*) $(-> $ret)? {
                body($($arg),*)
            }

            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2,fma,avx512f,avx512vl,avx512bw,avx512dq")]
            #[allow(clippy::too_many_arguments)]
            fn avx512($($arg: $ty),*) $(-> $ret)? {
                body($($arg),*)
            }

            #[cfg(target_arch = "x86_64")]
            match $crate::sim::simd::simd_level() {
                // SAFETY: calling a `#[target_feature]` function is sound exactly when the CPU
                // supports its features; `simd_level` returns a level only after testing them.
                $crate::sim::simd::SimdLevel::Avx512 => return unsafe { avx512($($arg),*) },
                // SAFETY: as above, for `avx2,fma`.
                $crate::sim::simd::SimdLevel::Avx2Fma => return unsafe { avx2($($arg),*) },
                $crate::sim::simd::SimdLevel::Baseline => {}
            }
            body($($arg),*)
        }
    };
}

pub use crate::multiversion;

/// [`LANES`] running maxima of values `≥ 0` that also remember any NaN or infinity pushed (see
/// the module docs). Push lane `l` of each `chunks_exact(LANES)` chunk with `push(l, d)`, the
/// remainder with any lane, then [`finish`](Self::finish).
#[derive(Debug, Clone, Copy, Default)]
pub struct MaxLanes {
    max: [f32; LANES],
    poison: [f32; LANES],
}

impl MaxLanes {
    /// All maxima 0, nothing non-finite seen.
    #[inline(always)]
    pub fn new() -> Self {
        Self::default()
    }

    /// Takes `d` into lane `lane` (`lane < LANES`; taken modulo [`LANES`]).
    #[inline(always)]
    pub fn push(&mut self, lane: usize, d: f32) {
        let l = lane % LANES;
        self.max[l] = if d > self.max[l] { d } else { self.max[l] };
        // 0·d is ±0 for finite d and NaN for NaN or ±∞; NaN sticks in a sum.
        self.poison[l] += 0.0 * d;
    }

    /// The largest value pushed (0 when none), `+∞` when an infinity was pushed, NaN when a
    /// NaN was.
    #[inline(always)]
    pub fn finish(&self) -> f32 {
        let mut m = 0.0f32;
        let mut p = 0.0f32;
        for l in 0..LANES {
            m = if self.max[l] > m { self.max[l] } else { m };
            p += self.poison[l];
        }
        if p.is_nan() && m != f32::INFINITY {
            f32::NAN
        } else {
            m
        }
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // lane loops index chunks on purpose
mod tests {
    use super::*;

    multiversion! {
        /// Largest |x| over a slice, NaN-aware, through the chunked lanes.
        fn max_abs(x: &[f32]) -> f32 {
            let mut acc = MaxLanes::new();
            let chunks = x.chunks_exact(LANES);
            let rest = chunks.remainder();
            for c in chunks {
                for l in 0..LANES {
                    acc.push(l, c[l].abs());
                }
            }
            for (l, v) in rest.iter().enumerate() {
                acc.push(l, v.abs());
            }
            acc.finish()
        }
    }

    #[test]
    fn max_lanes_find_the_maximum_in_any_lane_and_the_remainder() {
        for n in [0usize, 1, 7, 8, 9, 31, 100] {
            for hot in 0..n {
                let mut x: Vec<f32> = (0..n).map(|i| (i as f32 * 0.37).sin()).collect();
                x[hot] = -5.0;
                assert_eq!(max_abs(&x), 5.0, "n={n} hot={hot}");
            }
        }
        assert_eq!(max_abs(&[]), 0.0);
    }

    #[test]
    fn max_lanes_never_lose_nan_or_infinity() {
        for n in [1usize, 8, 13, 64] {
            for bad in 0..n {
                let mut x = vec![1.0f32; n];
                x[bad] = f32::NAN;
                assert!(max_abs(&x).is_nan(), "NaN lost n={n} at {bad}");
                x[bad] = f32::INFINITY;
                assert_eq!(max_abs(&x), f32::INFINITY, "∞ lost n={n} at {bad}");
                // A NaN after the maximum still shows.
                x[bad] = 1.0;
                x[0] = 1e30;
                x[n - 1] = f32::NAN;
                assert!(max_abs(&x).is_nan());
            }
        }
    }

    #[test]
    fn every_copy_agrees_with_the_plain_maximum() {
        let mut x: Vec<f32> = (0..1000)
            .map(|i| ((i * 7919) % 1013) as f32 - 500.0)
            .collect();
        x[997] = -777.0; // in the remainder of 16-wide and 8-wide chunks
        let plain = x.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert_eq!(plain, 777.0);
        for level in SimdLevel::ALL {
            assert_eq!(with_simd_level(level, || max_abs(&x)), plain, "{level:?}");
        }
    }

    #[test]
    fn a_level_cap_is_obeyed_and_undone() {
        let best = simd_level();
        assert_eq!(best, detected_level());
        for level in SimdLevel::ALL {
            assert_eq!(with_simd_level(level, simd_level), best.min(level));
        }
        // Nested caps restore the outer one.
        with_simd_level(SimdLevel::Avx2Fma, || {
            with_simd_level(SimdLevel::Baseline, || {
                assert_eq!(simd_level(), SimdLevel::Baseline)
            });
            assert_eq!(simd_level(), best.min(SimdLevel::Avx2Fma));
        });
        assert_eq!(simd_level(), best);
    }
}
