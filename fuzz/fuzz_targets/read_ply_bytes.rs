//! Any bytes given to the PLY reader give a cloud or an error, never a panic, a hang or an
//! allocation beyond what the input's size justifies.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let _ = mtpcr_core::io::read_ply_bytes(Path::new("fuzz.ply"), data);
});
