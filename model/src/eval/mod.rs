//! Evaluation: the paper's synthetic matching protocol (§V-A) and its metrics; trajectory error.

pub mod ate;
pub mod matching_protocol;
