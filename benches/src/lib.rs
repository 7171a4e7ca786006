//! Inputs shared by the criterion benchmarks in `benches/benches/`.

use mtpcr_core::eval::problem::Problem;
use mtpcr_core::eval::shared::find_shared_dir;
use mtpcr_core::{synthetic, PointCloud};

/// The three bunny-a scans from the shared data (`mtpcr_core::eval::shared`) and the label
/// `"bunny-a"`; without the data, a bunny-size synthetic problem (40,000 points per view)
/// labelled `"synthetic-40k"`, and a note on stderr.
pub fn bunny_a_or_synthetic() -> (Vec<PointCloud>, &'static str) {
    let Some(shared) = find_shared_dir() else {
        eprintln!("no shared data found; benchmarking a synthetic 40k-point problem");
        return (synthetic::three_views(1, 40_000).clouds, "synthetic-40k");
    };
    let file = shared.join("problems/bunny-a.json");
    match Problem::load(&file, None).and_then(|p| p.read_scans()) {
        Ok(clouds) => (clouds, "bunny-a"),
        Err(e) => {
            eprintln!("bunny-a not available ({e}); benchmarking a synthetic 40k-point problem");
            (synthetic::three_views(1, 40_000).clouds, "synthetic-40k")
        }
    }
}
