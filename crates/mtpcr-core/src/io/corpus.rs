//! The readers' regression corpus: valid files of every format (also the fuzzers' seeds) and
//! malformed ones, all generated here; no file is committed. Every malformed file must give an
//! error, and no mutation of a valid one may panic.
//!
//! `MTPCR_FUZZ_SEEDS=DIR cargo test -p mtpcr-core --lib io::corpus` also writes the valid files
//! into `DIR` (as `scripts/fuzz.sh` does for the fuzzers' corpora).

use super::*;
use std::path::PathBuf;

/// A fresh temporary file name: tests call [`seeds`] concurrently.
fn tmp(name: &str) -> PathBuf {
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("mtpcr-io-corpus-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(format!("{call}-{name}"))
}

/// Valid files: name (its extension matters for text formats), bytes, points per scan.
pub(crate) fn seeds() -> Vec<(String, Vec<u8>, Vec<usize>)> {
    let mut out = Vec::new();
    out.push((
        "stanford.ply".to_string(),
        ply::tests::STANFORD.as_bytes().to_vec(),
        vec![3],
    ));
    let path = tmp("seed-binary.ply");
    write_ply(
        &path,
        &[[1.0, 2.0, 3.0], [-4.0, 5.5, 1e-3]],
        Some(&[[1, 2, 3], [4, 5, 6]]),
    )
    .unwrap();
    out.push(("binary.ply".into(), std::fs::read(&path).unwrap(), vec![2]));
    let few: Vec<[f32; 3]> = pcd::tests::sample().into_iter().take(20).collect();
    for (name, kind) in [
        ("ascii.pcd", pcd_rs::DataKind::Ascii),
        ("binary.pcd", pcd_rs::DataKind::Binary),
        ("compressed.pcd", pcd_rs::DataKind::BinaryCompressed),
    ] {
        let path = tmp(&format!("seed-{name}"));
        pcd::tests::write_pcd(&path, kind, &few);
        out.push((name.into(), std::fs::read(&path).unwrap(), vec![20]));
    }
    let scans = e57::tests::sample_scans();
    let path = tmp("seed-three.e57");
    e57::tests::write_e57(&path, &scans);
    out.push((
        "three.e57".into(),
        std::fs::read(&path).unwrap(),
        vec![40, 38, 40],
    ));
    let pts: Vec<[f64; 3]> = las::tests::sample().into_iter().take(30).collect();
    out.push((
        "small.las".into(),
        las::tests::write_las(&pts, false),
        vec![30],
    ));
    out.push((
        "small.laz".into(),
        las::tests::write_las(&pts, true),
        vec![30],
    ));
    out.push((
        "rows.xyz".into(),
        b"# comment\n1 2 3\n4 5 6 7\n\n-1e3 0.5 inf\n".to_vec(),
        vec![3],
    ));
    out.push((
        "table.csv".into(),
        b"x,y,z,i\n1,2,3,4\n5,6,7,8\n".to_vec(),
        vec![2],
    ));
    out.push((
        "blocks.pts".into(),
        b"2\n1 2 3 4\n5 6 7 8\n1\n9 9 9 0\n".to_vec(),
        vec![3],
    ));
    out
}

/// Malformed files (name, bytes): every one must give an error.
pub(crate) fn malformed() -> Vec<(String, Vec<u8>)> {
    let mut out: Vec<(String, Vec<u8>)> = Vec::new();
    for (name, bytes, _) in ply::tests::malformed_cases() {
        out.push((name.to_string(), bytes));
    }
    for (name, bytes, _) in pcd::tests::malformed_cases() {
        out.push((name.to_string(), bytes));
    }
    for (name, text, _, _) in xyz::tests::malformed_cases() {
        out.push((name.to_string(), text.as_bytes().to_vec()));
    }
    let seeds = seeds();
    let find = |n: &str| seeds.iter().find(|s| s.0 == n).unwrap().1.clone();
    let e57 = find("three.e57");
    out.push(("head.e57".into(), e57[..48].to_vec()));
    out.push(("cut.e57".into(), e57[..e57.len() / 2].to_vec()));
    let mut flipped = e57.clone();
    flipped[1100] ^= 0x55;
    out.push(("crc.e57".into(), flipped));
    let las = find("small.las");
    out.push(("cut.las".into(), las[..las.len() - 7].to_vec()));
    out.push(("head.las".into(), las[..100].to_vec()));
    let mut lying = las.clone();
    lying[107..111].copy_from_slice(&u32::MAX.to_le_bytes());
    out.push(("count.las".into(), lying));
    let laz = find("small.laz");
    out.push(("cut.laz".into(), laz[..laz.len() - 20].to_vec()));
    // Found by the corpus test: a LAZ item size that does not match the record length made
    // laz panic (slice split out of range).
    let mut items = laz.clone();
    items[317] = 2;
    out.push(("items.laz".into(), items));
    // Found by the corpus test: a chunk count of 4 G made laz reserve 29 GB.
    let mut chunks = laz.clone();
    let data_start = u32::from_le_bytes(laz[96..100].try_into().unwrap()) as usize;
    let table = i64::from_le_bytes(laz[data_start..data_start + 8].try_into().unwrap()) as usize;
    chunks[table + 4..table + 8].copy_from_slice(&u32::MAX.to_le_bytes());
    out.push(("chunks.laz".into(), chunks));
    // Found by the fuzzer: LAZ with variable-size chunks (chunk size u32::MAX in the LASzip
    // record, at offset 281 + 12 here) whose chunk table does not cover the points made laz
    // index out of bounds; and the same with the point-wise (unchunked) compressor made it
    // reach its "no chunk table" panic.
    let mut variable = laz.clone();
    variable[293..297].copy_from_slice(&u32::MAX.to_le_bytes());
    out.push(("variable.laz".into(), variable.clone()));
    variable[281..283].copy_from_slice(&1u16.to_le_bytes());
    out.push(("variable-pointwise.laz".into(), variable));
    out.push(("unknown.bin".into(), b"\x00\x01 no signature".to_vec()));
    out.push(("noext".into(), b"1 2 3\n".to_vec()));
    out
}

#[test]
fn seeds_read_back_with_their_points() {
    let dir = std::env::var_os("MTPCR_FUZZ_SEEDS").map(PathBuf::from);
    for (name, bytes, counts) in seeds() {
        let scans = read_scans_bytes(&name, &bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
        let got: Vec<usize> = scans.iter().map(|s| s.cloud.len()).collect();
        assert_eq!(got, counts, "{name}");
        if let Some(dir) = &dir {
            std::fs::create_dir_all(dir).unwrap();
            std::fs::write(dir.join(&name), &bytes).unwrap();
        }
    }
}

/// Runs `read_scans_bytes`, turning a panic into a description.
fn no_panic(name: &str, bytes: &[u8]) -> std::result::Result<Result<Vec<Scan>>, String> {
    std::panic::catch_unwind(|| read_scans_bytes(name, bytes)).map_err(|p| {
        let what = p
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_default();
        format!("{name}: panicked: {what}")
    })
}

#[test]
fn every_malformed_file_gives_an_error_that_names_it() {
    let mut wrong = Vec::new();
    for (name, bytes) in malformed() {
        match no_panic(&name, &bytes) {
            Ok(Err(e)) => {
                let msg = e.to_string();
                if !msg.contains(&name) || msg.contains('\n') {
                    wrong.push(format!("{name}: message `{msg}`"));
                }
            }
            Ok(Ok(scans)) => wrong.push(format!("{name}: read {} scans", scans.len())),
            Err(panic) => wrong.push(panic),
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

#[test]
fn no_truncation_or_byte_flip_of_a_valid_file_panics() {
    let mut panics = Vec::new();
    for (name, bytes, _) in seeds() {
        let n = bytes.len();
        for cut in (0..n).step_by((n / 97).max(1)) {
            if let Err(p) = no_panic(&name, &bytes[..cut]) {
                panics.push(format!("cut at {cut}: {p}"));
            }
        }
        let mut state = 0x9e37_79b9_7f4a_7c15u64 ^ n as u64;
        for _ in 0..300 {
            // xorshift: deterministic positions and values.
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let mut mutated = bytes.clone();
            let at = (state % n as u64) as usize;
            mutated[at] = (state >> 32) as u8;
            if let Err(p) = no_panic(&name, &mutated) {
                panics.push(format!("byte {at} set to {}: {p}", (state >> 32) as u8));
            }
        }
    }
    assert!(panics.is_empty(), "{}", panics.join("\n"));
}
