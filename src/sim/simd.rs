//! Small helpers for the simulation's hot loops: runtime CPU dispatch and vectorizable
//! reductions. Nothing here changes results beyond the usual floating-point reassociation of
//! a reduction's order (maxima are exact whatever the order).
//!
//! # Runtime dispatch ([`multiversion!`](crate::sim::simd::multiversion))
//! The crate is built for the baseline `x86_64` (SSE2) so it runs everywhere; no
//! `target-cpu=native`. A hot loop written with [`multiversion!`](crate::sim::simd::multiversion)
//! is compiled twice: once for the baseline and once with `avx2,fma` enabled (8-wide vectors),
//! and each call picks the AVX2 copy when the CPU has AVX2 and FMA ([`has_avx2_fma`], a cached
//! feature test). The body must be safe Rust (it is compiled under `deny(unsafe_code)`); the
//! only `unsafe` is the call into the AVX2 copy, whose one requirement (the CPU has the
//! features) is checked right before it.
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

#[cfg(test)]
thread_local! {
    /// Unit tests: run the baseline copies on this thread even on an AVX2 machine.
    static FORCE_BASELINE: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Unit tests: runs `f` with every [`multiversion!`](crate::sim::simd::multiversion) function
/// on this thread taking its baseline (SSE2) copy, so both copies can be compared on one
/// machine.
#[cfg(test)]
pub fn with_baseline_copies<R>(f: impl FnOnce() -> R) -> R {
    FORCE_BASELINE.with(|b| b.set(true));
    let out = f();
    FORCE_BASELINE.with(|b| b.set(false));
    out
}

/// Whether the CPU running this has AVX2 and FMA (std caches the answer, so this is cheap).
#[inline]
pub fn has_avx2_fma() -> bool {
    #[cfg(test)]
    if FORCE_BASELINE.with(|b| b.get()) {
        return false;
    }
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Defines a function whose body is compiled twice, for the baseline CPU and with `avx2,fma`,
/// and that runs the AVX2 copy when [`has_avx2_fma`] says so. See the [module docs](self) for
/// an example and the rules for bodies.
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
            if $crate::sim::simd::has_avx2_fma() {
                // SAFETY: calling a `#[target_feature(enable = "avx2,fma")]` function is sound
                // exactly when the CPU supports those features, which was checked just above.
                return unsafe { avx2($($arg),*) };
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
    fn both_copies_agree_with_the_baseline() {
        let x: Vec<f32> = (0..1000)
            .map(|i| ((i * 7919) % 1013) as f32 - 500.0)
            .collect();
        let plain = x.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert_eq!(max_abs(&x), plain);
        // The dispatcher is deterministic for a given CPU.
        assert_eq!(has_avx2_fma(), has_avx2_fma());
    }
}
