//! ROS 1 bags (format 2.0): our writer (no maintained one exists on crates.io), the record
//! reader (`records`: uncompressed, bz2 and lz4 chunks, every declared length bounded) and the
//! replay's reader on top of it.

mod format;
pub mod reader;
pub mod records;
pub mod writer;
