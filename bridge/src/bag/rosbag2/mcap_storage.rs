//! rosbag2's MCAP storage (`.mcap`, mcap.dev's format): read front to back by the `mcap` crate's
//! streaming reader, chunks decompressed (zstd, lz4) as they come, so a file costs one record's
//! memory at a time, and every record's declared length is checked against a bound before it is
//! buffered. Channels name their topic and encoding, schemas their type (`sensor_msgs/msg/Image`).
//! Messages come in file order: what `ros2 bag record` wrote as they arrived.

use super::StorageRecord;
use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
use std::collections::BTreeMap;
use std::io::Read;

/// Reads the MCAP stream `file`, handing each channel and message to `visit` until it returns
/// false. `max_record_bytes` bounds every record, compressed or not (a chunk is streamed, not
/// buffered whole).
pub fn read_mcap(
    mut file: impl Read,
    max_record_bytes: usize,
    visit: &mut dyn FnMut(StorageRecord) -> Result<bool, String>,
) -> Result<(), String> {
    let options = LinearReaderOptions::default()
        .with_record_length_limit(max_record_bytes)
        .with_validate_chunk_crcs(true)
        .with_skip_end_magic(false);
    let mut reader = LinearReader::new_with_options(options);
    let mut schemas: BTreeMap<u16, String> = BTreeMap::new();
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
                match mcap::parse_record(opcode, data).map_err(|e| format!("a record does not parse: {e}"))? {
                    Record::Schema { header, .. } => {
                        schemas.insert(header.id, header.name);
                    }
                    Record::Channel(channel) => {
                        let msg_type = match channel.schema_id {
                            0 => "",
                            id => schemas.get(&id).map(String::as_str).ok_or_else(|| {
                                format!(
                                    "channel {} (topic {}) names schema {id}, not defined before it",
                                    channel.id, channel.topic
                                )
                            })?,
                        };
                        let topic = StorageRecord::Topic {
                            id: u32::from(channel.id),
                            name: &channel.topic,
                            msg_type,
                            encoding: &channel.message_encoding,
                        };
                        if !visit(topic)? {
                            return Ok(());
                        }
                    }
                    Record::Message { header, data } => {
                        let message = StorageRecord::Message {
                            topic: u32::from(header.channel_id),
                            time_nanos: header.log_time,
                            data: &data,
                        };
                        if !visit(message)? {
                            return Ok(());
                        }
                    }
                    _ => {}
                }
            }
        }
    }
    Ok(())
}
