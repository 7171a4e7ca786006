//! What the batched lookups of the fast indexes share to run in vectors: a floor that
//! vectorizes, and the choice of the widest vectors the CPU runs.
//!
//! Each batched lookup is written once, as portable code without branches in its locating
//! loop, and compiled three times by [`dispatch_by_lanes`]: as is (SSE2 on x86-64), inside a
//! `#[target_feature]` function for AVX2 and inside one for AVX-512 (the x86-64-v4 set). An
//! index picks its copy when it is built ([`Lanes::widest`]); the unsafe call of a copy is
//! sound because an index never holds a [`Lanes`] wider than the CPU's. The macro's feature
//! lists (an attribute takes a literal) must stay equal to the checks of `has_avx2` and
//! `has_avx512` below it.
//! All copies run the same IEEE operations in the same order (Rust never fuses a multiply and
//! an add, even where the CPU has FMA), so they give the same answers bit for bit; the tests
//! run every copy the CPU has.

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

/// The vector width a batched lookup runs in. Ordered from narrowest to widest.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum Lanes {
    /// The code as compiled for the target (SSE2 on x86-64).
    Portable,
    /// Compiled for AVX2 (`has_avx2`).
    Avx2,
    /// Compiled for AVX-512 (`has_avx512`): about 1.2x the AVX2 copy's throughput of
    /// the original loss on an AMD EPYC (`cargo bench --bench fitness`).
    Avx512,
}

/// Whether the CPU has the features of the AVX2 copies (their `#[target_feature]` lists).
#[cfg(target_arch = "x86_64")]
fn has_avx2() -> bool {
    use std::arch::is_x86_feature_detected as has;
    has!("avx2") && has!("bmi1") && has!("bmi2") && has!("lzcnt") && has!("popcnt")
}

/// Whether the CPU has the features of the AVX-512 copies: AVX2's and x86-64-v4's AVX-512
/// (F, BW, CD, DQ, VL).
#[cfg(target_arch = "x86_64")]
fn has_avx512() -> bool {
    use std::arch::is_x86_feature_detected as has;
    has_avx2()
        && has!("avx512f")
        && has!("avx512bw")
        && has!("avx512cd")
        && has!("avx512dq")
        && has!("avx512vl")
}

impl Lanes {
    /// The widest copy this CPU can run (the features are checked by std, once).
    pub(crate) fn widest() -> Lanes {
        #[cfg(target_arch = "x86_64")]
        {
            if has_avx512() {
                return Lanes::Avx512;
            }
            if has_avx2() {
                return Lanes::Avx2;
            }
        }
        Lanes::Portable
    }

    /// `self`, or the widest this CPU runs where that is narrower: what an index may hold
    /// (tests narrow an index's copy with it).
    #[cfg(test)]
    pub(crate) fn on_this_cpu(self) -> Lanes {
        self.min(Lanes::widest())
    }
}

/// `impl $ty { $vis fn $name(&self, args) -> ret }` running `self.$portable(args)` as
/// compiled for `self.lanes` (a [`Lanes`] field the type keeps, never wider than the CPU's):
/// the one place the copies' feature lists and their unsafe calls are written.
macro_rules! dispatch_by_lanes {
    ($ty:ty, $vis:vis fn $name:ident(&self $(, $arg:ident: $arg_ty:ty)*) -> $ret:ty
        => $portable:ident) => {
        impl $ty {
            #[allow(unsafe_code)]
            #[inline]
            $vis fn $name(&self $(, $arg: $arg_ty)*) -> $ret {
                #[cfg(target_arch = "x86_64")]
                #[target_feature(enable = "avx2,bmi1,bmi2,lzcnt,popcnt")]
                unsafe fn avx2(this: &$ty $(, $arg: $arg_ty)*) -> $ret {
                    this.$portable($($arg),*)
                }
                #[cfg(target_arch = "x86_64")]
                #[target_feature(
                    enable = "avx2,bmi1,bmi2,lzcnt,popcnt,avx512f,avx512bw,avx512cd,avx512dq,avx512vl"
                )]
                unsafe fn avx512(this: &$ty $(, $arg: $arg_ty)*) -> $ret {
                    this.$portable($($arg),*)
                }
                // SAFETY: `self.lanes` is never wider than what this CPU runs (`Lanes::widest`
                // at the build, clamped by `with_lanes`), so the CPU has every feature of the
                // copy called.
                match self.lanes {
                    #[cfg(target_arch = "x86_64")]
                    Lanes::Avx512 => unsafe { avx512(self $(, $arg)*) },
                    #[cfg(target_arch = "x86_64")]
                    Lanes::Avx2 => unsafe { avx2(self $(, $arg)*) },
                    _ => self.$portable($($arg),*),
                }
            }
        }
    };
}
pub(crate) use dispatch_by_lanes;

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
