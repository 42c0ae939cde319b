//! LZF (Marc Lehmann's liblzf format), the compression of PCL's `binary_compressed` PCD data.
//!
//! A stream of chunks, each starting with a control byte c:
//! * c < 32: a literal run of c + 1 bytes follows;
//! * else: a back reference of length (c >> 5) + 2 (if c >> 5 == 7, a further byte adds to the
//!   length) at distance ((c & 0x1f) << 8 | next byte) + 1 before the output position.
//!
//! Decompression checks every bound and reports corrupt input instead of panicking.

/// Corrupt or truncated compressed data.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LzfError {
    #[error("compressed data ends inside a chunk at byte {0}")]
    Truncated(usize),
    #[error("back reference at byte {0} points before the start of the output")]
    BadReference(usize),
    #[error("output would exceed the declared {0} bytes")]
    TooLong(usize),
    #[error("output is {got} bytes, the header declared {expected}")]
    WrongLength { got: usize, expected: usize },
    #[error("{input} compressed bytes cannot hold {expected} bytes (at most {MAX_EXPANSION}× each)")]
    Expansion { input: usize, expected: usize },
}

/// Most output bytes per input byte: a 3-byte back reference yields at most 7 + 255 + 2 = 264.
pub const MAX_EXPANSION: usize = 88;

/// Decompresses `input` into exactly `expected_len` bytes.
pub fn decompress(input: &[u8], expected_len: usize) -> Result<Vec<u8>, LzfError> {
    // Checked before allocating: a short file cannot make us reserve a declared gigabyte.
    if expected_len > input.len().saturating_mul(MAX_EXPANSION) {
        return Err(LzfError::Expansion { input: input.len(), expected: expected_len });
    }
    let mut out = Vec::with_capacity(expected_len);
    let mut ip = 0;
    while ip < input.len() {
        let ctrl = input[ip] as usize;
        ip += 1;
        if ctrl < 32 {
            let len = ctrl + 1;
            let literal = input.get(ip..ip + len).ok_or(LzfError::Truncated(ip))?;
            if out.len() + len > expected_len {
                return Err(LzfError::TooLong(expected_len));
            }
            out.extend_from_slice(literal);
            ip += len;
        } else {
            let mut len = ctrl >> 5;
            if len == 7 {
                len += *input.get(ip).ok_or(LzfError::Truncated(ip))? as usize;
                ip += 1;
            }
            len += 2;
            let low = *input.get(ip).ok_or(LzfError::Truncated(ip))? as usize;
            ip += 1;
            let distance = ((ctrl & 0x1f) << 8 | low) + 1;
            let start = out.len().checked_sub(distance).ok_or(LzfError::BadReference(ip))?;
            if out.len() + len > expected_len {
                return Err(LzfError::TooLong(expected_len));
            }
            // Overlapping copies repeat the pattern, so copy byte by byte.
            for k in 0..len {
                let byte = out[start + k];
                out.push(byte);
            }
        }
    }
    if out.len() != expected_len {
        return Err(LzfError::WrongLength { got: out.len(), expected: expected_len });
    }
    Ok(out)
}

const HASH_BITS: u32 = 14;
const MAX_LITERAL: usize = 32;
const MAX_OFFSET: usize = 1 << 13;
const MAX_REF: usize = (1 << 8) + (1 << 3);

/// Positions remembered per hash bucket: the longest of their matches is taken.
const WAYS: usize = 4;

/// Compresses `input`: greedy matching through a hash of the next three bytes, each bucket
/// remembering the last [`WAYS`] positions (one is liblzf's; periodic data with repeats inside
/// its period then never finds the period and compresses poorly).
pub fn compress(input: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(input.len() / 2 + 16);
    let mut table = vec![[usize::MAX; WAYS]; 1 << HASH_BITS];
    let mut literal_start = 0;
    let mut ip = 0;
    let flush_literals = |out: &mut Vec<u8>, from: usize, to: usize| {
        let mut k = from;
        while k < to {
            let run = (to - k).min(MAX_LITERAL);
            out.push((run - 1) as u8);
            out.extend_from_slice(&input[k..k + run]);
            k += run;
        }
    };
    let hash = |p: usize| {
        ((u32::from(input[p]) << 16 | u32::from(input[p + 1]) << 8 | u32::from(input[p + 2]))
            .wrapping_mul(2_654_435_761)
            >> (32 - HASH_BITS)) as usize
    };
    let remember = |table: &mut Vec<[usize; WAYS]>, p: usize| {
        let bucket = &mut table[hash(p)];
        bucket.copy_within(0..WAYS - 1, 1);
        bucket[0] = p;
    };
    while ip + 2 < input.len() {
        let max_len = (input.len() - ip).min(MAX_REF);
        let matched = |&candidate: &usize| {
            if candidate == usize::MAX || ip - candidate > MAX_OFFSET {
                return None;
            }
            let len = (0..max_len).take_while(|&k| input[candidate + k] == input[ip + k]).count();
            (len >= 3).then_some((len, candidate))
        };
        // The longest; among equals the nearest (the largest position).
        let best = table[hash(ip)].iter().filter_map(matched).max();
        remember(&mut table, ip);
        if let Some((len, candidate)) = best {
            flush_literals(&mut out, literal_start, ip);
            let distance = ip - candidate - 1;
            let code = len - 2;
            if code < 7 {
                out.push(((code << 5) | (distance >> 8)) as u8);
            } else {
                out.push(((7 << 5) | (distance >> 8)) as u8);
                out.push((code - 7) as u8);
            }
            out.push((distance & 0xff) as u8);
            // Every position the match covers is remembered too (as liblzf's default mode
            // does): otherwise the next match starts from stale candidates.
            for p in ip + 1..(ip + len).min(input.len().saturating_sub(2)) {
                remember(&mut table, p);
            }
            ip += len;
            literal_start = ip;
        } else {
            ip += 1;
        }
    }
    flush_literals(&mut out, literal_start, input.len());
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn round_trips_any_bytes(data in prop::collection::vec(any::<u8>(), 0..5000)) {
            prop_assert_eq!(decompress(&compress(&data), data.len()).unwrap(), data);
        }

        #[test]
        fn round_trips_repetitive_bytes(pattern in prop::collection::vec(0u8..4, 1..20), repeats in 1usize..500) {
            let data: Vec<u8> = pattern.iter().cycle().take(pattern.len() * repeats).copied().collect();
            let packed = compress(&data);
            prop_assert_eq!(decompress(&packed, data.len()).unwrap(), data.clone());
            if data.len() > 200 {
                prop_assert!(packed.len() < data.len() / 2);
            }
        }

        #[test]
        fn never_panics_on_garbage(data in prop::collection::vec(any::<u8>(), 0..300), len in 0usize..2000) {
            let _ = decompress(&data, len);
        }
    }

    #[test]
    fn corrupt_streams_are_errors() {
        assert_eq!(decompress(&[5, 1, 2], 6), Err(LzfError::Truncated(1)));
        assert_eq!(decompress(&[0, 9, 0x20, 5], 3), Err(LzfError::BadReference(4)));
        assert_eq!(decompress(&[1, 7, 7], 1), Err(LzfError::TooLong(1)));
        assert_eq!(decompress(&[0, 7], 3), Err(LzfError::WrongLength { got: 1, expected: 3 }));
        // A reference overlapping its own output repeats the byte: "a" + 4 × "a".
        assert_eq!(decompress(&[0, b'a', 0x40, 0], 5).unwrap(), b"aaaaa");
    }
}
