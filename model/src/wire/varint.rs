//! LEB128 unsigned varints and zigzag for signed values, with bounded decoding.

pub fn put_u64(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

pub fn put_i64(out: &mut Vec<u8>, v: i64) {
    put_u64(out, ((v << 1) ^ (v >> 63)) as u64);
}

/// Reads a varint at `*at`, advancing it; `None` if truncated or longer than 10 bytes.
pub fn get_u64(bytes: &[u8], at: &mut usize) -> Option<u64> {
    let mut v = 0u64;
    for shift in (0..70).step_by(7) {
        let b = *bytes.get(*at)?;
        *at += 1;
        if shift == 63 && b > 1 {
            return None;
        }
        v |= u64::from(b & 0x7f) << shift;
        if b < 0x80 {
            return Some(v);
        }
    }
    None
}

pub fn get_i64(bytes: &[u8], at: &mut usize) -> Option<i64> {
    let u = get_u64(bytes, at)?;
    Some(((u >> 1) as i64) ^ -((u & 1) as i64))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn round_trip(values in prop::collection::vec(any::<i64>(), 0..50), unsigned in any::<u64>()) {
            let mut out = Vec::new();
            for v in &values {
                put_i64(&mut out, *v);
            }
            put_u64(&mut out, unsigned);
            let mut at = 0;
            for v in &values {
                prop_assert_eq!(get_i64(&out, &mut at), Some(*v));
            }
            prop_assert_eq!(get_u64(&out, &mut at), Some(unsigned));
            prop_assert_eq!(at, out.len());
        }
    }

    #[test]
    fn truncated_and_overlong_are_rejected() {
        assert_eq!(get_u64(&[0x80], &mut 0), None);
        assert_eq!(get_u64(&[0xff; 11], &mut 0), None);
        assert_eq!(get_u64(&[0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x02], &mut 0), None);
    }
}
