//! The records of a ROS 1 bag (format 2.0, ROS wiki "Bags/Format/2.0"), read in file order
//! from any `Read` and within bounds: what the replay's reader ([`super::reader`]) walks.
//!
//! ```text
//! "#ROSBAG V2.0\n", bag header record (op 0x03: index_pos, conn_count, chunk_count),
//! chunk section: chunk records (op 0x05: compression none | bz2 | lz4, size; data: connection
//!                records (op 0x07) and message data records (op 0x02)), index data records
//!                (op 0x04) after each chunk,
//! index section from index_pos (connection and chunk info records; not needed to replay).
//! ```
//!
//! A record is `u32 header_len ‖ header ‖ u32 data_len ‖ data`; a header is a list of
//! `u32 field_len ‖ name=value`. Only the chunk section is read, record after record, so a
//! bag costs one chunk's memory at a time. The `rosbag` crate, which the reader used before,
//! mapped the file and sliced it at the declared `index_pos` (a panic when the bag's recording
//! was cut off and `index_pos` is still 0, or when it lies beyond the file), and reserved the
//! uncompressed size a chunk declares before decompressing (4 GB for a 60-byte chunk): the
//! `rosbag` fuzz target found both (`fuzz/README.md`). Here every length is checked against
//! the bytes the bag has left before anything is read, a chunk's uncompressed size against
//! [`BagLimits::max_chunk_bytes`], and decompression stops at the declared size.
//!
//! [`ChunkSection`] (`section.rs`) reads the bag header and then chunk after chunk, within
//! [`BagLimits`]; `decompress.rs` inflates a chunk to its declared size; [`Chunk`]
//! (`chunk.rs`) iterates the connection and message records inside; `header.rs` parses a
//! record header's fields; every failure is a [`RecordError`] (`error.rs`) naming the byte.

mod chunk;
mod decompress;
mod error;
mod header;
mod section;

pub use chunk::{Chunk, ChunkRecord, ChunkRecords};
pub use error::RecordError;
pub use section::{BagLimits, ChunkSection, MAX_RECORD_HEADER_BYTES};

#[cfg(test)]
mod test_bags;
