//! Health checks: conditions under which a robot maps badly without any error. Each is said
//! once in the log (`sgm_bridge::health`, warn) with its likely cause, and listed in the status
//! while it holds. Plain state: the node hands in the synchroniser's counts, the map's object
//! count and the mission time; nothing here reads a clock.
//!
//! The shares are taken over windows of `window_frames` clouds (assembled or dropped), so a
//! segmenter that dies an hour in is seen within a window, not diluted by the hour before.

use crate::sync::SyncCounts;
use serde::{Deserialize, Serialize};
use sgm_model::scene_graph::Stamp;
use std::collections::BTreeSet;

/// `[ros.health]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HealthConfig {
    /// Clouds per window over which the shares are judged. Default 50.
    pub window_frames: u64,
    /// A window in which more than this share of the assembled frames had no label image is a
    /// finding (`no_labels`). Default 0.5.
    pub max_unlabelled_share: f64,
    /// A window in which more than this share of the clouds found no odometry pose is a
    /// finding (`no_odometry`). Default 0.5.
    pub max_no_odometry_share: f64,
    /// Frames flowing and still no confirmed object in the map (none seen often enough to be
    /// shared) after this much mission time is a finding (`no_objects`), s. Default 60.
    pub no_objects_after_s: f64,
}

impl Default for HealthConfig {
    fn default() -> Self {
        Self { window_frames: 50, max_unlabelled_share: 0.5, max_no_odometry_share: 0.5, no_objects_after_s: 60.0 }
    }
}

impl HealthConfig {
    pub fn validate(&self) -> Result<(), String> {
        let share = |v: f64, key: &str| {
            if (0.0..=1.0).contains(&v) {
                Ok(())
            } else {
                Err(format!("ros.health.{key} = {v}: a share in [0, 1] expected"))
            }
        };
        share(self.max_unlabelled_share, "max_unlabelled_share")?;
        share(self.max_no_odometry_share, "max_no_odometry_share")?;
        if self.window_frames == 0 {
            return Err("ros.health.window_frames = 0: at least 1 expected".into());
        }
        if !(self.no_objects_after_s.is_finite() && self.no_objects_after_s > 0.0) {
            return Err(format!(
                "ros.health.no_objects_after_s = {}: finite and > 0 expected",
                self.no_objects_after_s
            ));
        }
        Ok(())
    }
}

/// What a finding is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Check {
    /// Most clouds had no label image near them.
    NoLabels,
    /// Most clouds found no odometry pose.
    NoOdometry,
    /// Frames flow, yet the map holds no confirmed object (none worth sharing).
    NoObjects,
}

impl Check {
    fn likely_cause(self) -> &'static str {
        match self {
            Check::NoLabels => {
                "the segmenter is not publishing on the labels topic, is slower than ros.sync.max_label_skew_s, \
                 or stamps its images by another clock than the LiDAR's (see sync.label_skew_max_ms)"
            }
            Check::NoOdometry => {
                "the odometry lags the clouds by more than ros.sync.max_wait_s, has gaps above \
                 ros.sync.max_odometry_gap_s, or is stamped by another clock"
            }
            Check::NoObjects => {
                "the LiDAR points do not land on the label image's objects: ros.camera_from_body inverted \
                 (tf gives ros.body_from_camera) or the wrong camera_info; or the segmenter's ids are not \
                 fusion.classes' ids (map them in [classes]); or the objects are beyond fusion's range"
            }
        }
    }
}

/// One condition that holds, for the status.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Finding {
    pub check: Check,
    pub detail: String,
    pub likely_cause: &'static str,
}

/// The checks' state: what has been said, the window's start, the first frame's time.
#[derive(Debug, Default)]
pub struct Health {
    config: HealthConfig,
    said: BTreeSet<Check>,
    window_start: SyncCounts,
    /// Findings of the last complete window.
    window_findings: Vec<Finding>,
    first_frame_at: Option<Stamp>,
}

/// Clouds the synchroniser settled (assembled or dropped for any reason).
fn settled(c: &SyncCounts) -> u64 {
    c.frames + c.no_odometry + c.no_image + c.no_camera_info + c.no_label_field + c.at_restart
}

impl Health {
    pub fn new(config: HealthConfig) -> Self {
        Self { config, ..Default::default() }
    }

    /// Judged afterwards (a replay at its bag's end): mapping began at `t`.
    pub fn mapping_since(mut self, t: Stamp) -> Self {
        self.first_frame_at = Some(t);
        self
    }

