//! One robot as a tree of actix actors (DESIGN.md §3) and the SGM exchange between robots
//! (paper §IV-B..F).

pub mod clock;
pub mod config;
pub mod protocol;
