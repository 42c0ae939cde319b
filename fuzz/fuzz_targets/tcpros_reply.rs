//! What a peer sends back to our TCPROS service client (`transport::call::read_reply`). The body, and what must hold,
//! is `sgm_tests::fuzz_bodies::tcpros_reply` (`tests/src/fuzz_bodies.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| sgm_tests::fuzz_bodies::tcpros_reply(data));
