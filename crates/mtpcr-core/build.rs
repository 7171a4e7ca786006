//! Tells the integration tests whether the shared data (`../shared`, or `$MTPCR_SHARED_DIR`)
//! is there: with it, `cfg(shared_data)` is set and `MTPCR_SHARED_DIR_FOUND` names the folder;
//! without it, the real-data tests are compiled as ignored, with the reason, instead of
//! passing without testing anything.

include!("src/eval/shared.rs");

fn main() {
    println!("cargo::rustc-check-cfg=cfg(shared_data)");
    println!("cargo::rerun-if-env-changed=MTPCR_SHARED_DIR");
    println!("cargo::rerun-if-changed=build.rs");
    let manifest =
        std::path::PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    if let Some(dir) = find_shared_dir_from(&manifest) {
        println!("cargo::rustc-cfg=shared_data");
        println!("cargo::rustc-env=MTPCR_SHARED_DIR_FOUND={}", dir.display());
        // Rebuild when the data goes away.
        println!("cargo::rerun-if-changed={}", dir.join("problems").display());
    }
}
