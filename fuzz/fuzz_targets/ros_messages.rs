//! Received ROS messages through `bounded::Bounded` and the node's `Inputs` checks. The body, and what must hold,
//! is `sgm_tests::fuzz_bodies::ros_messages` (`tests/src/fuzz_bodies.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| sgm_tests::fuzz_bodies::ros_messages(data));
