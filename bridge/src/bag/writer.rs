//! A ROS 1 bag writer (format 2.0, uncompressed chunks). Layout:
//!
//! ```text
//! "#ROSBAG V2.0\n"
//! bag header record, padded to 4096 bytes (index_pos, conn_count, chunk_count; rewritten at the end)
//! per chunk: chunk record (its connection records and message data records),
//!            then one index data record per connection in it
//! index section (at index_pos): every connection record, then every chunk info record
//! ```
//!
//! A record is `u32 header_len, header, u32 data_len, data`; a header is a list of
//! `u32 field_len, name=value`; integers and times are little-endian (time = sec u32, nsec u32).
//! Checked by Debian's `rosbag info`, `rosbag check` and `rosbag play` (`.ci/run`), and by the
//! `rosbag` crate (tests).

use rosrust::{Message, Time};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{self, BufWriter, Seek, SeekFrom, Write};
use std::path::Path;

use super::format::{MAGIC, OP_BAG_HEADER, OP_CHUNK, OP_CHUNK_INFO, OP_CONNECTION, OP_INDEX_DATA, OP_MESSAGE_DATA};
/// The bag header record's total size (the `rosbag` crate insists on it).
const BAG_HEADER_SIZE: usize = 4096;
/// A chunk is closed once its data passes this many bytes (rosbag's default is 768 KiB).
const CHUNK_BYTES: usize = 768 * 1024;

fn field(out: &mut Vec<u8>, name: &str, value: &[u8]) {
    out.extend_from_slice(&((name.len() + 1 + value.len()) as u32).to_le_bytes());
    out.extend_from_slice(name.as_bytes());
    out.push(b'=');
    out.extend_from_slice(value);
}

fn time_bytes(t: Time) -> [u8; 8] {
    let mut b = [0u8; 8];
    b[..4].copy_from_slice(&t.sec.to_le_bytes());
    b[4..].copy_from_slice(&t.nsec.to_le_bytes());
    b
}

fn record(out: &mut Vec<u8>, header: &[u8], data: &[u8]) {
    out.extend_from_slice(&(header.len() as u32).to_le_bytes());
    out.extend_from_slice(header);
    out.extend_from_slice(&(data.len() as u32).to_le_bytes());
    out.extend_from_slice(data);
}

struct Connection {
    topic: String,
    msg_type: String,
    md5sum: String,
    definition: String,
    /// Recorded from a latched publisher: `rosbag play` republishes it latched.
    latching: bool,
}

impl Connection {
    fn record(&self, id: u32, out: &mut Vec<u8>) {
        let mut header = Vec::new();
        field(&mut header, "op", &[OP_CONNECTION]);
        field(&mut header, "conn", &id.to_le_bytes());
        field(&mut header, "topic", self.topic.as_bytes());
        let mut data = Vec::new();
        field(&mut data, "topic", self.topic.as_bytes());
        field(&mut data, "type", self.msg_type.as_bytes());
        field(&mut data, "md5sum", self.md5sum.as_bytes());
        field(&mut data, "message_definition", self.definition.as_bytes());
        if self.latching {
            field(&mut data, "latching", b"1");
        }
        record(out, &header, &data);
    }
}

struct ChunkInfo {
    position: u64,
    start: Time,
    end: Time,
    counts: BTreeMap<u32, u32>,
}

/// Writes one bag. Messages may come in any order; `rosbag play` plays them by time.
pub struct BagWriter {
    file: BufWriter<File>,
    position: u64,
    connections: Vec<Connection>,
    by_topic: BTreeMap<String, u32>,
    chunk: Vec<u8>,
    /// Per connection of the open chunk: (time, offset in the chunk) of each message.
    chunk_index: BTreeMap<u32, Vec<(Time, u32)>>,
    chunk_span: Option<(Time, Time)>,
    chunks: Vec<ChunkInfo>,
}

impl BagWriter {
    pub fn create(path: &Path) -> io::Result<Self> {
        let mut file = BufWriter::new(File::create(path)?);
        file.write_all(MAGIC)?;
        let mut writer = Self {
            file,
            position: MAGIC.len() as u64,
            connections: Vec::new(),
            by_topic: BTreeMap::new(),
            chunk: Vec::new(),
            chunk_index: BTreeMap::new(),
            chunk_span: None,
            chunks: Vec::new(),
        };
        writer.write_bag_header(0)?;
        Ok(writer)
    }

    fn write_bag_header(&mut self, index_position: u64) -> io::Result<()> {
        let mut header = Vec::new();
        field(&mut header, "op", &[OP_BAG_HEADER]);
        field(&mut header, "index_pos", &index_position.to_le_bytes());
        field(&mut header, "conn_count", &(self.connections.len() as u32).to_le_bytes());
        field(&mut header, "chunk_count", &(self.chunks.len() as u32).to_le_bytes());
        let padding = vec![b' '; BAG_HEADER_SIZE - 8 - header.len()];
        let mut out = Vec::with_capacity(BAG_HEADER_SIZE);
        record(&mut out, &header, &padding);
        self.file.write_all(&out)?;
        self.position = MAGIC.len() as u64 + BAG_HEADER_SIZE as u64;
        Ok(())
    }

