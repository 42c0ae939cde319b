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

use std::io::{self, Read};

use super::format::{MAGIC, OP_BAG_HEADER, OP_CHUNK, OP_CONNECTION, OP_INDEX_DATA, OP_MESSAGE_DATA};
/// Largest record header accepted, bytes. The headers of a bag's records hold a few short
/// fields (a connection's topic is the longest); rosbag writes them well under 1 KiB.
pub const MAX_RECORD_HEADER_BYTES: u32 = 1 << 20;

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

/// A record header's fields, as `(name, value)`.
type Fields<'a> = Vec<(&'a [u8], &'a [u8])>;

/// The `name=value` fields of a record header.
fn fields(header: &[u8], at: u64) -> Result<Fields<'_>, RecordError> {
    let malformed = |message: String| RecordError::Malformed { at, message };
    let mut fields = Vec::new();
    let mut rest = header;
    while !rest.is_empty() {
        let Some((len, tail)) = rest.split_first_chunk::<4>() else {
            return Err(malformed(format!("its header ends inside a field length ({} bytes left)", rest.len())));
        };
        let len = u32::from_le_bytes(*len) as usize;
        let Some(field) = tail.get(..len) else {
            return Err(malformed(format!("a header field of {len} bytes, {} left", tail.len())));
        };
        let Some(equals) = field.iter().position(|&b| b == b'=') else {
            return Err(malformed(format!("header field {:?} has no `=`", String::from_utf8_lossy(field))));
        };
        fields.push((&field[..equals], &field[equals + 1..]));
        rest = &tail[len..];
    }
    Ok(fields)
}

/// The value of `name` among `fields` (the last one if repeated).
fn field<'a>(fields: &[(&[u8], &'a [u8])], name: &str) -> Option<&'a [u8]> {
    fields.iter().rev().find(|(n, _)| *n == name.as_bytes()).map(|(_, v)| *v)
}

fn field_u32(fields: &[(&[u8], &[u8])], name: &'static str, at: u64) -> Result<u32, RecordError> {
    let value =
        field(fields, name).ok_or_else(|| RecordError::Malformed { at, message: format!("no `{name}` field") })?;
    let bytes: [u8; 4] = value.try_into().map_err(|_| RecordError::Malformed {
        at,
        message: format!("`{name}` has {} bytes, 4 expected", value.len()),
    })?;
    Ok(u32::from_le_bytes(bytes))
}

fn field_u64(fields: &[(&[u8], &[u8])], name: &'static str, at: u64) -> Result<u64, RecordError> {
    let value =
        field(fields, name).ok_or_else(|| RecordError::Malformed { at, message: format!("no `{name}` field") })?;
    let bytes: [u8; 8] = value.try_into().map_err(|_| RecordError::Malformed {
        at,
        message: format!("`{name}` has {} bytes, 8 expected", value.len()),
    })?;
    Ok(u64::from_le_bytes(bytes))
}

