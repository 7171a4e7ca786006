//! `mtpcr_core::register` on clouds and settings made from the input bytes never panics (nor
//! crashes), and an `Ok` result has finite transforms. The decoder lives with the regression
//! tests of its crashes (crates/mtpcr-core/tests/common/fuzz_input.rs); a crash found here
//! becomes an entry of `CRASHES` in crates/mtpcr-core/tests/fuzz_register.rs.
//!
//! `MTPCR_FUZZ_PRINT=1 fuzz/target/x86_64-unknown-linux-gnu/release/register ARTIFACT` prints
//! the decoded config and clouds.
#![no_main]

use libfuzzer_sys::fuzz_target;

#[path = "../../crates/mtpcr-core/tests/common/fuzz_input.rs"]
mod fuzz_input;

fuzz_target!(|data: &[u8]| fuzz_input::check(data));
