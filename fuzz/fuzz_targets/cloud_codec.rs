//! Object and keyframe clouds from the radio: `cloud_codec::decode_at_most`. The body, and what must hold,
//! is `sgm_tests::fuzz_bodies::cloud_codec` (`tests/src/fuzz_bodies.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| sgm_tests::fuzz_bodies::cloud_codec(data));
