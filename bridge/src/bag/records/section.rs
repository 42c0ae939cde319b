//! A bag's chunk section, read in file order from any `Read`: the version line and the bag
//! header, then record after record, every declared length checked against the bytes the bag
//! has left and against [`BagLimits`] before anything is read.

use super::chunk::Chunk;
use super::decompress::decompress;
use super::error::RecordError;
use super::header::{field, field_u32, field_u64, fields, op};
use crate::bag::format::{MAGIC, OP_BAG_HEADER, OP_CHUNK, OP_INDEX_DATA};
use std::io::{self, Read};

/// Largest record header accepted, bytes. The headers of a bag's records hold a few short
/// fields (a connection's topic is the longest); rosbag writes them well under 1 KiB.
pub const MAX_RECORD_HEADER_BYTES: u32 = 1 << 20;

/// Bounds on what one bag may make the reader hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BagLimits {
    /// Largest chunk accepted, bytes, compressed or not. A recorder closes a chunk once it
    /// passes its chunk size (rosbag's default 768 KiB), so a chunk is at most that plus one
    /// message: the replay allows `ros.max_message_bytes` plus 64 MiB.
    pub max_chunk_bytes: u64,
}

impl BagLimits {
    /// Room for chunk sizes up to 64 MiB on top of one message of `max_message_bytes`.
    pub fn for_messages(max_message_bytes: usize) -> Self {
        Self { max_chunk_bytes: (max_message_bytes as u64).saturating_add(64 << 20) }
    }
}

/// A record's header and the length of its data, which is not read yet.
struct RecordHead {
    at: u64,
    header: Vec<u8>,
    data_len: u64,
}

/// A bag's chunk section, read record by record from `reader`.
pub struct ChunkSection<R> {
    reader: R,
    /// Bytes read so far: the position in the bag.
    at: u64,
    /// Where the chunk section ends (the bag header's `index_pos`).
    end: u64,
    limits: BagLimits,
}

impl<R: Read> ChunkSection<R> {
    /// Reads the version line and the bag header of a bag of `len` bytes.
    pub fn open(reader: R, len: u64, limits: BagLimits) -> Result<Self, RecordError> {
        let mut section = Self { reader, at: 0, end: len, limits };
        let mut magic = [0u8; MAGIC.len()];
        if len < MAGIC.len() as u64 || section.read_exact(&mut magic, "the version line").is_err() || magic != MAGIC {
            return Err(RecordError::NotABag);
        }
        let head = section.head()?;
        let fields = fields(&head.header, head.at)?;
        if op(&fields, head.at)? != OP_BAG_HEADER {
            return Err(RecordError::Malformed {
                at: head.at,
                message: "the first record is not the bag header".into(),
            });
        }
        let index_pos = field_u64(&fields, "index_pos", head.at)?;
        // The header's data is padding.
        section.skip(head.data_len)?;
        if index_pos < section.at || index_pos > len {
            return Err(RecordError::NoIndex { index_pos, start: section.at, len });
        }
        section.end = index_pos;
        Ok(section)
    }

    fn read_exact(&mut self, buffer: &mut [u8], what: &'static str) -> Result<(), RecordError> {
        match self.reader.read_exact(buffer) {
            Ok(()) => {
                self.at += buffer.len() as u64;
                Ok(())
            }
            Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => Err(RecordError::Truncated { what, at: self.at }),
            Err(e) => Err(RecordError::Io(e)),
        }
    }

    fn read_u32(&mut self, what: &'static str) -> Result<u32, RecordError> {
        let mut b = [0u8; 4];
        self.read_exact(&mut b, what)?;
        Ok(u32::from_le_bytes(b))
    }

    /// `len` bytes of `what`, which must be within `max` and what the section has left.
    fn read_vec(&mut self, len: u64, max: u64, what: &'static str) -> Result<Vec<u8>, RecordError> {
        if len > max {
            return Err(RecordError::TooLarge { what, at: self.at, len, max });
        }
        if len > self.end.saturating_sub(self.at) {
            return Err(RecordError::Truncated { what, at: self.at });
        }
        let mut bytes = vec![0u8; len as usize];
        self.read_exact(&mut bytes, what)?;
        Ok(bytes)
    }

