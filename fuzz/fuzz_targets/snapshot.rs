//! Robot snapshots on disk, whole and (framed with a correct checksum) their contents. The body, and what must hold,
//! is `sgm_tests::fuzz_bodies::snapshot` (`tests/src/fuzz_bodies.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| sgm_tests::fuzz_bodies::snapshot(data));