    /// Appends `message` on `topic` at `time` (the record time `rosbag play` schedules by).
    pub fn write<M: Message>(&mut self, topic: &str, time: Time, message: &M) -> io::Result<()> {
        self.write_on(topic, time, message, false)
    }

    /// As [`write`](Self::write), on a topic recorded as latched (`/tf_static`): `rosbag play`
    /// republishes it latched, so a node that subscribes late still gets it.
    pub fn write_latched<M: Message>(&mut self, topic: &str, time: Time, message: &M) -> io::Result<()> {
        self.write_on(topic, time, message, true)
    }

    fn write_on<M: Message>(&mut self, topic: &str, time: Time, message: &M, latching: bool) -> io::Result<()> {
        let id = match self.by_topic.get(topic) {
            Some(&id) => {
                if self.connections[id as usize].msg_type != M::msg_type() {
                    return Err(io::Error::new(
                        io::ErrorKind::InvalidInput,
                        format!(
                            "topic {topic} already carries {}, not {}",
                            self.connections[id as usize].msg_type,
                            M::msg_type()
                        ),
                    ));
                }
                id
            }
            None => {
                let id = self.connections.len() as u32;
                self.connections.push(Connection {
                    topic: topic.to_string(),
                    msg_type: M::msg_type(),
                    md5sum: M::md5sum(),
                    definition: M::msg_definition(),
                    latching,
                });
                self.by_topic.insert(topic.to_string(), id);
                id
            }
        };
        if !self.chunk_index.contains_key(&id) {
            // A chunk carries the connection records of the messages in it.
            self.connections[id as usize].record(id, &mut self.chunk);
        }
        let mut data = Vec::new();
        message.encode(&mut data)?;
        let mut header = Vec::new();
        field(&mut header, "op", &[OP_MESSAGE_DATA]);
        field(&mut header, "conn", &id.to_le_bytes());
        field(&mut header, "time", &time_bytes(time));
        let offset = self.chunk.len() as u32;
        record(&mut self.chunk, &header, &data);
        self.chunk_index.entry(id).or_default().push((time, offset));
        self.chunk_span = Some(match self.chunk_span {
            Some((start, end)) => (start.min(time), end.max(time)),
            None => (time, time),
        });
        if self.chunk.len() >= CHUNK_BYTES {
            self.close_chunk()?;
        }
        Ok(())
    }

    fn close_chunk(&mut self) -> io::Result<()> {
        let Some((start, end)) = self.chunk_span.take() else { return Ok(()) };
        let mut out = Vec::with_capacity(self.chunk.len() + 1024);
        let mut header = Vec::new();
        field(&mut header, "op", &[OP_CHUNK]);
        field(&mut header, "compression", b"none");
        field(&mut header, "size", &(self.chunk.len() as u32).to_le_bytes());
        record(&mut out, &header, &self.chunk);
        let mut counts = BTreeMap::new();
        for (id, entries) in std::mem::take(&mut self.chunk_index) {
            let mut header = Vec::new();
            field(&mut header, "op", &[OP_INDEX_DATA]);
            field(&mut header, "ver", &1u32.to_le_bytes());
            field(&mut header, "conn", &id.to_le_bytes());
            field(&mut header, "count", &(entries.len() as u32).to_le_bytes());
            let mut data = Vec::with_capacity(entries.len() * 12);
            for (time, offset) in &entries {
                data.extend_from_slice(&time_bytes(*time));
                data.extend_from_slice(&offset.to_le_bytes());
            }
            record(&mut out, &header, &data);
            counts.insert(id, entries.len() as u32);
        }
        self.chunks.push(ChunkInfo { position: self.position, start, end, counts });
        self.file.write_all(&out)?;
        self.position += out.len() as u64;
        self.chunk.clear();
        Ok(())
    }

    /// Closes the last chunk, writes the index and the final bag header.
    pub fn finish(mut self) -> io::Result<()> {
        self.close_chunk()?;
        let index_position = self.position;
        let mut out = Vec::new();
        for (id, connection) in self.connections.iter().enumerate() {
            connection.record(id as u32, &mut out);
        }
        for chunk in &self.chunks {
            let mut header = Vec::new();
            field(&mut header, "op", &[OP_CHUNK_INFO]);
            field(&mut header, "ver", &1u32.to_le_bytes());
            field(&mut header, "chunk_pos", &chunk.position.to_le_bytes());
            field(&mut header, "start_time", &time_bytes(chunk.start));
            field(&mut header, "end_time", &time_bytes(chunk.end));
            field(&mut header, "count", &(chunk.counts.len() as u32).to_le_bytes());
            let mut data = Vec::new();
            for (id, count) in &chunk.counts {
                data.extend_from_slice(&id.to_le_bytes());
                data.extend_from_slice(&count.to_le_bytes());
            }
            record(&mut out, &header, &data);
        }
        self.file.write_all(&out)?;
        self.file.seek(SeekFrom::Start(MAGIC.len() as u64))?;
        self.write_bag_header(index_position)?;
        self.file.flush()?;
        self.file.get_ref().sync_all()
    }
}
