//! The ROS 1 bag format 2.0's constants, shared by the writer and the record reader
//! (<http://wiki.ros.org/Bags/Format/2.0>): the file's first line and each record's `op`.

pub const MAGIC: &[u8] = b"#ROSBAG V2.0\n";
pub const OP_MESSAGE_DATA: u8 = 0x02;
pub const OP_BAG_HEADER: u8 = 0x03;
pub const OP_INDEX_DATA: u8 = 0x04;
pub const OP_CHUNK: u8 = 0x05;
pub const OP_CHUNK_INFO: u8 = 0x06;
pub const OP_CONNECTION: u8 = 0x07;
