//! rosbag2's MCAP storage (`.mcap`, mcap.dev's format), read front to back.
//!
//! ```text
//! magic, header, data section: records (u8 opcode ‖ u64 length ‖ body), among them chunks
//! (header ‖ compression "" | "zstd" | "lz4" ‖ records), summary, footer, magic
//! ```
//!
//! The `mcap` crate's streaming reader hands over the file's records, each within a bound, and
//! parses each record's body. Chunks are taken whole and opened here: decompressed to exactly
//! the size they declare (itself within the bound, the output growing as it is produced), and
//! their records walked with every length checked against the bytes the chunk holds. The
//! crate's own chunk walk trusts an inner record's length in an uncompressed chunk (an overflow
//! that the `rosbag2_mcap` fuzz target found, `fuzz/README.md`). As the ROS 1 reader does with a
//! bag's chunks, each chunk's messages are handed on in log-time order (stable); channels name
//! their topic and encoding, schemas their type (`sensor_msgs/msg/Image`).

use super::StorageRecord;
use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::io::Read;

/// What channels and schemas a file has declared so far.
#[derive(Default)]
struct Declared {
    schemas: BTreeMap<u16, String>,
}

impl Declared {
    /// Hands on a schema or channel record; messages are the caller's.
    fn declare(
        &mut self,
        record: Record,
        visit: &mut dyn FnMut(StorageRecord) -> Result<bool, String>,
    ) -> Result<bool, String> {
        match record {
            Record::Schema { header, .. } => {
                self.schemas.insert(header.id, header.name);
                Ok(true)
            }
            Record::Channel(channel) => {
                let msg_type = match channel.schema_id {
                    0 => "",
                    id => self.schemas.get(&id).map(String::as_str).ok_or_else(|| {
                        format!(
                            "channel {} (topic {}) names schema {id}, not defined before it",
                            channel.id, channel.topic
                        )
                    })?,
                };
                visit(StorageRecord::Topic {
                    id: u32::from(channel.id),
                    name: &channel.topic,
                    msg_type,
                    encoding: &channel.message_encoding,
                })
            }
            _ => Ok(true),
        }
    }
}

/// Reads the MCAP stream `file`, handing each channel and message to `visit` until it returns
/// false. `max_record_bytes` bounds every record and every chunk, compressed and not.
pub fn read_mcap(
    mut file: impl Read,
    max_record_bytes: usize,
    visit: &mut dyn FnMut(StorageRecord) -> Result<bool, String>,
) -> Result<(), String> {
    let options = LinearReaderOptions::default()
        .with_record_length_limit(max_record_bytes)
        .with_emit_chunks(true)
        .with_skip_end_magic(false);
    let mut reader = LinearReader::new_with_options(options);
    let mut declared = Declared::default();
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| format!("not a readable MCAP file: {e}"))? {
            LinearReadEvent::ReadRequest(need) => {
                let read = file.read(reader.insert(need)).map_err(|e| format!("cannot read: {e}"))?;
                if read == 0 {
                    return Err("the MCAP file ends before its footer (cut short?)".into());
                }
                reader.notify_read(read);
            }
            LinearReadEvent::Record { opcode, data } => {
                let record = mcap::parse_record(opcode, data).map_err(|e| format!("a record does not parse: {e}"))?;
                let go = match record {
                    Record::Chunk { header, data } => {
                        let records =
                            decompress(&header.compression, &data, header.uncompressed_size, max_record_bytes)?;
                        read_chunk(&records, &mut declared, visit)?
                    }
                    Record::Message { header, data } => visit(StorageRecord::Message {
                        topic: u32::from(header.channel_id),
                        time_nanos: header.log_time,
                        data: &data,
                    })?,
                    other => declared.declare(other, visit)?,
                };
                if !go {
                    return Ok(());
                }
            }
        }
    }
    Ok(())
}

/// A chunk's records, decompressed to exactly the `size` it declares (at most `max` bytes).
fn decompress<'a>(compression: &str, data: &'a [u8], size: u64, max: usize) -> Result<Cow<'a, [u8]>, String> {
    if size > max as u64 {
        return Err(format!("a chunk declares {size} bytes uncompressed, at most {max} accepted"));
    }
    let mut decoder: Box<dyn Read + 'a> = match compression {
        "" => {
            if data.len() as u64 != size {
                return Err(format!("an uncompressed chunk declares {size} bytes and holds {}", data.len()));
            }
            return Ok(Cow::Borrowed(data));
        }
        "zstd" => Box::new(zstd::stream::read::Decoder::new(data).map_err(|e| format!("zstd chunk: {e}"))?),
        "lz4" => Box::new(lz4::Decoder::new(data).map_err(|e| format!("lz4 chunk: {e}"))?),
        other => return Err(format!("chunk compression `{other}` (none, zstd or lz4 expected)")),
    };
    let mut out = Vec::new();
    decoder.by_ref().take(size + 1).read_to_end(&mut out).map_err(|e| format!("{compression} chunk: {e}"))?;
    if out.len() as u64 != size {
        return Err(format!("a {compression} chunk declares {size} bytes uncompressed and holds {}", out.len()));
    }
    Ok(Cow::Owned(out))
}

/// Walks a chunk's records: schemas and channels handed on at once, messages in log-time order
/// after them.
fn read_chunk(
    mut rest: &[u8],
    declared: &mut Declared,
    visit: &mut dyn FnMut(StorageRecord) -> Result<bool, String>,
) -> Result<bool, String> {
    let mut messages = Vec::new();
    while !rest.is_empty() {
        let Some((head, body)) = rest.split_first_chunk::<9>() else {
            return Err(format!("a chunk ends inside a record's header ({} bytes left)", rest.len()));
        };
        let opcode = head[0];
        let mut len = [0u8; 8];
        len.copy_from_slice(&head[1..]);
        let len = u64::from_le_bytes(len);
        if len > body.len() as u64 {
            return Err(format!("a record in a chunk declares {len} bytes, {} left in the chunk", body.len()));
        }
        let (body, after) = body.split_at(len as usize);
        rest = after;
        match mcap::parse_record(opcode, body).map_err(|e| format!("a record in a chunk does not parse: {e}"))? {
            Record::Message { header, data } => messages.push((header.log_time, header.channel_id, data)),
            other => {
                if !declared.declare(other, visit)? {
                    return Ok(false);
                }
            }
        }
    }
    messages.sort_by_key(|m| m.0);
    for (time_nanos, channel, data) in &messages {
        if !visit(StorageRecord::Message { topic: u32::from(*channel), time_nanos: *time_nanos, data })? {
            return Ok(false);
        }
    }
    Ok(true)
}
