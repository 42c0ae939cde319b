//! rosbag2's MCAP storage (`.mcap`, mcap.dev's format), read front to back.
//!
//! ```text
//! magic, header, data section: records (u8 opcode ‖ u64 length ‖ body), among them chunks
//! (header ‖ compression "" | "zstd" | "lz4" ‖ records), summary, footer, magic
//! ```
//!
//! The `mcap` crate's streaming reader frames the file: magic, footer, and each record's opcode
//! and body, every body within a bound before it is buffered. The bodies SGM needs (schema,
//! channel, message, chunk) are parsed here ([`McapRecord`]), every string's and byte array's
//! length checked against the bytes the record holds; chunks are decompressed to exactly the
//! size they declare (within the bound, the output growing as it is produced) and their records
//! walked the same way. The `rosbag2_mcap` fuzz target found the crate's own parsing trusting
//! declared lengths: its chunk walk subtracts an inner record's length from an uncompressed
//! chunk's remaining size (an overflow), and its string fields reserve what they declare (3.5 GB
//! for a chunk's compression name) (`fuzz/README.md`). As the ROS 1 reader does with a bag's
//! chunks, each chunk's messages are handed on in log-time order (stable); channels name their
//! topic and encoding, schemas their type (`sensor_msgs/msg/Image`).

use super::StorageRecord;
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
        record: McapRecord,
        visit: &mut dyn FnMut(StorageRecord) -> Result<bool, String>,
    ) -> Result<bool, String> {
        match record {
            McapRecord::Schema { id, name } => {
                self.schemas.insert(id, name.to_string());
                Ok(true)
            }
            McapRecord::Channel { id, schema_id, topic, encoding } => {
                let msg_type = match schema_id {
                    0 => "",
                    schema => self.schemas.get(&schema).map(String::as_str).ok_or_else(|| {
                        format!("channel {id} (topic {topic}) names schema {schema}, not defined before it")
                    })?,
                };
                visit(StorageRecord::Topic { id: u32::from(id), name: topic, msg_type, encoding })
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
                let go = match McapRecord::parse(opcode, data)? {
                    McapRecord::Chunk { uncompressed_size, compression, records } => {
                        let records = decompress(compression, records, uncompressed_size, max_record_bytes)?;
                        read_chunk(&records, &mut declared, visit)?
                    }
                    McapRecord::Message { channel, log_time, data } => {
                        visit(StorageRecord::Message { topic: u32::from(channel), time_nanos: log_time, data })?
                    }
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
        match McapRecord::parse(opcode, body)? {
            McapRecord::Message { channel, log_time, data } => messages.push((log_time, channel, data)),
            McapRecord::Chunk { .. } => return Err("a chunk inside a chunk".into()),
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

/// The records SGM reads, parsed from their bodies (mcap.dev, "Records"); the others are
/// `Other`.
#[derive(Debug, PartialEq)]
enum McapRecord<'a> {
    /// op 0x03: id u16, name string, encoding string, data bytes.
    Schema {
        id: u16,
        name: &'a str,
    },
    /// op 0x04: id u16, schema_id u16, topic string, message_encoding string, metadata map.
    Channel {
        id: u16,
        schema_id: u16,
        topic: &'a str,
        encoding: &'a str,
    },
    /// op 0x05: channel_id u16, sequence u32, log_time u64, publish_time u64, data (the rest).
    Message {
        channel: u16,
        log_time: u64,
        data: &'a [u8],
    },
    /// op 0x06: start and end time u64, uncompressed_size u64, uncompressed_crc u32,
    /// compression string, records (u64 length).
    Chunk {
        uncompressed_size: u64,
        compression: &'a str,
        records: &'a [u8],
    },
    Other,
}

/// A cursor over one record's body; every length checked against the bytes left.
struct Body<'a> {
    bytes: &'a [u8],
    what: &'static str,
}

impl<'a> Body<'a> {
    fn take(&mut self, field: &str, n: u64) -> Result<&'a [u8], String> {
        if n > self.bytes.len() as u64 {
            return Err(format!("{} record: `{field}` needs {n} bytes, {} left", self.what, self.bytes.len()));
        }
        let (head, rest) = self.bytes.split_at(n as usize);
        self.bytes = rest;
        Ok(head)
    }

    fn fixed<const N: usize>(&mut self, field: &str) -> Result<[u8; N], String> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(field, N as u64)?);
        Ok(out)
    }

    fn u16(&mut self, field: &str) -> Result<u16, String> {
        self.fixed(field).map(u16::from_le_bytes)
    }

    fn u32(&mut self, field: &str) -> Result<u32, String> {
        self.fixed(field).map(u32::from_le_bytes)
    }

    fn u64(&mut self, field: &str) -> Result<u64, String> {
        self.fixed(field).map(u64::from_le_bytes)
    }

    /// A u32-prefixed byte array.
    fn bytes(&mut self, field: &str) -> Result<&'a [u8], String> {
        let n = self.u32(field)?;
        self.take(field, u64::from(n))
    }

    fn string(&mut self, field: &str) -> Result<&'a str, String> {
        let what = self.what;
        std::str::from_utf8(self.bytes(field)?).map_err(|_| format!("{what} record: `{field}` is not UTF-8"))
    }
}

