//! What the batched lookups of the fast indexes share to run in vectors: a floor that
//! vectorizes, and the CPU check before their AVX2 copies run.
//!
//! Each batched lookup is written once, as portable code without branches in its locating
//! loop, and compiled twice: as is (SSE2 on x86-64) and inside a `#[target_feature(enable =
//! "avx2,bmi1,bmi2,lzcnt,popcnt")]` function called only when [`avx2_detected`] (each such
//! function writes the list out; keep them in step with [`avx2_detected`]). The two run
//! the same IEEE operations in the same order (FMA is not enabled, and Rust never fuses a
//! multiply and an add), so they give the same answers bit for bit; the tests run both.

/// `floor(v)` as u32 for `0 <= v < 2^31`, in operations that vectorize (the saturating `as`
/// conversion does not); other inputs give unspecified values.
#[inline(always)]
pub(super) fn floor_in_range(v: f64) -> u32 {
    // Adding 2^52 rounds to the nearest integer and leaves it in the low bits; one less
    // where that rounded up.
    const SHIFT: f64 = 4_503_599_627_370_496.0;
    let shifted = v + SHIFT;
    let nearest = shifted.to_bits() as u32;
    nearest.wrapping_sub((shifted - SHIFT > v) as u32)
}

/// Whether this CPU has every feature the AVX2 copies are compiled for (cached by std).
#[cfg(target_arch = "x86_64")]
#[inline]
pub(super) fn avx2_detected() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("bmi1")
        && std::arch::is_x86_feature_detected!("bmi2")
        && std::arch::is_x86_feature_detected!("lzcnt")
        && std::arch::is_x86_feature_detected!("popcnt")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_in_range_is_the_floor_on_its_whole_range() {
        let mut values = vec![0.0, 0.25, 0.5, 1.5, 2.5, 3.0, 2f64.powi(31) - 1.0];
        for k in 0..200 {
            let x = k as f64 * 0.37;
            values.extend([x, x.next_up(), (x + 1.0).next_down(), x + 0.5]);
        }
        values.extend([
            1.0f64.next_down(),
            2.0f64.next_down(),
            1e9 + 0.5,
            2147483647.9,
        ]);
        for v in values {
            assert_eq!(floor_in_range(v), v.floor() as u32, "{v}");
        }
    }
}
