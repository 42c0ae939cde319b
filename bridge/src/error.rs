//! What can be wrong with a ROS message coming in. Every conversion from outside data returns
//! one of these (never panics); the node and the replay log it with the topic and count it.

/// Why an incoming message was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum InputError {
    #[error("no field `{field}`")]
    MissingField { field: String },
    #[error("field `{field}` has datatype {datatype} ({found}), {expected} expected")]
    FieldType { field: String, datatype: u8, found: &'static str, expected: &'static str },
    #[error("field `{field}` at offset {offset} does not fit in a {point_step}-byte point")]
    FieldOutsidePoint { field: String, offset: u32, point_step: u32 },
    #[error("data is {got} bytes, {expected} expected ({what})")]
    Truncated { got: usize, expected: usize, what: String },
    #[error("unsupported encoding `{0}` (mono8, mono16, 8UC1, 16UC1, rgb8, bgr8, rgba8 or bgra8 expected)")]
    Encoding(String),
    #[error("frame `{got}`, `{expected}` expected")]
    Frame { got: String, expected: String },
    #[error("{0}")]
    Invalid(String),
}

impl InputError {
    pub fn invalid(what: impl Into<String>) -> Self {
        Self::Invalid(what.into())
    }
}
