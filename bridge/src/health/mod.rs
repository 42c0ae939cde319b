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
//! each update says (here: [`Health`], [`judge_whole_stream`]), and the shares judged per window
//! (`window.rs`). The thresholds, [`HealthConfig`], are `[ros.health]` in [`crate::config`].

mod finding;
mod observed;
mod window;

pub use crate::config::HealthConfig;
pub use finding::{Check, Finding};
pub use observed::{Observed, TopicTally};

use sgm_model::scene_graph::Stamp;
use std::collections::{BTreeMap, BTreeSet};
use window::{settled, WindowStart};

/// The checks over a whole stream, judged at its end (one window: every cloud) — a replayed
/// bag, the doctor's span: what `sync` and `inputs` saw from `since` to `now`, with `objects`
/// confirmed objects (none: not judged). Findings are logged once, as a node's are.
pub fn judge_whole_stream(
    config: &HealthConfig,
    sync: &crate::sync::Synchroniser,
    inputs: &BTreeMap<String, TopicTally>,
    objects: Option<usize>,
    since: Stamp,
    now: Stamp,
) -> Vec<Finding> {
    let tf = sync.tf();
    let missing = sync.missing_mount();
    let observed = Observed { sync: &sync.counts, inputs, tf: &tf, missing_mount: missing.as_deref(), objects };
    Health::new(HealthConfig { window_frames: 1, ..config.clone() }).mapping_since(since).update(now, &observed)
}

/// The checks' state: what has been said, the window's start, the first frame's time.
#[derive(Debug, Default)]
pub struct Health {
    config: HealthConfig,
    said: BTreeSet<(Check, String)>,
    window_start: WindowStart,
    /// Findings of the last complete window.
    window_findings: Vec<Finding>,
    first_frame_at: Option<Stamp>,
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

    /// The findings that hold at mission time `now`, given what was observed so far; a
    /// finding seen for the first time is logged.
    pub fn update(&mut self, now: Stamp, observed: &Observed) -> Vec<Finding> {
        let sync = observed.sync;
        if sync.frames > 0 && self.first_frame_at.is_none() {
            self.first_frame_at = Some(now);
        }
        // Counts only grow, but a node restart of the synchroniser would start them over.
        if settled(sync) < settled(&self.window_start.sync) {
            self.window_start = WindowStart::default();
        }
        let clouds = settled(sync) - settled(&self.window_start.sync);
        if clouds >= self.config.window_frames {
            self.window_findings = self.window(observed, clouds);
            self.window_start =
                WindowStart { sync: sync.clone(), inputs: observed.inputs.clone(), tf: observed.tf.counts.clone() };
        }
        let mut findings = self.window_findings.clone();
        if !observed.tf.mounts_disagreeing.is_empty() {
            let detail = observed
                .tf
                .mounts
                .iter()
                .filter(|m| observed.tf.mounts_disagreeing.contains(&m.key))
                .filter_map(|m| {
                    let d = m.disagreement?;
                    Some(format!(
                        "{} disagrees with tf's `{}` → `{}` by {:.3} m and {:.2}° (the configured value is used)",
                        m.key, m.body_frame, m.sensor_frame, d.translation_m, d.rotation_deg
                    ))
                })
                .collect::<Vec<_>>()
                .join("; ");
            findings.push(Finding::new(Check::MountDisagrees, detail));
        }
        if let Some(first) = self.first_frame_at {
            if observed.objects == Some(0) && now - first >= self.config.no_objects_after_s {
                findings.push(Finding::new(
                    Check::NoObjects,
                    format!(
                        "{} frames in {:.0} s of mapping and no confirmed object in the map",
                        sync.frames,
                        now - first
                    ),
                ));
            }
        }
        findings.sort_by_key(|f| f.check);
        for f in &findings {
            let subject = if f.check == Check::InputRefused { f.detail.clone() } else { String::new() };
            if self.said.insert((f.check, subject)) {
                tracing::warn!(target: "sgm_bridge::health", check = ?f.check, "{}; likely cause: {}", f.detail, f.likely_cause);
            }
        }
        findings
    }
}

