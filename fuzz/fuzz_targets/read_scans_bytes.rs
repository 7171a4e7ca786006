//! Any bytes given to the format-detecting reader give scans or an error, never a panic, a
//! hang or an allocation beyond what the input's size justifies. The first byte picks the file
//! name's extension (which decides the format when the content has no signature); the rest is
//! the file.
#![no_main]

use libfuzzer_sys::fuzz_target;

const NAMES: [&str; 10] = [
    "fuzz.xyz", "fuzz.pts", "fuzz.csv", "fuzz.txt", "fuzz.ply", "fuzz.pcd", "fuzz.e57", "fuzz.las",
    "fuzz.laz", "fuzz.bin",
];

fuzz_target!(|data: &[u8]| {
    let Some((&pick, bytes)) = data.split_first() else {
        return;
    };
    let name = NAMES[pick as usize % NAMES.len()];
    let _ = mtpcr_core::io::read_scans_bytes(name, bytes);
});
