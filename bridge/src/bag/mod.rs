//! ROS 1 bags (format 2.0): our writer (no maintained one exists on crates.io) and the reader
//! the replay uses (the `rosbag` crate: uncompressed, bz2 and lz4 chunks).

pub mod reader;
pub mod writer;
