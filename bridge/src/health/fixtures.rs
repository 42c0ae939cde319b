//! What the health checks' tests share.

use super::{Check, Finding, Health, Observed};
use crate::sync::SyncCounts;
use crate::tf::listener::TfStatus;
use std::collections::BTreeMap;

pub(super) fn counts(frames: u64, unlabelled: u64, no_odometry: u64) -> SyncCounts {
    SyncCounts { frames, unlabelled, no_odometry, ..Default::default() }
}

pub(super) fn tf() -> TfStatus {
    crate::tf::listener::TfListener::pinned(sgm_model::geometry::Pose3::identity()).status()
}

/// Feeds `sync` and `objects` with no other news.
pub(super) fn update(h: &mut Health, now: f64, sync: &SyncCounts, objects: usize) -> Vec<Finding> {
    let (inputs, tf) = (BTreeMap::new(), tf());
    h.update(now, &Observed { sync, inputs: &inputs, tf: &tf, missing_mount: None, objects: Some(objects) })
}

pub(super) fn checks(f: &[Finding]) -> Vec<Check> {
    f.iter().map(|f| f.check).collect()
}
