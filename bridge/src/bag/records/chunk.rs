//! The records inside a decompressed chunk: connections and messages, in order.

use super::error::RecordError;
use super::header::{field, field_u32, field_u64, fields, op};
use crate::bag::format::{OP_CONNECTION, OP_MESSAGE_DATA};

/// A chunk's records, decompressed.
pub struct Chunk {
    /// Where the chunk record starts in the bag.
    pub at: u64,
    pub(super) data: Vec<u8>,
}

/// A record inside a chunk.
#[derive(Clone, Debug, PartialEq)]
pub enum ChunkRecord<'a> {
    /// A connection: messages with `conn == id` are of `msg_type` on `topic`.
    Connection { id: u32, topic: String, msg_type: String, md5sum: String },
    /// A message of connection `conn`, recorded at `time_nanos` (nanoseconds since 1970).
    Message { conn: u32, time_nanos: u64, data: &'a [u8] },
}

impl Chunk {
    /// The chunk's records in order; the first malformed one ends them with its error.
    pub fn records(&self) -> ChunkRecords<'_> {
        ChunkRecords { chunk: self, rest: &self.data, failed: false }
    }
}

/// Iterator over a chunk's records.
pub struct ChunkRecords<'a> {
    chunk: &'a Chunk,
    rest: &'a [u8],
    failed: bool,
}

impl<'a> ChunkRecords<'a> {
    /// Where in the chunk's data the next record starts (for errors).
    fn offset(&self) -> u64 {
        (self.chunk.data.len() - self.rest.len()) as u64
    }

    /// `u32 len ‖ len bytes` of `what`.
    fn counted(&mut self, what: &'static str) -> Result<&'a [u8], RecordError> {
        let at = self.offset();
        let malformed = |message: String| RecordError::Malformed { at: self.chunk.at, message };
        let Some((len, tail)) = self.rest.split_first_chunk::<4>() else {
            return Err(malformed(format!("{what} length at byte {at} of its data ends early")));
        };
        let len = u32::from_le_bytes(*len) as usize;
        let Some(bytes) = tail.get(..len) else {
            return Err(malformed(format!(
                "{what} at byte {at} of its data declares {len} bytes, {} left",
                tail.len()
            )));
        };
        self.rest = &tail[len..];
        Ok(bytes)
    }

    fn record(&mut self) -> Result<ChunkRecord<'a>, RecordError> {
        let at = self.chunk.at;
        let header = self.counted("a record header")?;
        let data = self.counted("a record's data")?;
        let header = fields(header, at)?;
        match op(&header, at)? {
            OP_CONNECTION => {
                let id = field_u32(&header, "conn", at)?;
                let body = fields(data, at)?;
                let text = |name: &str| {
                    field(&body, name).or_else(|| field(&header, name)).map(|v| String::from_utf8_lossy(v).into_owned())
                };
                let missing =
                    |name: &str| RecordError::Malformed { at, message: format!("connection {id} has no `{name}`") };
                Ok(ChunkRecord::Connection {
                    id,
                    topic: text("topic").ok_or_else(|| missing("topic"))?,
                    msg_type: text("type").ok_or_else(|| missing("type"))?,
                    md5sum: text("md5sum").ok_or_else(|| missing("md5sum"))?,
                })
            }
            OP_MESSAGE_DATA => {
                let conn = field_u32(&header, "conn", at)?;
                let time = field_u64(&header, "time", at)?;
                // sec u32, nsec u32: at most 4.3 × 10¹⁸ ns, within u64.
                let time_nanos = (time & 0xFFFF_FFFF) * 1_000_000_000 + (time >> 32);
                Ok(ChunkRecord::Message { conn, time_nanos, data })
            }
            op => Err(RecordError::Malformed {
                at,
                message: format!("op {op:#04x} inside a chunk (connections and messages expected)"),
            }),
        }
    }
}

impl<'a> Iterator for ChunkRecords<'a> {
    type Item = Result<ChunkRecord<'a>, RecordError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed || self.rest.is_empty() {
            return None;
        }
        let record = self.record();
        self.failed = record.is_err();
        Some(record)
    }
}

#[cfg(test)]
mod tests {
    use crate::bag::format::OP_INDEX_DATA;
    use crate::bag::records::test_bags::{bag, chunk, field_bytes, read, record, records};

    #[test]
    fn chunks_and_their_records_read_in_order() {
        let records = records();
        let index = record(&[field_bytes("op", &[OP_INDEX_DATA])], &[0; 12]);
        let bag = bag(&[chunk("none", records.len() as u32, &records), index], None);
        let chunks = read(&bag).unwrap();
        assert_eq!(chunks.len(), 1);
        assert_eq!(chunks[0][0], "Connection { id: 3, topic: \"/a\", msg_type: \"std_msgs/Header\", md5sum: \"x\" }");
        assert!(chunks[0][1].starts_with("Message { conn: 3, time_nanos: 2000000005, data: [104,"), "{}", chunks[0][1]);
    }
}
