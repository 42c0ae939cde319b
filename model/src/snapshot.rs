//! The snapshot file format: any serde value framed for storage on disk, so that a robot's map
//! survives a crash (DESIGN.md §3, "freeze and thaw"). The frame says what it holds and proves
//! that it is whole:
//!
//! ```text
//! offset  size  field
//!      0     8  magic "SGMSNAP\0"
//!      8     4  format version, u32 little-endian (FORMAT_VERSION)
//!     12     4  kind, u32 little-endian (what the payload is; the caller names it)
//!     16     8  payload length in bytes, u64 little-endian
//!     24    32  BLAKE3 hash of the payload
//!     56     …  payload: lz4 block (uncompressed size first, u32 LE) of the postcard encoding
//! ```
//!
//! Decoding checks, in order: the magic, the version, the kind, the length against the bytes
//! present (a truncated file is named as such), the hash ([`verify`] stops here), the
//! uncompressed size against the caller's bound (before allocating), then decodes. It never
//! panics on any input.

use serde::de::DeserializeOwned;
use serde::Serialize;

pub const MAGIC: [u8; 8] = *b"SGMSNAP\0";
/// Version 1: the layout above. Version 2: the same frame; the robot snapshot's optimiser state
/// also keeps its outlier decisions (a version-1 file is refused by name, not misread).
/// Version 3: the scene graph's semantic layer is a bounded cloud store (each scan marked
/// compacted or not, and the count evicted). Version 4: replay windows per sender incarnation.
/// Version 5: Comms keeps the pose each neighbour was last told of each keyframe we served, and
/// the optimiser counts the neighbour priors those poses refreshed. Version 6: the object
/// tracker counts the objects it merged and the tentative ones it let expire, and the Tracker
/// keeps each keyframe's pose from the robot's own measurements (what neighbours are told).
/// Version 7: the object tracker keeps the returns of each object's latest estimate (the
/// weights of a merge's centroid). Version 8: the Matcher keeps each neighbour's withdrawn
/// alignments and the pose graph how many withdrawals of each neighbour it has handled.
/// Version 9: the pose graph keeps each own keyframe's measured tilt (its gravity prior).
/// Version 10: the object tracker keeps where each object's latest sighting was counted from
/// (glimpses' spacing). Version 11: the pose graph keeps the σ of each own keyframe's up when
/// its odometry measured one. Version 12: the Matcher keeps, per neighbour, why its alignment
/// was last withdrawn, the significance of the match its alignment came from, and a bar that
/// stands on a stronger match's word (`relay.rematch`). Version 13: the Matcher counts, per
/// neighbour, the refuted rounds of its own graph matches (it keeps only the recent ones).
/// Version 14: the pose graph keeps its factor log and the neighbours' chains it holds
/// (`optimiser.share_factors`).
pub const FORMAT_VERSION: u32 = 14;
pub const HEADER_LEN: usize = 56;

/// Why bytes are not a snapshot (or not the one expected).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SnapshotError {
    #[error("not a snapshot: the file does not start with the SGM snapshot magic")]
    NotASnapshot,
    #[error("truncated: {present} bytes, the header alone is {HEADER_LEN}")]
    TruncatedHeader { present: usize },
    #[error("snapshot format version {found}; this build reads version {FORMAT_VERSION}")]
    Version { found: u32 },
    #[error("snapshot holds kind {found}, expected kind {expected}")]
    Kind { found: u32, expected: u32 },
    #[error("truncated: the header promises {promised} payload bytes, {present} are present")]
    Truncated { promised: u64, present: usize },
    #[error("{extra} bytes after the payload")]
    TrailingBytes { extra: usize },
    #[error("checksum mismatch: the payload is corrupted")]
    Checksum,
    #[error("the payload unpacks to {size} bytes, more than the limit of {limit}")]
    TooLarge { size: u64, limit: u64 },
    #[error("the payload does not decompress: {0}")]
    Compression(String),
    #[error("the payload does not decode: {0}")]
    Decode(String),
    #[error("cannot encode: {0}")]
    Encode(String),
}

/// Frames `value` as a snapshot of `kind`.
pub fn encode<T: Serialize>(kind: u32, value: &T) -> Result<Vec<u8>, SnapshotError> {
    let plain = postcard::to_allocvec(value).map_err(|e| SnapshotError::Encode(e.to_string()))?;
    frame(kind, &plain)
}

/// Frames an already encoded payload `plain` (postcard bytes) as a snapshot of `kind`.
pub fn frame(kind: u32, plain: &[u8]) -> Result<Vec<u8>, SnapshotError> {
    if u32::try_from(plain.len()).is_err() {
        return Err(SnapshotError::Encode(format!("{} bytes: more than 4 GiB", plain.len())));
    }
    let payload = lz4_flex::compress_prepend_size(plain);
    let mut out = Vec::with_capacity(HEADER_LEN + payload.len());
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&kind.to_le_bytes());
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(blake3::hash(&payload).as_bytes());
    out.extend_from_slice(&payload);
    Ok(out)
}

fn u32_at(bytes: &[u8], at: usize) -> u32 {
    let mut b = [0u8; 4];
    b.copy_from_slice(&bytes[at..at + 4]);
    u32::from_le_bytes(b)
}

