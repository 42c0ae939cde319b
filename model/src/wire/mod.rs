//! What crosses the radio (DESIGN.md §4): encodings of inter-robot payloads.

pub mod cloud_codec;
mod varint;
