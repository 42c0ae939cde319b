//! What the health checks are handed: the synchroniser's counts, the inputs' tallies, tf.

use crate::sync::SyncCounts;
use crate::tf::listener::TfStatus;
use serde::Serialize;
use std::collections::BTreeMap;

/// One input topic's messages so far.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct TopicTally {
    pub accepted: u64,
    pub refused: u64,
    /// Why the latest refused message was refused.
    pub last_refusal: Option<String>,
}

/// What the checks are handed: everything counts up from the start.
#[derive(Clone, Copy, Debug)]
pub struct Observed<'a> {
    pub sync: &'a SyncCounts,
    /// Per input (`points`, `labels`, `camera_info`, `odometry`, `tf`, `tf_static`, …).
    pub inputs: &'a BTreeMap<String, TopicTally>,
    pub tf: &'a TfStatus,
    /// Why a mount the frames need is unknown, naming the frames (the synchroniser's).
    pub missing_mount: Option<&'a str>,
    /// Confirmed objects in the map (none: not judged, as `sgm doctor`, which builds no map).
    pub objects: Option<usize>,
}
