//! `f32` numbers from files and devices, widened to `f64` as the decimals they were written as.

/// `x` as the shortest decimal that reads back as the same `f32`, in `f64`: 0.1 gives 0.1,
/// where `f64::from` gives 0.10000000149011612 (a key time of 2.4 s would be reported as
/// 2.4000000953674316 s). NaN and the infinities stay what they are.
pub fn widen_as_written(x: f32) -> f64 {
    // `Display` writes the shortest decimal that round-trips, and `f64`'s parser reads every
    // string it writes ("NaN" and "inf" included); the fallback is only a guard.
    x.to_string().parse().unwrap_or(f64::from(x))
}

#[cfg(test)]
mod tests {
    use super::widen_as_written;

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