fn op(fields: &[(&[u8], &[u8])], at: u64) -> Result<u8, RecordError> {
    match field(fields, "op") {
        Some([op]) => Ok(*op),
        Some(v) => Err(RecordError::Malformed { at, message: format!("`op` has {} bytes, 1 expected", v.len()) }),
        None => Err(RecordError::Malformed { at, message: "no `op` field".into() }),
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

/// `data` of a chunk compressed with `compression`, decompressed to exactly `size` bytes: the
/// output grows as it is produced and stops one byte past `size`.
fn decompress(compression: &[u8], data: Vec<u8>, size: u64, at: u64) -> Result<Vec<u8>, RecordError> {
    let (name, mut decoder): (&'static str, Box<dyn Read + '_>) = match compression {
        b"none" => {
            if data.len() as u64 != size {
                return Err(RecordError::SizeMismatch { at, declared: size, found: data.len() as u64 });
            }
            return Ok(data);
        }
        b"bz2" => ("bz2", Box::new(bzip2::read::BzDecoder::new(&data[..]))),
        b"lz4" => {
            let decoder = lz4::Decoder::new(&data[..]).map_err(|e| RecordError::Decompress {
                at,
                compression: "lz4",
                message: e.to_string(),
            })?;
            ("lz4", Box::new(decoder))
        }
        other => {
            return Err(RecordError::Malformed {
                at,
                message: format!("compression {:?} (none, bz2 or lz4 expected)", String::from_utf8_lossy(other)),
            })
        }
    };
    let mut out = Vec::new();
    decoder.by_ref().take(size.saturating_add(1)).read_to_end(&mut out).map_err(|e| RecordError::Decompress {
        at,
        compression: name,
        message: e.to_string(),
    })?;
    if out.len() as u64 != size {
        return Err(RecordError::SizeMismatch { at, declared: size, found: out.len() as u64 });
    }
    Ok(out)
}

/// A chunk's records, decompressed.
pub struct Chunk {
    /// Where the chunk record starts in the bag.
    pub at: u64,
    data: Vec<u8>,
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
    use super::*;

    fn field_bytes(name: &str, value: &[u8]) -> Vec<u8> {
        let mut out = ((name.len() + 1 + value.len()) as u32).to_le_bytes().to_vec();
        out.extend_from_slice(name.as_bytes());
        out.push(b'=');
        out.extend_from_slice(value);
        out
    }

    fn record(header: &[Vec<u8>], data: &[u8]) -> Vec<u8> {
        let header = header.concat();
        let mut out = (header.len() as u32).to_le_bytes().to_vec();
        out.extend_from_slice(&header);
        out.extend_from_slice(&(data.len() as u32).to_le_bytes());
        out.extend_from_slice(data);
        out
    }

    /// A bag of `chunks` (records as given), with a correct index_pos unless `index_pos` says.
    fn bag(chunks: &[Vec<u8>], index_pos: Option<u64>) -> Vec<u8> {
        let head = |index_pos: u64| {
            let mut out = MAGIC.to_vec();
            out.extend(record(
                &[
                    field_bytes("op", &[OP_BAG_HEADER]),
                    field_bytes("index_pos", &index_pos.to_le_bytes()),
                    field_bytes("conn_count", &1u32.to_le_bytes()),
                    field_bytes("chunk_count", &1u32.to_le_bytes()),
                ],
                &[b' '; 4],
            ));
            out
        };
        let section: Vec<u8> = chunks.concat();
        let mut out = head(index_pos.unwrap_or((head(0).len() + section.len()) as u64));
        out.extend(section);
        out
    }

    fn chunk(compression: &str, size: u32, data: &[u8]) -> Vec<u8> {
        record(
            &[
                field_bytes("op", &[OP_CHUNK]),
                field_bytes("compression", compression.as_bytes()),
                field_bytes("size", &size.to_le_bytes()),
            ],
            data,
        )
    }

    fn records() -> Vec<u8> {
        let mut out = record(
            &[
                field_bytes("op", &[OP_CONNECTION]),
                field_bytes("conn", &3u32.to_le_bytes()),
                field_bytes("topic", b"/a"),
            ],
            &[field_bytes("topic", b"/a"), field_bytes("type", b"std_msgs/Header"), field_bytes("md5sum", b"x")]
                .concat(),
        );
        let mut time = 2u64.to_le_bytes();
        time[4] = 5;
        out.extend(record(
            &[
                field_bytes("op", &[OP_MESSAGE_DATA]),
                field_bytes("conn", &3u32.to_le_bytes()),
                field_bytes("time", &time),
            ],
            b"hello",
        ));
        out
    }

    fn read(bag: &[u8]) -> Result<Vec<Vec<String>>, RecordError> {
        let mut section = ChunkSection::open(bag, bag.len() as u64, BagLimits::for_messages(1 << 20))?;
        let mut chunks = Vec::new();
        while let Some(chunk) = section.next_chunk()? {
            chunks.push(chunk.records().map(|r| r.map(|r| format!("{r:?}"))).collect::<Result<Vec<_>, _>>()?);
        }
        Ok(chunks)
    }

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

    #[test]
    fn compressed_chunks_decompress_to_their_declared_size() {
        let records = records();
        let mut bz2 = Vec::new();
        let mut encoder = bzip2::read::BzEncoder::new(&records[..], bzip2::Compression::best());
        encoder.read_to_end(&mut bz2).unwrap();
        let mut lz4 = lz4::EncoderBuilder::new().build(Vec::new()).unwrap();
        io::Write::write_all(&mut lz4, &records).unwrap();
        let (lz4, result) = lz4.finish();
        result.unwrap();
        let size = records.len() as u32;
        for data in [chunk("bz2", size, &bz2), chunk("lz4", size, &lz4)] {
            assert_eq!(read(&bag(&[data], None)).unwrap().len(), 1);
        }
        let e = read(&bag(&[chunk("bz2", size + 1, &bz2)], None)).unwrap_err().to_string();
        assert!(e.contains("uncompressed, holds"), "{e}");
        let e = read(&bag(&[chunk("lz4", size - 1, &lz4)], None)).unwrap_err().to_string();
        assert!(e.contains("uncompressed, holds"), "{e}");
        let e = read(&bag(&[chunk("zip", size, &records)], None)).unwrap_err().to_string();
        assert!(e.contains("compression \"zip\""), "{e}");
    }

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
