//! ROS 2 recordings' sqlite3 storage through the replay's reader. The body, and what must hold,
//! is `sgm_tests::fuzz_bodies::rosbag2_sqlite` (`tests/src/fuzz_bodies.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| sgm_tests::fuzz_bodies::rosbag2_sqlite(data));
