//! Recordings for the replay: ROS 1 bags (format 2.0) — our writer (no maintained one exists on
//! crates.io) and the record reader (`records`: uncompressed, bz2 and lz4 chunks, every declared
//! length bounded) — and ROS 2 recordings (`rosbag2`: MCAP and sqlite3 storage, their `cdr`
//! messages decoded within bounds), read by one reader (`reader`) chosen by what the path holds.

pub mod cdr;
mod format;
pub mod reader;
pub mod records;
pub mod rosbag2;
pub mod writer;
