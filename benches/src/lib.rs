//! Inputs shared by the criterion benchmarks in `benches/benches/`.

use mtpcr_core::io::Problem;
use mtpcr_core::{synthetic, PointCloud};
use std::path::PathBuf;

/// The three bunny-a scans from `../shared` (or `$MTPCR_SHARED_DIR`) and the label
/// `"bunny-a"`; without the data, a bunny-size synthetic problem (40,000 points per view)
/// labelled `"synthetic-40k"`, and a note on stderr.
pub fn bunny_a_or_synthetic() -> ([PointCloud; 3], &'static str) {
    let shared = std::env::var_os("MTPCR_SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"));
    let file = shared.join("problems/bunny-a.json");
    match Problem::load(&file, None).and_then(|p| p.read_scans()) {
        Ok(clouds) => (clouds, "bunny-a"),
        Err(e) => {
            eprintln!("bunny-a not available ({e}); benchmarking a synthetic 40k-point problem");
            (synthetic::three_views(1, 40_000).clouds, "synthetic-40k")
        }
    }
}
