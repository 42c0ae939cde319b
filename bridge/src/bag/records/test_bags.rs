//! Bags built byte by byte for the record reader's tests, and a reader of them.

use super::{BagLimits, ChunkSection, RecordError};
use crate::bag::format::{MAGIC, OP_BAG_HEADER, OP_CHUNK, OP_CONNECTION, OP_MESSAGE_DATA};

pub(super) fn field_bytes(name: &str, value: &[u8]) -> Vec<u8> {
    let mut out = ((name.len() + 1 + value.len()) as u32).to_le_bytes().to_vec();
    out.extend_from_slice(name.as_bytes());
    out.push(b'=');
    out.extend_from_slice(value);
    out
}

pub(super) fn record(header: &[Vec<u8>], data: &[u8]) -> Vec<u8> {
    let header = header.concat();
    let mut out = (header.len() as u32).to_le_bytes().to_vec();
    out.extend_from_slice(&header);
    out.extend_from_slice(&(data.len() as u32).to_le_bytes());
    out.extend_from_slice(data);
    out
}

/// A bag of `chunks` (records as given), with a correct index_pos unless `index_pos` says.
pub(super) fn bag(chunks: &[Vec<u8>], index_pos: Option<u64>) -> Vec<u8> {
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

pub(super) fn chunk(compression: &str, size: u32, data: &[u8]) -> Vec<u8> {
    record(
        &[
            field_bytes("op", &[OP_CHUNK]),
            field_bytes("compression", compression.as_bytes()),
            field_bytes("size", &size.to_le_bytes()),
        ],
        data,
    )
}

pub(super) fn records() -> Vec<u8> {
    let mut out = record(
        &[field_bytes("op", &[OP_CONNECTION]), field_bytes("conn", &3u32.to_le_bytes()), field_bytes("topic", b"/a")],
        &[field_bytes("topic", b"/a"), field_bytes("type", b"std_msgs/Header"), field_bytes("md5sum", b"x")].concat(),
    );
    let mut time = 2u64.to_le_bytes();
    time[4] = 5;
    out.extend(record(
        &[field_bytes("op", &[OP_MESSAGE_DATA]), field_bytes("conn", &3u32.to_le_bytes()), field_bytes("time", &time)],
        b"hello",
    ));
    out
}

pub(super) fn read(bag: &[u8]) -> Result<Vec<Vec<String>>, RecordError> {
    let mut section = ChunkSection::open(bag, bag.len() as u64, BagLimits::for_messages(1 << 20))?;
    let mut chunks = Vec::new();
    while let Some(chunk) = section.next_chunk()? {
        chunks.push(chunk.records().map(|r| r.map(|r| format!("{r:?}"))).collect::<Result<Vec<_>, _>>()?);
    }
    Ok(chunks)
}
