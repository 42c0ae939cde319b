//! A bounded reader of OMG CDR (XCDR1, the encoding of rosbag2's `cdr` messages; DDS-XTypes
//! §7.4.3 "Classic CDR").
//!
//! ```text
//! encapsulation: u8 0, u8 kind (0 = CDR big-endian, 1 = CDR little-endian), u16 options
//! body:          primitives aligned to their own size (at most 8), counted from the body's start;
//!                string = u32 length with the terminating NUL, bytes, NUL;
//!                sequence = u32 count, elements; fixed array = elements only
//! ```
//!
//! Every length and count is checked against the bytes left before anything is allocated, so a
//! 60-byte message that declares 4 × 10⁹ bytes of data is refused, not reserved.

use std::fmt;

/// Where a CDR message does not hold what its type says.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum CdrError {
    #[error("{len} bytes, at most {max} accepted")]
    TooLarge { len: usize, max: usize },
    #[error("encapsulation header needs 4 bytes, {0} present")]
    NoHeader(usize),
    #[error("encapsulation kind {0:#06x} is not plain CDR (0x0000 big-endian or 0x0001 little-endian)")]
    Encapsulation(u16),
    #[error("field `{field}` needs {needed} bytes at byte {at}, {left} left")]
    Short { field: &'static str, needed: u64, at: usize, left: usize },
    #[error("field `{field}` is not a UTF-8 string ending in NUL")]
    BadString { field: &'static str },
    #[error("{0} bytes after the last field")]
    Trailing(usize),
    #[error("field `{field}`: {what}")]
    Value { field: &'static str, what: String },
}

/// A cursor over one CDR message (encapsulation header first).
pub struct CdrReader<'a> {
    body: &'a [u8],
    at: usize,
    little: bool,
}

impl fmt::Debug for CdrReader<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "CdrReader {{ at: {}, of: {}, little: {} }}", self.at, self.body.len(), self.little)
    }
}

impl<'a> CdrReader<'a> {
    /// Reads the encapsulation header of `bytes`, at most `max_bytes` long.
    pub fn new(bytes: &'a [u8], max_bytes: usize) -> Result<Self, CdrError> {
        if bytes.len() > max_bytes {
            return Err(CdrError::TooLarge { len: bytes.len(), max: max_bytes });
        }
        let Some((head, body)) = bytes.split_first_chunk::<4>() else {
            return Err(CdrError::NoHeader(bytes.len()));
        };
        let little = match u16::from_be_bytes([head[0], head[1]]) {
            0x0000 => false,
            0x0001 => true,
            kind => return Err(CdrError::Encapsulation(kind)),
        };
        Ok(Self { body, at: 0, little })
    }

    fn left(&self) -> usize {
        self.body.len() - self.at
    }

    /// Takes `n` bytes of `field`.
    fn take(&mut self, field: &'static str, n: u64) -> Result<&'a [u8], CdrError> {
        let left = self.left();
        if n > left as u64 {
            return Err(CdrError::Short { field, needed: n, at: self.at + 4, left });
        }
        let bytes = &self.body[self.at..self.at + n as usize];
        self.at += n as usize;
        Ok(bytes)
    }

    /// Skips the padding before a primitive of `size` bytes.
    fn align(&mut self, field: &'static str, size: usize) -> Result<(), CdrError> {
        let pad = (size - self.at % size) % size;
        self.take(field, pad as u64).map(|_| ())
    }

    fn fixed<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], CdrError> {
        self.align(field, N)?;
        let bytes = self.take(field, N as u64)?;
        let mut out = [0u8; N];
        out.copy_from_slice(bytes);
        if !self.little {
            out.reverse();
        }
        Ok(out)
    }

    pub fn u8(&mut self, field: &'static str) -> Result<u8, CdrError> {
        Ok(self.take(field, 1)?[0])
    }

    /// A `bool`: one byte, 0 or 1.
    pub fn bool(&mut self, field: &'static str) -> Result<bool, CdrError> {
        match self.u8(field)? {
            0 => Ok(false),
            1 => Ok(true),
            v => Err(CdrError::Value { field, what: format!("bool is {v}, 0 or 1 expected") }),
        }
    }

    pub fn u32(&mut self, field: &'static str) -> Result<u32, CdrError> {
        self.fixed::<4>(field).map(u32::from_le_bytes)
    }

    pub fn i32(&mut self, field: &'static str) -> Result<i32, CdrError> {
        self.fixed::<4>(field).map(i32::from_le_bytes)
    }

    pub fn f64(&mut self, field: &'static str) -> Result<f64, CdrError> {
        self.fixed::<8>(field).map(f64::from_le_bytes)
    }

