//! Regression tests of the `register` fuzz target (fuzz/fuzz_targets/register.rs): every input
//! it crashed on, replayed through the same decoder, plus a sweep of short inputs. Each must
//! give an error or a result with finite transforms, never a panic or a crash.

#[path = "common/fuzz_input.rs"]
mod fuzz_input;

/// Inputs the fuzzer crashed on (minimised), or that crashed the engine through this decoder
/// (the issue-23 ones: found by running the decoder's scenes against the unfixed engine),
/// with what went wrong.
const CRASHES: &[(&str, &[u8])] = &[
    (
        "segfault in nalgebra's LU solve of a 0 x 0 system: refine_poses with one cloud placed \
         of four (order auto, refine_iterations 1)",
        &[91, 10, 99],
    ),
    (
        "MFEA panicked (mfea.rs best_of: no member with a cost) on NaN costs: a cloud at 1e50 \
         overflowed the f32 distance field; coordinates beyond 1e30 are now refused",
        &[4, 43, 39],
    ),
    ("the same MFEA panic, on another input", &[67, 237, 249]),
    (
        "issue 23: multiview.rs panicked (refine_placed, expect(\"placed\")): scans verified \
         among themselves in a group apart from scan 1 kept their spanning-tree pairs, which \
         the refinement met with both scans unplaced (9 scans in no known order, one group \
         apart; refine_iterations 1)",
        &[47, 0, 0],
    ),
    (
        "issue 23 without refinement: the same pairs reached the measurement (measure, \
         expect(\"placed\")); 7 scans, refine_iterations 0",
        &[29, 0, 0],
    ),
];

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

/// Replays the fuzzer's input files named in `MTPCR_FUZZ_REPLAY` (separated by `:`), printing
/// each one's config, cloud sizes, outcome and time, in a plain release build:
/// `MTPCR_FUZZ_REPLAY=fuzz/artifacts/register/crash-... cargo test -p mtpcr-core --release
/// --test fuzz_register -- --ignored --nocapture`.
#[test]
#[ignore = "set MTPCR_FUZZ_REPLAY to the input files"]
fn replay() {
    let files = std::env::var_os("MTPCR_FUZZ_REPLAY")
        .expect("set MTPCR_FUZZ_REPLAY to the fuzzer's input files (separated by `:`)");
    for file in std::env::split_paths(&files) {
        let data = std::fs::read(&file).unwrap();
        let (config, clouds) = fuzz_input::decode(&data);
        let sizes: Vec<usize> = clouds.iter().map(|c| c.len()).collect();
        println!(
            "{}: {data:?}\n  {config:?}\n  points {sizes:?}",
            file.display()
        );
        let start = std::time::Instant::now();
        let outcome = std::panic::catch_unwind(|| mtpcr_core::register(&clouds, &config, None));
        println!(
            "  {:.2} s: {}",
            start.elapsed().as_secs_f64(),
            match &outcome {
                Ok(Ok(r)) => format!("ok, {} edges, unplaced {:?}", r.edges.len(), r.unplaced),
                Ok(Err(e)) => format!("error: {e}"),
                Err(_) => "panicked".to_string(),
            }
        );
        fuzz_input::check(&data);
    }
}