/// Checks the frame of a snapshot of `kind` — magic, version, kind, length, checksum — without
/// unpacking it; returns the payload. Enough to know a file is whole.
pub fn verify(bytes: &[u8], kind: u32) -> Result<&[u8], SnapshotError> {
    if bytes.len() < MAGIC.len() || bytes[..MAGIC.len()] != MAGIC {
        return Err(SnapshotError::NotASnapshot);
    }
    if bytes.len() < HEADER_LEN {
        return Err(SnapshotError::TruncatedHeader { present: bytes.len() });
    }
    let version = u32_at(bytes, 8);
    if version != FORMAT_VERSION {
        return Err(SnapshotError::Version { found: version });
    }
    let found = u32_at(bytes, 12);
    if found != kind {
        return Err(SnapshotError::Kind { found, expected: kind });
    }
    let mut len = [0u8; 8];
    len.copy_from_slice(&bytes[16..24]);
    let promised = u64::from_le_bytes(len);
    let payload = &bytes[HEADER_LEN..];
    match u64::try_from(payload.len()).map(|present| present.cmp(&promised)) {
        Ok(std::cmp::Ordering::Less) => return Err(SnapshotError::Truncated { promised, present: payload.len() }),
        Ok(std::cmp::Ordering::Greater) => {
            return Err(SnapshotError::TrailingBytes { extra: payload.len() - promised as usize })
        }
        _ => {}
    }
    if blake3::hash(payload).as_bytes() != &bytes[24..56] {
        return Err(SnapshotError::Checksum);
    }
    Ok(payload)
}

/// Opens a snapshot of `kind` whose payload unpacks to at most `max_bytes`.
pub fn decode<T: DeserializeOwned>(bytes: &[u8], kind: u32, max_bytes: u64) -> Result<T, SnapshotError> {
    let payload = verify(bytes, kind)?;
    if payload.len() < 4 {
        return Err(SnapshotError::Compression("no size prefix".into()));
    }
    let size = u64::from(u32_at(payload, 0));
    if size > max_bytes {
        return Err(SnapshotError::TooLarge { size, limit: max_bytes });
    }
    let plain = lz4_flex::decompress_size_prepended(payload).map_err(|e| SnapshotError::Compression(e.to_string()))?;
    postcard::from_bytes(&plain).map_err(|e| SnapshotError::Decode(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::collections::BTreeMap;

    fn sample() -> BTreeMap<u32, Vec<f64>> {
        (0..50).map(|k| (k, (0..k).map(f64::from).collect())).collect()
    }

    #[test]
    fn round_trip_and_layout() {
        let bytes = encode(7, &sample()).unwrap();
        assert_eq!(&bytes[..8], b"SGMSNAP\0");
        assert_eq!(u32_at(&bytes, 8), FORMAT_VERSION);
        assert_eq!(u32_at(&bytes, 12), 7);
        assert_eq!(bytes.len() as u64 - HEADER_LEN as u64, u64::from_le_bytes(bytes[16..24].try_into().unwrap()));
        let back: BTreeMap<u32, Vec<f64>> = decode(&bytes, 7, 1 << 20).unwrap();
        assert_eq!(back, sample());
    }

    #[test]
    fn every_damage_is_named() {
        let bytes = encode(7, &sample()).unwrap();
        let decode = |b: &[u8]| decode::<BTreeMap<u32, Vec<f64>>>(b, 7, 1 << 20);
        assert_eq!(decode(b"hello"), Err(SnapshotError::NotASnapshot));
        assert_eq!(decode(&bytes[..30]), Err(SnapshotError::TruncatedHeader { present: 30 }));
        let present = bytes.len() - HEADER_LEN - 10;
        assert!(matches!(
            decode(&bytes[..bytes.len() - 10]),
            Err(SnapshotError::Truncated { present: p, .. }) if p == present
        ));
        let mut longer = bytes.clone();
        longer.push(0);
        assert_eq!(decode(&longer), Err(SnapshotError::TrailingBytes { extra: 1 }));
        let mut flipped = bytes.clone();
        let last = flipped.len() - 1;
        flipped[last] ^= 1;
        assert_eq!(decode(&flipped), Err(SnapshotError::Checksum));
        let mut newer = bytes.clone();
        newer[8..12].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
        assert_eq!(decode(&newer), Err(SnapshotError::Version { found: FORMAT_VERSION + 1 }));
        assert_eq!(
            super::decode::<BTreeMap<u32, Vec<f64>>>(&bytes, 8, 1 << 20),
            Err(SnapshotError::Kind { found: 7, expected: 8 })
        );
        assert!(matches!(
            super::decode::<BTreeMap<u32, Vec<f64>>>(&bytes, 7, 100),
            Err(SnapshotError::TooLarge { limit: 100, .. })
        ));
        // A well-framed payload of the wrong type.
        let other = encode(7, &"text").unwrap();
        assert!(matches!(decode(&other), Err(SnapshotError::Decode(_))));
    }

    proptest! {
        /// Any bytes: an error or a value, never a panic; any single flipped bit of a real
        /// snapshot is caught.
        #[test]
        fn arbitrary_bytes_never_panic(data in proptest::collection::vec(any::<u8>(), 0..300)) {
            let _ = decode::<BTreeMap<u32, Vec<f64>>>(&data, 7, 1 << 20);
            let mut framed = MAGIC.to_vec();
            framed.extend_from_slice(&data);
            let _ = decode::<BTreeMap<u32, Vec<f64>>>(&framed, 7, 1 << 20);
        }

        #[test]
        fn a_flipped_bit_is_caught(bit in 0usize..4000) {
            let bytes = encode(7, &sample()).unwrap();
            let bit = bit % (bytes.len() * 8);
            let mut damaged = bytes.clone();
            damaged[bit / 8] ^= 1 << (bit % 8);
            prop_assert!(decode::<BTreeMap<u32, Vec<f64>>>(&damaged, 7, 1 << 20).is_err());
        }
    }
}
