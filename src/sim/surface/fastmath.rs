//! Branch-free `f32` approximations of `log2`, `exp2`, `pow`, `sin`/`cos` and `atan2` for the
//! constraint kernels: plain arithmetic, bit manipulation and selects only (no library calls),
//! so loops over arrays of points vectorise. The series are chosen so the relative error is a
//! few units in the last place of `f32` over the ranges the kernels use (tested below against
//! `std`); the kernels' own tolerance is 10 µm on shapes of centimetres.
//!
//! Methods (textbook, coefficients are the Taylor/atanh series themselves):
//! - `log2`: split the float into exponent and mantissa `m ∈ [√½, √2)`, then
//!   `ln m = 2 atanh t`, `t = (m − 1)/(m + 1)`, `|t| ≤ 0.172`, five odd terms.
//! - `exp2`: `y = k + f` with `k` the nearest integer (the 1.5·2²³ rounding trick) and
//!   `|f| ≤ ½`; `2^f = e^(f ln 2)` by its Taylor series to degree 7; `2^k` built in the exponent
//!   bits.
//! - `sin`/`cos`: quadrant `k = round(2θ/π)`, Cody-Waite reduction to `|r| ≤ π/4`, Taylor
//!   series to degree 9 (sin) and 10 (cos), quadrant fix-up by selects.
//! - `atan2`: `a = min/max` of `|x|, |y|`, folded to `|t| ≤ tan(π/8)` with
//!   `atan a = π/4 + atan((a − 1)/(a + 1))`, odd series to degree 15, octant fix-up.

use std::f32::consts::{FRAC_PI_2, FRAC_PI_4, LN_2, PI};

/// 1.5·2²³: adding it rounds an `f32` of magnitude below 2²² to the nearest integer.
const ROUND_MAGIC: f32 = 12_582_912.0;
/// Below this a base is treated as zero by [`pow0`] (also keeps `log2` off denormals).
const TINY: f32 = 1e-30;

/// `log2(x)` for finite `x > 0` (normal floats); relative error about 1e-7.
#[inline(always)]
pub fn log2(x: f32) -> f32 {
    let bits = x.to_bits();
    let exponent = ((bits >> 23) & 0xff) as i32 - 127;
    let m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000); // [1, 2)
    let big = m > std::f32::consts::SQRT_2;
    let m = if big { 0.5 * m } else { m };
    let e = exponent as f32 + if big { 1.0 } else { 0.0 };
    let t = (m - 1.0) / (m + 1.0);
    let t2 = t * t;
    // 2 atanh t = 2 (t + t³/3 + t⁵/5 + t⁷/7 + t⁹/9)
    let series =
        t * (2.0 + t2 * (2.0 / 3.0 + t2 * (2.0 / 5.0 + t2 * (2.0 / 7.0 + t2 * (2.0 / 9.0)))));
    e + series * (1.0 / LN_2)
}

/// `2^y`, `y` clamped to `[−126, 126]`; relative error about 1e-7.
#[inline(always)]
pub fn exp2(y: f32) -> f32 {
    let y = y.clamp(-126.0, 126.0);
    let shifted = y + ROUND_MAGIC;
    let k = shifted - ROUND_MAGIC;
    let k_bits = shifted.to_bits().wrapping_sub(ROUND_MAGIC.to_bits()) as i32;
    let f = (y - k) * LN_2; // |f| ≤ ln2/2
    let p = 1.0
        + f * (1.0
            + f * (1.0 / 2.0
                + f * (1.0 / 6.0
                    + f * (1.0 / 24.0
                        + f * (1.0 / 120.0 + f * (1.0 / 720.0 + f * (1.0 / 5040.0)))))));
    let scale = f32::from_bits(((k_bits + 127) as u32) << 23);
    p * scale
}

/// `x^e` for `x > 0` (finite `e`), 0 for `x ≤ 0` or tiny `x` (the `pow0` of the shape model).
#[inline(always)]
pub fn pow0(x: f32, e: f32) -> f32 {
    let safe = if x > TINY { x } else { 1.0 };
    let r = exp2(e * log2(safe));
    if x > TINY { r } else { 0.0 }
}

/// `(sin θ, cos θ)` for `|θ| < 10⁵`; absolute error about 1e-7.
#[inline(always)]
pub fn sin_cos(theta: f32) -> (f32, f32) {
    const PIO2_HI: f32 = 1.570_796_4; // nearest f32 to π/2
    const PIO2_LO: f32 = -4.371_139e-8; // π/2 − PIO2_HI
    let shifted = theta * (2.0 / PI) + ROUND_MAGIC;
    let k = shifted - ROUND_MAGIC;
    let quadrant = shifted.to_bits().wrapping_sub(ROUND_MAGIC.to_bits());
    let r = (theta - k * PIO2_HI) - k * PIO2_LO;
    let r2 = r * r;
    let s = r
        * (1.0
            + r2 * (-1.0 / 6.0
                + r2 * (1.0 / 120.0 + r2 * (-1.0 / 5040.0 + r2 * (1.0 / 362_880.0)))));
    let c = 1.0
        + r2 * (-0.5
            + r2 * (1.0 / 24.0
                + r2 * (-1.0 / 720.0 + r2 * (1.0 / 40_320.0 + r2 * (-1.0 / 3_628_800.0)))));
    let swap = quadrant & 1 != 0;
    let (sin, cos) = if swap { (c, s) } else { (s, c) };
    let sin = if quadrant & 2 != 0 { -sin } else { sin };
    let cos = if quadrant.wrapping_add(1) & 2 != 0 {
        -cos
    } else {
        cos
    };
    (sin, cos)
}