    /// The findings that hold at mission time `now`, given the synchroniser's counts so far
    /// and the map's confirmed objects; a finding seen for the first time is logged.
    pub fn update(&mut self, now: Stamp, sync: &SyncCounts, objects: usize) -> Vec<Finding> {
        if sync.frames > 0 && self.first_frame_at.is_none() {
            self.first_frame_at = Some(now);
        }
        // Counts only grow, but a node restart of the synchroniser would start them over.
        if settled(sync) < settled(&self.window_start) {
            self.window_start = SyncCounts::default();
        }
        let clouds = settled(sync) - settled(&self.window_start);
        if clouds >= self.config.window_frames {
            self.window_findings = self.window(sync, clouds);
            self.window_start = sync.clone();
        }
        let mut findings = self.window_findings.clone();
        if let Some(first) = self.first_frame_at {
            if objects == 0 && now - first >= self.config.no_objects_after_s {
                findings.push(Finding {
                    check: Check::NoObjects,
                    detail: format!(
                        "{} frames in {:.0} s of mapping and no confirmed object in the map",
                        sync.frames,
                        now - first
                    ),
                    likely_cause: Check::NoObjects.likely_cause(),
                });
            }
        }
        for f in &findings {
            if self.said.insert(f.check) {
                tracing::warn!(check = ?f.check, "{}; likely cause: {}", f.detail, f.likely_cause);
            }
        }
        findings
    }

    fn window(&self, sync: &SyncCounts, clouds: u64) -> Vec<Finding> {
        let w = &self.window_start;
        let mut out = Vec::new();
        let frames = sync.frames - w.frames.min(sync.frames);
        let unlabelled = sync.unlabelled.saturating_sub(w.unlabelled) + sync.no_image.saturating_sub(w.no_image);
        let labelled_or_not = frames + sync.no_image.saturating_sub(w.no_image);
        if labelled_or_not > 0 && unlabelled as f64 / labelled_or_not as f64 > self.config.max_unlabelled_share {
            out.push(Finding {
                check: Check::NoLabels,
                detail: format!(
                    "{unlabelled} of the last {labelled_or_not} clouds had no label image within \
                     ros.sync.max_label_skew_s (largest skew of a labelled one so far: {} ms)",
                    sync.label_skew_max_ms
                ),
                likely_cause: Check::NoLabels.likely_cause(),
            });
        }
        let no_odometry = sync.no_odometry.saturating_sub(w.no_odometry);
        if no_odometry as f64 / clouds as f64 > self.config.max_no_odometry_share {
            out.push(Finding {
                check: Check::NoOdometry,
                detail: format!("{no_odometry} of the last {clouds} clouds found no odometry pose"),
                likely_cause: Check::NoOdometry.likely_cause(),
            });
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn counts(frames: u64, unlabelled: u64, no_odometry: u64) -> SyncCounts {
        SyncCounts { frames, unlabelled, no_odometry, ..Default::default() }
    }

    fn checks(f: &[Finding]) -> Vec<Check> {
        f.iter().map(|f| f.check).collect()
    }

    #[test]
    fn healthy_streams_raise_nothing() {
        let mut h = Health::new(HealthConfig::default());
        for k in 1..=100u64 {
            assert!(h.update(k as f64, &counts(k, k / 10, 0), 5).is_empty());
        }
    }

    /// A segmenter that dies after 100 frames: the next window says so, though the mission's
    /// whole share is still under half; it stays listed while it holds and clears after.
    #[test]
    fn a_segmenter_that_stops_is_seen_within_a_window() {
        let mut h = Health::new(HealthConfig::default());
        assert!(h.update(10.0, &counts(100, 0, 0), 3).is_empty());
        let f = h.update(20.0, &counts(150, 50, 0), 3);
        assert_eq!(checks(&f), vec![Check::NoLabels]);
        assert!(f[0].detail.starts_with("50 of the last 50 clouds"), "{}", f[0].detail);
        assert!(f[0].likely_cause.contains("max_label_skew_s"));
        assert_eq!(
            checks(&h.update(21.0, &counts(160, 60, 0), 3)),
            vec![Check::NoLabels],
            "held until the window ends"
        );
        assert!(h.update(30.0, &counts(210, 60, 0), 3).is_empty(), "labels came back");
    }

    #[test]
    fn clouds_without_odometry_are_a_finding() {
        let mut h = Health::new(HealthConfig::default());
        let f = h.update(5.0, &counts(10, 0, 40), 1);
        assert_eq!(checks(&f), vec![Check::NoOdometry]);
        assert!(f[0].detail.contains("40 of the last 50 clouds"), "{}", f[0].detail);
    }

    /// An inverted camera extrinsic maps geometry but never an object: said after
    /// `no_objects_after_s` of frames, naming the extrinsic.
    #[test]
    fn frames_without_objects_are_a_finding_after_a_while() {
        let mut h = Health::new(HealthConfig { no_objects_after_s: 60.0, ..Default::default() });
        assert!(h.update(100.0, &counts(1, 0, 0), 0).is_empty());
        assert!(h.update(159.0, &counts(30, 0, 0), 0).is_empty());
        let f = h.update(160.0, &counts(31, 0, 0), 0);
        assert_eq!(checks(&f), vec![Check::NoObjects]);
        assert!(f[0].likely_cause.contains("body_from_camera"));
        assert!(h.update(161.0, &counts(32, 0, 0), 1).is_empty(), "an object: nothing to say");
    }

    #[test]
    fn bad_thresholds_are_named() {
        let e = HealthConfig { max_unlabelled_share: 1.5, ..Default::default() }.validate().unwrap_err();
        assert!(e.contains("ros.health.max_unlabelled_share"), "{e}");
        let e = HealthConfig { window_frames: 0, ..Default::default() }.validate().unwrap_err();
        assert!(e.contains("window_frames"), "{e}");
    }
}
