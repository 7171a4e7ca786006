//! Regression tests of the `register` fuzz target (fuzz/fuzz_targets/register.rs): every input
//! it crashed on, replayed through the same decoder, plus a sweep of short inputs. Each must
//! give an error or a result with finite transforms, never a panic or a crash.

#[path = "common/fuzz_input.rs"]
mod fuzz_input;

/// Inputs the fuzzer crashed on (minimised), with what went wrong.
const CRASHES: &[(&str, &[u8])] = &[(
    "segfault in nalgebra's LU solve of a 0 x 0 system: refine_poses with one cloud placed \
     of four (order auto, refine_iterations 1)",
    &[91, 10, 99],
)];

#[test]
fn inputs_the_fuzzer_crashed_on() {
    for (what, data) in CRASHES {
        eprintln!("{what}");
        fuzz_input::check(data);
    }
}

#[test]
fn short_inputs() {
    for a in 0..32u8 {
        fuzz_input::check(&[a.wrapping_mul(37), a, 255 - a]);
    }
}
