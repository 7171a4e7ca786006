//! Helpers shared by the integration tests (included with `mod common;`).
#![allow(dead_code)]

use std::path::PathBuf;

/// Why a real-data test is ignored: set by `build.rs` when the shared data is absent.
pub const NO_SHARED_DATA: &str =
    "needs the shared data (../shared or $MTPCR_SHARED_DIR with problems/ and data/), not found at build time";

/// The shared data folder found at build time (real-data tests are ignored without it).
pub fn shared_dir() -> PathBuf {
    match option_env!("MTPCR_SHARED_DIR_FOUND") {
        Some(dir) => PathBuf::from(dir),
        None => panic!("{NO_SHARED_DATA}"),
    }
}
