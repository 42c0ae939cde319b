//! CDR messages as each ROS 2 type the replay reads. The body, and what must hold, is
//! `sgm_tests::fuzz_bodies::cdr_messages` (`tests/src/fuzz_bodies.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| sgm_tests::fuzz_bodies::cdr_messages(data));