    /// Reads past `len` bytes without keeping them.
    fn skip(&mut self, len: u64) -> Result<(), RecordError> {
        if len > self.end.saturating_sub(self.at) {
            return Err(RecordError::Truncated { what: "a record's data", at: self.at });
        }
        let copied = io::copy(&mut self.reader.by_ref().take(len), &mut io::sink())?;
        self.at += copied;
        if copied < len {
            return Err(RecordError::Truncated { what: "a record's data", at: self.at });
        }
        Ok(())
    }

    /// A record's header, and its data length (checked against the bytes left).
    fn head(&mut self) -> Result<RecordHead, RecordError> {
        let at = self.at;
        let header_len = self.read_u32("a record's header length")?;
        let header = self.read_vec(u64::from(header_len), u64::from(MAX_RECORD_HEADER_BYTES), "a record header")?;
        let data_len = u64::from(self.read_u32("a record's data length")?);
        if data_len > self.end.saturating_sub(self.at) {
            return Err(RecordError::Truncated { what: "a record's data", at: self.at });
        }
        Ok(RecordHead { at, header, data_len })
    }

    /// The next chunk, decompressed; `None` where the chunk section ends. Index data records
    /// between chunks are passed over.
    pub fn next_chunk(&mut self) -> Result<Option<Chunk>, RecordError> {
        while self.at < self.end {
            let head = self.head()?;
            let fields = fields(&head.header, head.at)?;
            match op(&fields, head.at)? {
                OP_CHUNK => {
                    let compression = field(&fields, "compression").ok_or_else(|| RecordError::Malformed {
                        at: head.at,
                        message: "a chunk without `compression`".into(),
                    })?;
                    let size = u64::from(field_u32(&fields, "size", head.at)?);
                    let max = self.limits.max_chunk_bytes;
                    if size > max {
                        return Err(RecordError::TooLarge { what: "a chunk", at: head.at, len: size, max });
                    }
                    let data = self.read_vec(head.data_len, max, "a chunk")?;
                    let data = decompress(compression, data, size, head.at)?;
                    return Ok(Some(Chunk { at: head.at, data }));
                }
                OP_INDEX_DATA => self.skip(head.data_len)?,
                op => {
                    return Err(RecordError::Malformed {
                        at: head.at,
                        message: format!("op {op:#04x} in the chunk section (chunks and index data expected)"),
                    })
                }
            }
        }
        Ok(None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bag::records::test_bags::{bag, chunk, read, records};

    #[test]
    fn a_bag_without_its_index_is_refused_by_name() {
        let records = records();
        let e = read(&bag(&[chunk("none", records.len() as u32, &records)], Some(0))).unwrap_err().to_string();
        assert!(e.contains("index_pos 0 is outside the file") && e.contains("rosbag reindex"), "{e}");
        let e = read(&bag(&[], Some(1 << 40))).unwrap_err().to_string();
        assert!(e.contains("index_pos 1099511627776"), "{e}");
    }

    #[test]
    fn declared_sizes_are_checked_before_anything_is_reserved() {
        // A chunk declaring 4 GB uncompressed: refused by the limit, not reserved.
        let e = read(&bag(&[chunk("bz2", u32::MAX, b"BZh9")], None)).unwrap_err().to_string();
        assert!(e.contains("a chunk at byte") && e.contains("declares 4294967295 bytes"), "{e}");
        // A record whose data runs past the end of the chunk section.
        let mut section = chunk("none", 4, b"abcd");
        section.truncate(section.len() - 2);
        let e = read(&bag(&[section], None)).unwrap_err().to_string();
        assert!(e.contains("ends inside a record's data"), "{e}");
        // A record header beyond the limit.
        let mut huge = (MAX_RECORD_HEADER_BYTES + 1).to_le_bytes().to_vec();
        huge.extend_from_slice(&[0; 8]);
        let e = read(&bag(&[huge], None)).unwrap_err().to_string();
        assert!(e.contains("a record header at byte"), "{e}");
        assert!(matches!(read(b"#ROSBAG V1.2\n"), Err(RecordError::NotABag)));
        assert!(matches!(read(b""), Err(RecordError::NotABag)));
    }
}