/// `atan2(y, x)` in `(−π, π]`; absolute error about 2e-7 (0 for `x = y = 0`).
#[inline(always)]
pub fn atan2(y: f32, x: f32) -> f32 {
    const TAN_PI_8: f32 = 0.414_213_57;
    let (ax, ay) = (x.abs(), y.abs());
    let big = ax.max(ay);
    let small = ax.min(ay);
    let a = if big > 0.0 { small / big } else { 0.0 };
    let fold = a > TAN_PI_8;
    let t = if fold { (a - 1.0) / (a + 1.0) } else { a };
    let base = if fold { FRAC_PI_4 } else { 0.0 };
    let t2 = t * t;
    let series = t
        * (1.0
            + t2 * (-1.0 / 3.0
                + t2 * (1.0 / 5.0
                    + t2 * (-1.0 / 7.0
                        + t2 * (1.0 / 9.0
                            + t2 * (-1.0 / 11.0 + t2 * (1.0 / 13.0 + t2 * (-1.0 / 15.0))))))));
    let r = base + series;
    let r = if ay > ax { FRAC_PI_2 - r } else { r };
    let r = if x < 0.0 { PI - r } else { r };
    if y < 0.0 { -r } else { r }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_noise::Noise;

    fn uniform(noise: &mut Noise, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * 0.5 * (noise.next() + 1.0)
    }

    #[test]
    fn log2_exp2_and_pow_match_std() {
        let mut noise = Noise(3);
        let mut worst = 0.0f64;
        for _ in 0..200_000 {
            let x = 10f32.powf(uniform(&mut noise, -20.0, 20.0));
            let rel = (f64::from(log2(x)) - f64::from(x).log2()).abs()
                / f64::from(x).log2().abs().max(1.0);
            worst = worst.max(rel);
        }
        assert!(worst < 3e-7, "log2 error {worst}");
        let mut worst = 0.0f64;
        for _ in 0..200_000 {
            let y = uniform(&mut noise, -120.0, 120.0);
            let exact = 2f64.powf(f64::from(y));
            worst = worst.max((f64::from(exp2(y)) - exact).abs() / exact);
        }
        assert!(worst < 5e-7, "exp2 error {worst}");
        let mut worst = 0.0f64;
        for _ in 0..200_000 {
            let x = uniform(&mut noise, 0.0, 3.0);
            let e = uniform(&mut noise, 0.3, 20.0);
            let exact = f64::from(x).powf(f64::from(e));
            let got = f64::from(pow0(x, e));
            if exact > 1e-30 && exact < 1e30 {
                worst = worst.max((got - exact).abs() / exact);
            }
        }
        // `e·log2 x` is rounded to f32 (up to 32 here): about 1e-6 relative per unit of it.
        assert!(worst < 1e-5, "pow error {worst}");
        assert_eq!(pow0(0.0, 2.5), 0.0);
        assert_eq!(pow0(-1.0, 2.0), 0.0);
        assert_eq!(pow0(1e-35, 0.5), 0.0);
    }

    #[test]
    fn sin_cos_and_atan2_match_std() {
        let mut noise = Noise(4);
        let (mut ws, mut wc) = (0.0f32, 0.0f32);
        for _ in 0..200_000 {
            let t = uniform(&mut noise, -40.0, 40.0);
            let (s, c) = sin_cos(t);
            ws = ws.max((s - t.sin()).abs());
            wc = wc.max((c - t.cos()).abs());
        }
        assert!(ws < 2e-6 && wc < 2e-6, "sin {ws} cos {wc}");
        let mut wa = 0.0f32;
        for _ in 0..200_000 {
            let (y, x) = (
                uniform(&mut noise, -2.0, 2.0),
                uniform(&mut noise, -2.0, 2.0),
            );
            wa = wa.max((atan2(y, x) - y.atan2(x)).abs());
        }
        assert!(wa < 1e-6, "atan2 {wa}");
        for (y, x) in [(0.0, 1.0), (1.0, 0.0), (0.0, -1.0), (-1.0, 0.0), (1.0, 1.0)] {
            assert!((atan2(y, x) - y.atan2(x)).abs() < 1e-6, "{y} {x}");
        }
        assert_eq!(atan2(0.0, 0.0), 0.0);
    }
}
