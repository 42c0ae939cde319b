//! Keyframe point-cloud codec for keyframe responses (paper §IV-F: geometry only; the paper used
//! PCL's octree compression).
//!
//! Encoding of points p_k (in the keyframe's body frame) at resolution r:
//! 1. quantise q_k = round(p_k / r) − q_min, q_min the cloud's minimum corner (≤ 2²¹ cells per
//!    axis: 21 km at 1 cm);
//! 2. interleave the bits of q_k into a 63-bit Morton (Z-order) code m_k and sort: neighbouring
//!    cells get nearby codes;
//! 3. write the deltas m_k − m_{k−1} ≥ 0 as LEB128 varints (points in one cell give zeros);
//! 4. compress with LZ4.
//!
//! Layout: `u8 version | f64 r (LE) | zigzag varint q_min ×3 | varint n | LZ4 block (size
//! prepended)`. Decoding returns r·(q + q_min) in Morton order: every input point has an
//! output point within r/2 per axis (lossless within the quantum), the count is preserved, the
//! order is not. Decoding is bounded (declared sizes checked before allocation) and never panics.

use super::varint::{get_i64, get_u64, put_i64, put_u64};
use nalgebra::Point3;

const VERSION: u8 = 1;
const AXIS_BITS: u32 = 21;
/// Largest cloud accepted by the decoder.
pub const MAX_POINTS: usize = 50_000_000;

/// Why a cloud cannot be encoded or decoded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CodecError {
    #[error("resolution {0} m must be finite and > 0")]
    Resolution(f64),
    #[error("point {0} is not finite")]
    NonFinite(usize),
    #[error("the cloud spans more than 2^21 cells on an axis at this resolution")]
    TooLarge,
    #[error("unsupported codec version {0}")]
    Version(u8),
    #[error("encoded cloud is truncated or corrupt: {0}")]
    Corrupt(&'static str),
}

/// An encoded cloud and what it cost.
#[derive(Clone, Debug, PartialEq)]
pub struct EncodedCloud {
    pub bytes: Vec<u8>,
    pub points: usize,
    /// Largest distance between an input point and its decoded cell centre, m.
    pub max_error_m: f64,
}

impl EncodedCloud {
    pub fn bytes_per_point(&self) -> f64 {
        if self.points == 0 {
            0.0
        } else {
            self.bytes.len() as f64 / self.points as f64
        }
    }
}

