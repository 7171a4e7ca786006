//! Inputs shared by the criterion benchmarks in `benches/benches/`.

use mtpcr_core::eval::problem::Problem;
use mtpcr_core::eval::shared::find_shared_dir;
use mtpcr_core::{synthetic, PointCloud};

/// The three bunny-a scans from the shared data (`mtpcr_core::eval::shared`) and the label
/// `"bunny-a"`; without the data, a bunny-size synthetic problem (40,000 points per view)
/// labelled `"synthetic-40k"`, and a note on stderr.
pub fn bunny_a_or_synthetic() -> (Vec<PointCloud>, &'static str) {
    shared_or(
        "problems/bunny-a.json",
        "bunny-a",
        || synthetic::three_views(1, 40_000).clouds,
        "synthetic-40k",
    )
}

/// The 15 dragon stand scans (`problems-nview/dragon-all.json`, in ring order) and the
/// label `"dragon-all"`; without the data, 15 synthetic views of 40,000 points around one
/// shape, labelled `"synthetic-15x40k"`.
pub fn dragon_all_or_synthetic() -> (Vec<PointCloud>, &'static str) {
    shared_or(
        "problems-nview/dragon-all.json",
        "dragon-all",
        || synthetic::views_around(1, 15, 40_000).clouds,
        "synthetic-15x40k",
    )
}

/// The scans of the shared problem file `problem` (labelled `label`), else `fallback()`
/// (labelled `fallback_label`) with a note on stderr saying why.
fn shared_or(
    problem: &str,
    label: &'static str,
    fallback: impl Fn() -> Vec<PointCloud>,
    fallback_label: &'static str,
) -> (Vec<PointCloud>, &'static str) {
    let Some(shared) = find_shared_dir() else {
        eprintln!("no shared data found; benchmarking {fallback_label}");
        return (fallback(), fallback_label);
    };
    match Problem::load(shared.join(problem), None).and_then(|p| p.read_scans()) {
        Ok(clouds) => (clouds, label),
        Err(e) => {
            eprintln!("{label} not available ({e}); benchmarking {fallback_label}");
            (fallback(), fallback_label)
        }
    }
}