#[cfg(test)]
mod fixtures;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::health::fixtures::{checks, counts, update};
    use crate::sync::SyncCounts;

    /// An inverted camera extrinsic maps geometry but never an object: said after
    /// `no_objects_after_s` of frames, naming the extrinsic.
    #[test]
    fn frames_without_objects_are_a_finding_after_a_while() {
        let mut h = Health::new(HealthConfig { no_objects_after_s: 60.0, ..Default::default() });
        assert!(update(&mut h, 100.0, &counts(1, 0, 0), 0).is_empty());
        assert!(update(&mut h, 159.0, &counts(30, 0, 0), 0).is_empty());
        let f = update(&mut h, 160.0, &counts(31, 0, 0), 0);
        assert_eq!(checks(&f), vec![Check::NoObjects]);
        assert!(f[0].likely_cause.contains("body_from_camera"));
        assert!(update(&mut h, 161.0, &counts(32, 0, 0), 1).is_empty(), "an object: nothing to say");
    }

    /// A mount missing, a pin tf contradicts, an odometry tf contradicts, and frames whose points
    /// miss the image: each is a finding naming what it is about.
    #[test]
    fn mounts_odometry_and_projection_findings() {
        use crate::tf::listener::TfListener;
        use crate::tf::mounts::Mount;
        use crate::tf::{TfBatch, TfConfig, TfTransform};
        use sgm_model::geometry::Pose3;
        let offset = |x: f64| {
            Pose3::from_parts(nalgebra::Vector3::new(x, 0.0, 0.0).into(), nalgebra::UnitQuaternion::identity())
        };
        let camera = Mount::new("camera", "ros.body_from_camera", "base_link", "camera", Some(offset(0.1)));
        let lidar = Mount::new("lidar", "ros.body_from_lidar", "base_link", "base_link", None);
        let mut listener = TfListener::new(TfConfig::default(), "odom", "base_link", camera, lidar);
        let t = |parent: &str, child: &str, pose| TfTransform {
            stamp: rosrust::Time::default(),
            parent: parent.into(),
            child: child.into(),
            parent_from_child: pose,
        };
        listener.feed(
            TfBatch { is_static: true, transforms: vec![t("base_link", "camera", offset(0.3))], refused: vec![] },
            |_| 0.0,
        );
        for _ in 0..10 {
            listener.compared(&offset(0.0), &offset(1.0));
        }
        let tf = listener.status();
        let sync = SyncCounts {
            frames: 10,
            no_lidar_mount: 5,
            sampled_points: 10_000,
            sampled_in_image: 20,
            ..Default::default()
        };
        let inputs = BTreeMap::new();
        let missing = "the lidar mount `base_link` ← `velodyne` is unknown: no frame `velodyne` in tf";
        let mut h = Health::new(HealthConfig { window_frames: 10, ..Default::default() });
        let f = h.update(
            0.0,
            &Observed { sync: &sync, inputs: &inputs, tf: &tf, missing_mount: Some(missing), objects: Some(1) },
        );
        assert_eq!(
            checks(&f),
            vec![Check::NoMount, Check::MountDisagrees, Check::OdometryDisagreesWithTf, Check::PointsOutsideImage]
        );
        assert!(f[0].detail.ends_with(missing), "{}", f[0].detail);
        assert!(f[1].detail.starts_with("ros.body_from_camera disagrees with tf's `base_link` → `camera` by 0.200 m"));
        assert!(f[2].detail.contains("10 of 10 poses of tf's `odom` → `base_link`"), "{}", f[2].detail);
        assert!(f[3].detail.starts_with("20 of 10000 points"), "{}", f[3].detail);
    }
}
