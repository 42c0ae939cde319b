//! Evaluation: the paper's synthetic matching protocol (§V-A) and its metrics, repeated layouts
//! for the matcher; trajectory error (`ate`) and an odometry's relative drift (`drift`).

pub mod ate;
pub mod drift;
pub mod matching_protocol;
pub mod repeated_layouts;
