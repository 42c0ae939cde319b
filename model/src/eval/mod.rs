//! Evaluation: the paper's synthetic matching protocol (§V-A) and its metrics.

pub mod matching_protocol;
