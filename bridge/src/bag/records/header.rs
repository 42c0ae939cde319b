//! A record header: a list of `u32 field_len ‖ name=value`, and the fields every record needs.

use super::error::RecordError;

/// A record header's fields, as `(name, value)`.
pub(super) type Fields<'a> = Vec<(&'a [u8], &'a [u8])>;

/// The `name=value` fields of a record header.
pub(super) fn fields(header: &[u8], at: u64) -> Result<Fields<'_>, RecordError> {
    let malformed = |message: String| RecordError::Malformed { at, message };
    let mut fields = Vec::new();
    let mut rest = header;
    while !rest.is_empty() {
        let Some((len, tail)) = rest.split_first_chunk::<4>() else {
            return Err(malformed(format!("its header ends inside a field length ({} bytes left)", rest.len())));
        };
        let len = u32::from_le_bytes(*len) as usize;
        let Some(field) = tail.get(..len) else {
            return Err(malformed(format!("a header field of {len} bytes, {} left", tail.len())));
        };
        let Some(equals) = field.iter().position(|&b| b == b'=') else {
            return Err(malformed(format!("header field {:?} has no `=`", String::from_utf8_lossy(field))));
        };
        fields.push((&field[..equals], &field[equals + 1..]));
        rest = &tail[len..];
    }
    Ok(fields)
}

/// The value of `name` among `fields` (the last one if repeated).
pub(super) fn field<'a>(fields: &[(&[u8], &'a [u8])], name: &str) -> Option<&'a [u8]> {
    fields.iter().rev().find(|(n, _)| *n == name.as_bytes()).map(|(_, v)| *v)
}

pub(super) fn field_u32(fields: &[(&[u8], &[u8])], name: &'static str, at: u64) -> Result<u32, RecordError> {
    let value =
        field(fields, name).ok_or_else(|| RecordError::Malformed { at, message: format!("no `{name}` field") })?;
    let bytes: [u8; 4] = value.try_into().map_err(|_| RecordError::Malformed {
        at,
        message: format!("`{name}` has {} bytes, 4 expected", value.len()),
    })?;
    Ok(u32::from_le_bytes(bytes))
}

pub(super) fn field_u64(fields: &[(&[u8], &[u8])], name: &'static str, at: u64) -> Result<u64, RecordError> {
    let value =
        field(fields, name).ok_or_else(|| RecordError::Malformed { at, message: format!("no `{name}` field") })?;
    let bytes: [u8; 8] = value.try_into().map_err(|_| RecordError::Malformed {
        at,
        message: format!("`{name}` has {} bytes, 8 expected", value.len()),
    })?;
    Ok(u64::from_le_bytes(bytes))
}

pub(super) fn op(fields: &[(&[u8], &[u8])], at: u64) -> Result<u8, RecordError> {
    match field(fields, "op") {
        Some([op]) => Ok(*op),
        Some(v) => Err(RecordError::Malformed { at, message: format!("`op` has {} bytes, 1 expected", v.len()) }),
        None => Err(RecordError::Malformed { at, message: "no `op` field".into() }),
    }
}
