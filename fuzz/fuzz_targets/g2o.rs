//! g2o pose graphs (`sgm optimize`): `read_g2o` on one or two files. The body, and what must hold,
//! is `sgm_tests::fuzz_bodies::g2o` (`tests/src/fuzz_bodies.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| sgm_tests::fuzz_bodies::g2o(data));