/// Spreads the low 21 bits of v to every third bit.
fn spread(v: u64) -> u64 {
    let mut x = v & 0x1f_ffff;
    x = (x | x << 32) & 0x1f_0000_0000_ffff;
    x = (x | x << 16) & 0x1f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

fn compact(v: u64) -> u64 {
    let mut x = v & 0x1249_2492_4924_9249;
    x = (x ^ (x >> 2)) & 0x10c3_0c30_c30c_30c3;
    x = (x ^ (x >> 4)) & 0x100f_00f0_0f00_f00f;
    x = (x ^ (x >> 8)) & 0x1f_0000_ff00_00ff;
    x = (x ^ (x >> 16)) & 0x1f_0000_0000_ffff;
    x = (x ^ (x >> 32)) & 0x1f_ffff;
    x
}

fn morton(q: [u64; 3]) -> u64 {
    spread(q[0]) | spread(q[1]) << 1 | spread(q[2]) << 2
}

fn unmorton(m: u64) -> [u64; 3] {
    [compact(m), compact(m >> 1), compact(m >> 2)]
}

/// Encodes points at `resolution_m`.
pub fn encode(points: &[Point3<f64>], resolution_m: f64) -> Result<EncodedCloud, CodecError> {
    if !resolution_m.is_finite() || resolution_m <= 0.0 {
        return Err(CodecError::Resolution(resolution_m));
    }
    let mut cells = Vec::with_capacity(points.len());
    for (k, p) in points.iter().enumerate() {
        let q = p.coords.map(|v| (v / resolution_m).round());
        if q.iter().any(|v| !v.is_finite() || v.abs() > 9.0e15) {
            return Err(CodecError::NonFinite(k));
        }
        cells.push([q.x as i64, q.y as i64, q.z as i64]);
    }
    let mut min = [0i64; 3];
    if let Some(first) = cells.first() {
        min = *first;
        for c in &cells {
            for a in 0..3 {
                min[a] = min[a].min(c[a]);
            }
        }
    }
    let mut codes = Vec::with_capacity(cells.len());
    let mut max_error_m: f64 = 0.0;
    for (c, p) in cells.iter().zip(points) {
        let mut q = [0u64; 3];
        for a in 0..3 {
            let d = c[a] - min[a];
            if d >= 1 << AXIS_BITS {
                return Err(CodecError::TooLarge);
            }
            q[a] = d as u64;
        }
        codes.push(morton(q));
        let centre = Point3::new(c[0] as f64, c[1] as f64, c[2] as f64) * resolution_m;
        max_error_m = max_error_m.max((p - centre).norm());
    }
    codes.sort_unstable();
    let mut stream = Vec::with_capacity(codes.len() * 2);
    let mut previous = 0;
    for m in codes {
        put_u64(&mut stream, m - previous);
        previous = m;
    }
    let mut bytes = vec![VERSION];
    bytes.extend_from_slice(&resolution_m.to_le_bytes());
    for v in min {
        put_i64(&mut bytes, v);
    }
    put_u64(&mut bytes, points.len() as u64);
    bytes.extend_from_slice(&lz4_flex::block::compress_prepend_size(&stream));
    Ok(EncodedCloud { bytes, points: points.len(), max_error_m })
}

/// Decodes a cloud (cell centres, Morton order) of at most [`MAX_POINTS`] points.
pub fn decode(bytes: &[u8]) -> Result<Vec<Point3<f64>>, CodecError> {
    decode_at_most(bytes, MAX_POINTS)
}

/// The point count a cloud's header declares, read without decompressing anything (0 for an
/// empty stream, which stands for "no stored points"); `None` when the header is unreadable.
/// [`decode_at_most`] refuses a stream whose content does not match it.
pub fn declared_points(bytes: &[u8]) -> Option<u64> {
    if bytes.is_empty() {
        return Some(0);
    }
    origin_and_count(bytes).ok().map(|(_, n, _)| n)
}

/// The header's origin cell and point count (after the version byte and the resolution), and
/// where the packed stream starts.
fn origin_and_count(bytes: &[u8]) -> Result<([i64; 3], u64, usize), CodecError> {
    let mut at = 9;
    let mut min = [0i64; 3];
    for v in &mut min {
        *v = get_i64(bytes, &mut at).ok_or(CodecError::Corrupt("origin"))?;
    }
    let n = get_u64(bytes, &mut at).ok_or(CodecError::Corrupt("count"))?;
    Ok((min, n, at))
}

/// Decodes a cloud of at most `max_points` points (checked before anything is allocated or
/// decompressed: a radio payload cannot make us allocate more).
pub fn decode_at_most(bytes: &[u8], max_points: usize) -> Result<Vec<Point3<f64>>, CodecError> {
    let version = *bytes.first().ok_or(CodecError::Corrupt("empty"))?;
    if version != VERSION {
        return Err(CodecError::Version(version));
    }
    let r = f64::from_le_bytes(
        bytes.get(1..9).ok_or(CodecError::Corrupt("header"))?.try_into().map_err(|_| CodecError::Corrupt("header"))?,
    );
    if !r.is_finite() || r <= 0.0 {
        return Err(CodecError::Resolution(r));
    }
    let (min, n, at) = origin_and_count(bytes)?;
    let n = n as usize;
    if n > max_points.min(MAX_POINTS) {
        return Err(CodecError::Corrupt("more points than the limit"));
    }
    let packed = &bytes[at..];
    // Each point takes at least one varint byte: bound the declared stream size first.
    let declared = packed
        .get(..4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
        .ok_or(CodecError::Corrupt("stream"))?;
    if declared < n || declared > n.saturating_mul(10) {
        return Err(CodecError::Corrupt("stream size does not match the point count"));
    }
    let stream = lz4_flex::block::decompress_size_prepended(packed).map_err(|_| CodecError::Corrupt("lz4"))?;
    let mut points = Vec::with_capacity(n);
    let mut m = 0u64;
    let mut k = 0;
    for _ in 0..n {
        let delta = get_u64(&stream, &mut k).ok_or(CodecError::Corrupt("delta stream"))?;
        m = m.checked_add(delta).ok_or(CodecError::Corrupt("delta overflow"))?;
        let q = unmorton(m);
        let p = Point3::new(
            (q[0] as i64 + min[0]) as f64 * r,
            (q[1] as i64 + min[1]) as f64 * r,
            (q[2] as i64 + min[2]) as f64 * r,
        );
        // A huge resolution times a cell index overflows to infinity (found by fuzzing).
        if !p.coords.iter().all(|v| v.is_finite()) {
            return Err(CodecError::Corrupt("coordinates beyond the finite range"));
        }
        points.push(p);
    }
    if k != stream.len() {
        return Err(CodecError::Corrupt("trailing bytes"));
    }
    Ok(points)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn key(p: &Point3<f64>, r: f64) -> [i64; 3] {
        [(p.x / r).round() as i64, (p.y / r).round() as i64, (p.z / r).round() as i64]
    }

    proptest! {
        #[test]
        fn lossless_within_the_quantum(
            raw in prop::collection::vec((-50.0f64..50.0, -50.0f64..50.0, -5.0f64..5.0), 0..400),
            r in prop::sample::select(vec![0.001, 0.01, 0.05, 0.2]),
        ) {
            let points: Vec<Point3<f64>> = raw.iter().map(|&(x, y, z)| Point3::new(x, y, z)).collect();
            let encoded = encode(&points, r).unwrap();
            prop_assert!(encoded.max_error_m <= 3f64.sqrt() * r / 2.0 + 1e-12);
            let decoded = decode(&encoded.bytes).unwrap();
            prop_assert_eq!(decoded.len(), points.len());
            // Same multiset of cells.
            let mut a: Vec<[i64; 3]> = points.iter().map(|p| key(p, r)).collect();
            let mut b: Vec<[i64; 3]> = decoded.iter().map(|p| key(p, r)).collect();
            a.sort_unstable();
            b.sort_unstable();
            prop_assert_eq!(a, b);
            for p in &decoded {
                let c = key(p, r);
                prop_assert!((p - Point3::new(c[0] as f64, c[1] as f64, c[2] as f64) * r).norm() < 1e-9);
            }
        }

        #[test]
        fn decoding_garbage_never_panics(bytes in prop::collection::vec(any::<u8>(), 0..200)) {
            let _ = decode(&bytes);
        }
    }

    #[test]
    fn morton_round_trips_and_errors() {
        for q in [[0, 0, 0], [1, 2, 3], [(1 << 21) - 1, 0, 12345], [7, (1 << 21) - 1, (1 << 21) - 1]] {
            assert_eq!(unmorton(morton(q)), q);
        }
        assert_eq!(encode(&[Point3::origin()], 0.0), Err(CodecError::Resolution(0.0)));
        assert_eq!(encode(&[Point3::new(f64::NAN, 0.0, 0.0)], 0.01), Err(CodecError::NonFinite(0)));
        assert_eq!(encode(&[Point3::origin(), Point3::new(30_000.0, 0.0, 0.0)], 0.01), Err(CodecError::TooLarge));
        let ok = encode(&[Point3::new(1.0, 2.0, 3.0)], 0.01).unwrap();
        let mut wrong_version = ok.bytes.clone();
        wrong_version[0] = 9;
        assert_eq!(decode(&wrong_version), Err(CodecError::Version(9)));
        assert!(decode(&ok.bytes[..ok.bytes.len() - 1]).is_err());
        assert!(decode(&[]).is_err());
        assert_eq!(decode(&encode(&[], 0.01).unwrap().bytes).unwrap(), vec![]);
    }
}
