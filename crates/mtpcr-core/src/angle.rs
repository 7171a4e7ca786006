//! Angles for binning: an `atan2` within [`ATAN2_APPROX_ERROR`] at a fraction of libm's cost.
//! Callers that bin an angle use it where the angle is clear of every bin edge by more than
//! the error, and libm's `atan2` (or `asin`) elsewhere, so the bins are exactly those libm's
//! angle gives.

/// The largest difference between [`atan2_approx`] and `atan2` (radians), with room to spare:
/// the polynomial's own error is 1e-5 (Abramowitz and Stegun 4.4.49).
pub(crate) const ATAN2_APPROX_ERROR: f64 = 2e-5;

/// `atan2(y, x)` within [`ATAN2_APPROX_ERROR`]: NaN where the ratio of the smaller to the larger
/// of `|x|` and `|y|` is (both 0, both infinite, or a NaN), the sign of `y` kept.
#[inline]
pub(crate) fn atan2_approx(y: f64, x: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, PI};
    let (ay, ax) = (y.abs(), x.abs());
    // NaN stays NaN here (unlike through `min` and `max`).
    let z = if ay > ax { ax / ay } else { ay / ax };
    let z2 = z * z;
    let atan_z = z
        * (0.999_866_0
            + z2 * (-0.330_299_5 + z2 * (0.180_141_0 + z2 * (-0.085_133_0 + z2 * 0.020_835_1))));
    // atan(|y| / |x|) in the first quadrant, then reflected into y's and x's.
    let first = if ay > ax { FRAC_PI_2 - atan_z } else { atan_z };
    let half = if x < 0.0 { PI - first } else { first };
    if y.is_sign_negative() {
        -half
    } else {
        half
    }
}

/// Is `x` (an angle divided by a bin width `width`) farther than twice the approximation's
/// error from every integer, i.e. from every bin edge? False for NaN.
#[inline]
pub(crate) fn clear_of_edges(x: f64, width: f64) -> bool {
    (x - x.round()).abs() * width > 2.0 * ATAN2_APPROX_ERROR
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn the_approximation_is_within_its_error_of_atan2() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut worst = 0.0f64;
        for _ in 0..200_000 {
            let scale = 10f64.powi(rng.random_range(-3..4));
            let (y, x) = (
                rng.random_range(-1.0..1.0) * scale,
                rng.random_range(-1.0..1.0) * scale,
            );
            worst = worst.max((atan2_approx(y, x) - y.atan2(x)).abs());
        }
        for (y, x) in [
            (0.0, 1.0),
            (1.0, 0.0),
            (0.0, -1.0),
            (-1.0, 0.0),
            (1.0, 1.0),
            (-1.0, -1.0),
        ] {
            worst = worst.max((atan2_approx(y, x) - f64::atan2(y, x)).abs());
        }
        assert!(worst < ATAN2_APPROX_ERROR / 1.5, "{worst}");
        assert!(
            worst > 1e-7,
            "{worst}: the test would not see a worse polynomial"
        );
        assert!(atan2_approx(0.0, 0.0).is_nan());
        assert!(!clear_of_edges(f64::NAN, 0.1));
        assert!(clear_of_edges(3.5, 0.1) && !clear_of_edges(3.0001, 0.1));
    }
}
