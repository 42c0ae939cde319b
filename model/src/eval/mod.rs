//! Evaluation: the paper's synthetic matching protocol (§V-A) and its metrics, repeated layouts
//! for the matcher; trajectory error.

pub mod ate;
pub mod matching_protocol;
pub mod repeated_layouts;
