//! Health checks: conditions under which a robot maps badly without any error. Each is said
//! once in the log (`sgm_bridge::health`, warn) with its likely cause, and listed in the status
//! while it holds. Plain state: the node (or the replay, or `sgm doctor`) hands in what it has
//! observed ([`Observed`]: the synchroniser's counts, the inputs' tallies, tf, the map's object
//! count) and the mission time; nothing here reads a clock.
//!
//! The shares are taken over windows of `window_frames` clouds (assembled or dropped), so a
//! segmenter that dies an hour in is seen within a window, not diluted by the hour before.
//!
//! What a finding is (`finding.rs`: [`Check`], [`Finding`] with its likely cause), what the
//! checks are handed (`observed.rs`: [`Observed`], [`TopicTally`]), the checks' state and what
//! each update says (`checks.rs`: [`Health`], [`judge_whole_stream`]), and the shares judged
//! per window (`window.rs`). The thresholds, [`HealthConfig`], are `[ros.health]` in
//! [`crate::config`].

mod checks;
mod finding;
mod observed;
mod window;

#[cfg(test)]
mod fixtures;

pub use crate::config::HealthConfig;
pub use checks::{judge_whole_stream, Health};
pub use finding::{Check, Finding};
pub use observed::{Observed, TopicTally};
