//! ROS 1 bags through the replay's reader (`bag::reader`). The body, and what must hold,
//! is `sgm_tests::fuzz_bodies::rosbag` (`tests/src/fuzz_bodies.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| sgm_tests::fuzz_bodies::rosbag(data));