impl<'a> McapRecord<'a> {
    fn parse(opcode: u8, bytes: &'a [u8]) -> Result<Self, String> {
        Ok(match opcode {
            0x03 => {
                let mut b = Body { bytes, what: "schema" };
                let id = b.u16("id")?;
                let name = b.string("name")?;
                b.string("encoding")?;
                b.bytes("data")?;
                McapRecord::Schema { id, name }
            }
            0x04 => {
                let mut b = Body { bytes, what: "channel" };
                let (id, schema_id) = (b.u16("id")?, b.u16("schema_id")?);
                let (topic, encoding) = (b.string("topic")?, b.string("message_encoding")?);
                b.bytes("metadata")?;
                McapRecord::Channel { id, schema_id, topic, encoding }
            }
            0x05 => {
                let mut b = Body { bytes, what: "message" };
                let channel = b.u16("channel_id")?;
                b.u32("sequence")?;
                let log_time = b.u64("log_time")?;
                b.u64("publish_time")?;
                McapRecord::Message { channel, log_time, data: b.bytes }
            }
            0x06 => {
                let mut b = Body { bytes, what: "chunk" };
                b.u64("message_start_time")?;
                b.u64("message_end_time")?;
                let uncompressed_size = b.u64("uncompressed_size")?;
                b.u32("uncompressed_crc")?;
                let compression = b.string("compression")?;
                let len = b.u64("records")?;
                let records = b.take("records", len)?;
                McapRecord::Chunk { uncompressed_size, compression, records }
            }
            _ => McapRecord::Other,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn string(s: &str) -> Vec<u8> {
        let mut v = (s.len() as u32).to_le_bytes().to_vec();
        v.extend_from_slice(s.as_bytes());
        v
    }

    #[test]
    fn records_parse_field_by_field_and_refuse_lengths_beyond_their_bytes() {
        let mut channel = [7u16.to_le_bytes(), 2u16.to_le_bytes()].concat();
        channel.extend(string("/alpha/points"));
        channel.extend(string("cdr"));
        channel.extend(0u32.to_le_bytes());
        assert_eq!(
            McapRecord::parse(0x04, &channel),
            Ok(McapRecord::Channel { id: 7, schema_id: 2, topic: "/alpha/points", encoding: "cdr" })
        );
        let mut message = [3u16.to_le_bytes().to_vec(), 9u32.to_le_bytes().to_vec()].concat();
        message.extend(42u64.to_le_bytes());
        message.extend(41u64.to_le_bytes());
        message.extend([1, 2, 3]);
        assert_eq!(
            McapRecord::parse(0x05, &message),
            Ok(McapRecord::Message { channel: 3, log_time: 42, data: &[1, 2, 3] })
        );
        // A chunk whose compression name declares 3.5 GB: refused, not reserved.
        let mut chunk = vec![0u8; 28];
        chunk.extend(3_529_762_959u32.to_le_bytes());
        chunk.extend(b"zstd");
        let e = McapRecord::parse(0x06, &chunk).unwrap_err();
        assert_eq!(e, "chunk record: `compression` needs 3529762959 bytes, 4 left");
        assert_eq!(McapRecord::parse(0x0B, &[1, 2]), Ok(McapRecord::Other));
    }
}
