//! `f32` numbers from files and devices, widened to `f64` as the decimals they were written as.

/// `x` as the shortest decimal that reads back as the same `f32`, in `f64`: 0.1 gives 0.1,
/// where `f64::from` gives 0.10000000149011612 (a key time of 2.4 s would be reported as
/// 2.4000000953674316 s). NaN and the infinities stay what they are.
pub fn widen_as_written(x: f32) -> f64 {
    // `Display` writes the shortest decimal that round-trips, and `f64`'s parser reads every
    // string it writes ("NaN" and "inf" included); the fallback is only a guard.
    x.to_string().parse().unwrap_or(f64::from(x))
}

/// `a − b` for two decimals read from `f32` numbers (by [`widen_as_written`]), rounded to the
/// nine significant digits that an `f32` holds: 2.7 − 0.3 gives 2.4, where the `f64`
/// subtraction gives 2.4000000000000004 (and 2.4 − 0.3 in `f32` gives 2.1000001). Non-finite
/// differences stay what they are.
pub fn difference_as_written(a: f64, b: f64) -> f64 {
    let d = a - b;
    if !d.is_finite() {
        return d;
    }
    // `{:.8e}` rounds to nine significant digits; `f64`'s parser reads every such string.
    format!("{d:.8e}").parse().unwrap_or(d)
}

#[cfg(test)]
mod tests {
    use super::{difference_as_written, widen_as_written};

    #[test]
    fn differences_of_written_decimals_come_out_as_written() {
        let w = widen_as_written;
        assert_eq!(difference_as_written(w(2.4), w(0.3)), 2.1);
        assert_eq!(difference_as_written(w(2.7), w(0.3)), 2.4);
        assert_eq!(difference_as_written(w(0.3), w(2.4)), -2.1);
        assert_eq!(difference_as_written(w(1.0), w(1.0)), 0.0);
        assert_eq!(difference_as_written(w(3.75), w(0.125)), 3.625);
        // Nine significant digits are kept, not rounded away.
        assert_eq!(difference_as_written(w(2.4), w(1e-8)), 2.39999999);
        assert_eq!(
            difference_as_written(w(1.234_567_9), w(0.1)),
            1.1345679,
            "digits a file can write"
        );
        assert!(difference_as_written(f64::INFINITY, 1.0).is_infinite());
        assert!(difference_as_written(f64::NAN, 1.0).is_nan());
        assert_ne!(2.7 - 0.3, 2.4, "the plain subtraction is what this avoids");
    }

    #[test]
    fn written_decimals_come_back_as_written() {
        assert_eq!(widen_as_written(0.1), 0.1);
        assert_eq!(widen_as_written(2.4), 2.4);
        assert_eq!(widen_as_written(-3.75), -3.75);
        assert_ne!(
            f64::from(2.4f32),
            2.4,
            "the plain widening is what this avoids"
        );
    }

    #[test]
    fn every_value_reads_back_as_the_same_f32() {
        let specials = [
            0.0,
            -0.0,
            f32::MIN_POSITIVE,
            1e-45, // the smallest subnormal
            f32::MAX,
            f32::MIN,
            f32::EPSILON,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ];
        // A spread of bit patterns over the whole range as well.
        let spread = (0..4096u32).map(|k| f32::from_bits(k.wrapping_mul(1_048_573)));
        for x in specials.into_iter().chain(spread) {
            let w = widen_as_written(x);
            if x.is_nan() {
                assert!(w.is_nan(), "{x:?} gave {w}");
            } else {
                assert_eq!((w as f32).to_bits(), x.to_bits(), "{x:?} gave {w}");
            }
        }
    }
}
