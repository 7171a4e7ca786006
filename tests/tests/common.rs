//! Helpers shared by the integration tests (included with `mod common;`).
#![allow(dead_code)]

use std::path::PathBuf;

/// The `shared/` folder beside the checkout, or `$MTPCR_SHARED_DIR`; `None` (with the reason
/// printed) when it is absent, so real-data tests skip instead of failing.
pub fn shared_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("MTPCR_SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"));
    if dir.join("problems").is_dir() && dir.join("data").is_dir() {
        Some(dir)
    } else {
        eprintln!(
            "SKIPPED: no shared data at {} (set MTPCR_SHARED_DIR to the folder holding problems/ and data/)",
            dir.display()
        );
        None
    }
}
