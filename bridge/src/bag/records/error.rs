//! Where a bag's bytes are not a bag, or not one within bounds.

use std::io;

/// Where a bag's bytes are not a bag, or not one within bounds.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("{0}")]
    Io(#[from] io::Error),
    #[error("not a ROS 1 bag (format 2.0): it does not start with \"#ROSBAG V2.0\"")]
    NotABag,
    #[error("the file ends inside {what} at byte {at}")]
    Truncated { what: &'static str, at: u64 },
    #[error("{what} at byte {at} declares {len} bytes, at most {max} accepted")]
    TooLarge { what: &'static str, at: u64, len: u64, max: u64 },
    #[error("record at byte {at}: {message}")]
    Malformed { at: u64, message: String },
    #[error(
        "the bag header's index_pos {index_pos} is outside the file (its records start at byte {start}, it has \
         {len} bytes): a bag whose recording was cut off has no index, `rosbag reindex` writes one"
    )]
    NoIndex { index_pos: u64, start: u64, len: u64 },
    #[error("chunk at byte {at}: {compression} data does not decompress: {message}")]
    Decompress { at: u64, compression: &'static str, message: String },
    #[error("chunk at byte {at} declares {declared} bytes uncompressed, holds {found}")]
    SizeMismatch { at: u64, declared: u64, found: u64 },
}