    /// A fixed array `float64[N]`.
    pub fn f64_array<const N: usize>(&mut self, field: &'static str) -> Result<[f64; N], CdrError> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.f64(field)?;
        }
        Ok(out)
    }

    /// A sequence's count, checked against the bytes left for elements of at least `element`
    /// bytes each.
    pub fn count(&mut self, field: &'static str, element: u64) -> Result<usize, CdrError> {
        let count = self.u32(field)?;
        let needed = u64::from(count).saturating_mul(element.max(1));
        if needed > self.left() as u64 {
            return Err(CdrError::Short { field, needed, at: self.at + 4, left: self.left() });
        }
        Ok(count as usize)
    }

    /// A `float64[]`.
    pub fn f64_seq(&mut self, field: &'static str) -> Result<Vec<f64>, CdrError> {
        let count = self.count(field, 8)?;
        (0..count).map(|_| self.f64(field)).collect()
    }

    /// A `uint8[]`, as it is in the message.
    pub fn bytes(&mut self, field: &'static str) -> Result<&'a [u8], CdrError> {
        let count = self.count(field, 1)?;
        self.take(field, count as u64)
    }

    /// A `string`: its length counts the terminating NUL (a length of 0 is read as empty).
    pub fn string(&mut self, field: &'static str) -> Result<String, CdrError> {
        let len = self.count(field, 1)?;
        let bytes = self.take(field, len as u64)?;
        let text = match bytes.split_last() {
            None => &[][..],
            Some((0, text)) => text,
            Some(_) => return Err(CdrError::BadString { field }),
        };
        String::from_utf8(text.to_vec()).map_err(|_| CdrError::BadString { field })
    }

    /// The message must end here, but for the padding a writer may add to a 4-byte boundary
    /// of the whole (rmw pads the serialised size; at most 3 zero bytes).
    pub fn finish(self) -> Result<(), CdrError> {
        let rest = &self.body[self.at..];
        if rest.len() < 4 && rest.iter().all(|&b| b == 0) {
            Ok(())
        } else {
            Err(CdrError::Trailing(rest.len()))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn le(body: &[u8]) -> Vec<u8> {
        let mut v = vec![0, 1, 0, 0];
        v.extend_from_slice(body);
        v
    }

    #[test]
    fn primitives_are_aligned_from_the_body_start_in_either_byte_order() {
        // u8 1, pad 3, u32 7, f64 at offset 8: 0.5
        let mut body = vec![1, 0, 0, 0, 7, 0, 0, 0];
        body.extend_from_slice(&0.5f64.to_le_bytes());
        let bytes = le(&body);
        let mut r = CdrReader::new(&bytes, 1 << 20).unwrap();
        assert_eq!(r.u8("a").unwrap(), 1);
        assert_eq!(r.u32("b").unwrap(), 7);
        assert_eq!(r.f64("c").unwrap(), 0.5);
        r.finish().unwrap();

        let mut big = vec![0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 7];
        big.extend_from_slice(&0.5f64.to_be_bytes());
        let mut r = CdrReader::new(&big, 1 << 20).unwrap();
        assert_eq!((r.u8("a").unwrap(), r.u32("b").unwrap(), r.f64("c").unwrap()), (1, 7, 0.5));
    }

    #[test]
    fn strings_carry_their_nul_and_sequences_their_count() {
        let mut body = vec![3, 0, 0, 0, b'h', b'i', 0, 0];
        body.extend_from_slice(&[2, 0, 0, 0, 9, 8]);
        let bytes = le(&body);
        let mut r = CdrReader::new(&bytes, 1 << 20).unwrap();
        assert_eq!(r.string("s").unwrap(), "hi");
        assert_eq!(r.bytes("d").unwrap(), &[9, 8]);
        r.finish().unwrap();
        let bad = le(&[2, 0, 0, 0, b'h', b'i']);
        assert_eq!(CdrReader::new(&bad, 100).unwrap().string("s"), Err(CdrError::BadString { field: "s" }));
    }

    #[test]
    fn declared_lengths_beyond_the_bytes_are_refused_before_allocating() {
        let bytes = le(&[0xF0, 0xFF, 0xFF, 0xFF, 1, 2]);
        let e = CdrReader::new(&bytes, 100).unwrap().bytes("data").unwrap_err();
        assert_eq!(e, CdrError::Short { field: "data", needed: 0xFFFF_FFF0, at: 8, left: 2 });
        let e = CdrReader::new(&bytes, 100).unwrap().f64_seq("d").unwrap_err();
        assert!(matches!(e, CdrError::Short { field: "d", .. }), "{e}");
        assert_eq!(CdrReader::new(&bytes, 4).unwrap_err(), CdrError::TooLarge { len: 10, max: 4 });
        assert_eq!(CdrReader::new(&[0, 1], 100).unwrap_err(), CdrError::NoHeader(2));
        assert_eq!(CdrReader::new(&[0, 3, 0, 0], 100).unwrap_err(), CdrError::Encapsulation(3));
        assert_eq!(CdrReader::new(&[1, 1, 0, 0], 100).unwrap_err(), CdrError::Encapsulation(0x0101));
        let trailing = le(&[1, 0, 0, 0, 5]);
        let mut r = CdrReader::new(&trailing, 100).unwrap();
        r.u32("a").unwrap();
        assert_eq!(r.finish(), Err(CdrError::Trailing(1)));
    }
}
