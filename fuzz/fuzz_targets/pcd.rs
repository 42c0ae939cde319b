//! PCD files (ascii, binary, binary_compressed): `pcd::read_pcd`. The body, and what must hold,
//! is `sgm_tests::fuzz_bodies::pcd` (`tests/src/fuzz_bodies.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| sgm_tests::fuzz_bodies::pcd(data));
