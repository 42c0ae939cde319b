//! `sensor_msgs/PointField` datatypes: their codes, names and sizes.

pub(super) const INT8: u8 = 1;
pub(super) const UINT8: u8 = 2;
pub(super) const INT16: u8 = 3;
pub(super) const UINT16: u8 = 4;
pub(super) const INT32: u8 = 5;
pub(super) const UINT32: u8 = 6;
pub(super) const FLOAT32: u8 = 7;
pub(super) const FLOAT64: u8 = 8;

pub(super) fn type_name(datatype: u8) -> &'static str {
    match datatype {
        INT8 => "int8",
        UINT8 => "uint8",
        INT16 => "int16",
        UINT16 => "uint16",
        INT32 => "int32",
        UINT32 => "uint32",
        FLOAT32 => "float32",
        FLOAT64 => "float64",
        _ => "unknown",
    }
}

pub(super) fn type_size(datatype: u8) -> Option<u32> {
    match datatype {
        INT8 | UINT8 => Some(1),
        INT16 | UINT16 => Some(2),
        INT32 | UINT32 | FLOAT32 => Some(4),
        FLOAT64 => Some(8),
        _ => None,
    }
}
