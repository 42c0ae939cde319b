//! The radio's decoder, `wire::open`, on the bytes as received and sealed with the team key. The body, and what must hold,
//! is `sgm_tests::fuzz_bodies::wire_envelope` (`tests/src/fuzz_bodies.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| sgm_tests::fuzz_bodies::wire_envelope(data));
