//! A chunk's data, decompressed (`none`, `bz2` or `lz4`) to exactly the size it declares: the
//! output grows as it is produced and stops one byte past it, so a chunk that declares 4 GB
//! costs what it holds, not what it declares.

use super::error::RecordError;
use std::io::Read;

/// `data` of a chunk compressed with `compression`, decompressed to exactly `size` bytes: the
/// output grows as it is produced and stops one byte past `size`.
pub(super) fn decompress(compression: &[u8], data: Vec<u8>, size: u64, at: u64) -> Result<Vec<u8>, RecordError> {
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

#[cfg(test)]
mod tests {
    use crate::bag::records::test_bags::{bag, chunk, read, records};
    use std::io::{self, Read};

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
}
