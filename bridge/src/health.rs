//! Health checks: conditions under which a robot maps badly without any error. Each is said
//! once in the log (`sgm_bridge::health`, warn) with its likely cause, and listed in the status
//! while it holds. Plain state: the node (or the replay, or `sgm doctor`) hands in what it has
//! observed ([`Observed`]: the synchroniser's counts, the inputs' tallies, tf, the map's object
//! count) and the mission time; nothing here reads a clock.
//!
//! The shares are taken over windows of `window_frames` clouds (assembled or dropped), so a
//! segmenter that dies an hour in is seen within a window, not diluted by the hour before.

pub use crate::config::HealthConfig;
use crate::sync::SyncCounts;
use crate::tf::listener::{TfCounts, TfStatus};
use serde::Serialize;
use sgm_model::scene_graph::Stamp;
use std::collections::{BTreeMap, BTreeSet};

/// What a finding is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Check {
    /// Most of an input topic's messages were refused.
    InputRefused,
    /// A sensor's mount is unknown: not pinned, and tf does not connect its frame to the body.
    NoMount,
    /// A mount pinned in configuration disagrees with tf.
    MountDisagrees,
    /// Most clouds found no odometry pose.
    NoOdometry,
    /// The odometry topic and tf give different poses for the same world and body frames.
    OdometryDisagreesWithTf,
    /// Most clouds had no label image near them.
    NoLabels,
    /// Labelled frames, but (almost) none of their points lands in the label image.
    PointsOutsideImage,
    /// Frames flow, yet the map holds no confirmed object (none worth sharing).
    NoObjects,
}

impl Check {
    fn likely_cause(self) -> &'static str {
        match self {
            Check::InputRefused => {
                "the messages do not match [ros]: frame ids (ros.frames, or rename them with ros.frames.aliases), \
                 encodings or sizes; the reason above names what"
            }
            Check::NoMount => {
                "nothing publishes the mount on tf (robot_state_publisher, static_transform_publisher, the \
                 driver's tf_static), tf comes on another topic (ros.tf.topic, ros.tf.static_topic), or \
                 ros.frames names another frame than the messages carry; or pin it in [ros]"
            }
            Check::MountDisagrees => {
                "the configured mount is stale (the sensor was moved or recalibrated) or written the wrong way \
                 round (body_from_camera vs camera_from_body); tf or the key is wrong"
            }
            Check::NoOdometry => {
                "the odometry lags the clouds by more than ros.sync.max_wait_s, has gaps above \
                 ros.sync.max_odometry_gap_s, or is stamped by another clock"
            }
            Check::OdometryDisagreesWithTf => {
                "two sources publish the same frames (another odometry or localisation on tf), or the odometry \
                 topic is not the one whose transform is on tf"
            }
            Check::NoLabels => {
                "the segmenter is not publishing on the labels topic, is slower than ros.sync.max_label_skew_s, \
                 or stamps its images by another clock than the LiDAR's (see sync.label_skew_max_ms)"
            }
            Check::PointsOutsideImage => {
                "the camera mount is wrong (inverted: tf gives ros.body_from_camera, not camera_from_body; or the \
                 camera's link instead of its optical frame), or camera_info is another camera's"
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

impl Finding {
    fn new(check: Check, detail: String) -> Self {
        Self { check, detail, likely_cause: check.likely_cause() }
    }
}

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

/// Where the current window started.
#[derive(Clone, Debug, Default)]
struct WindowStart {
    sync: SyncCounts,
    inputs: BTreeMap<String, TopicTally>,
    tf: TfCounts,
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

/// Clouds the synchroniser settled (assembled or dropped for any reason).
fn settled(c: &SyncCounts) -> u64 {
    c.frames + c.no_odometry + c.no_image + c.no_camera_info + c.no_label_field + c.at_restart + c.no_lidar_mount
}

fn share(part: u64, whole: u64) -> f64 {
    if whole == 0 {
        0.0
    } else {
        part as f64 / whole as f64
    }
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

    fn window(&self, observed: &Observed, clouds: u64) -> Vec<Finding> {
        let (sync, w) = (observed.sync, &self.window_start.sync);
        let mut out = Vec::new();
        for (topic, tally) in observed.inputs {
            let before = self.window_start.inputs.get(topic).cloned().unwrap_or_default();
            let refused = tally.refused.saturating_sub(before.refused);
            let all = refused + tally.accepted.saturating_sub(before.accepted);
            if refused > 0 && share(refused, all) > self.config.max_refused_share {
                out.push(Finding::new(
                    Check::InputRefused,
                    format!(
                        "{refused} of the last {all} messages on {topic} refused (last: {})",
                        tally.last_refusal.as_deref().unwrap_or("no reason kept")
                    ),
                ));
            }
        }
        let no_mount = sync.no_lidar_mount.saturating_sub(w.no_lidar_mount)
            + sync.no_camera_mount.saturating_sub(w.no_camera_mount);
        if no_mount > 0 {
            out.push(Finding::new(
                Check::NoMount,
                format!(
                    "{no_mount} of the last {clouds} clouds without a sensor mount: {}",
                    observed.missing_mount.unwrap_or("a mount was missing (tf has it now)")
                ),
            ));
        }
        let no_odometry = sync.no_odometry.saturating_sub(w.no_odometry);
        if share(no_odometry, clouds) > self.config.max_no_odometry_share {
            out.push(Finding::new(
                Check::NoOdometry,
                format!("{no_odometry} of the last {clouds} clouds found no odometry pose"),
            ));
        }
        let (tf, tf0) = (&observed.tf.counts, &self.window_start.tf);
        let compared = tf.odometry_compared.saturating_sub(tf0.odometry_compared);
        let disagreed = tf.odometry_disagreed.saturating_sub(tf0.odometry_disagreed);
        if disagreed > 0 && share(disagreed, compared) > 0.5 {
            out.push(Finding::new(
                Check::OdometryDisagreesWithTf,
                format!(
                    "{disagreed} of {compared} poses of tf's `{}` → `{}` differ from the odometry topic's at the same \
                     stamp (up to {:.3} m, {:.2}°)",
                    observed.tf.world_frame, observed.tf.body_frame, tf.odometry_max_m, tf.odometry_max_deg
                ),
            ));
        }
        let frames = sync.frames - w.frames.min(sync.frames);
        // Frames unlabelled for want of the camera's mount are `no_mount`'s, not the segmenter's.
        let unlabelled = (sync.unlabelled.saturating_sub(w.unlabelled))
            .saturating_sub(sync.no_camera_mount.saturating_sub(w.no_camera_mount))
            + sync.no_image.saturating_sub(w.no_image);
        let labelled_or_not = frames + sync.no_image.saturating_sub(w.no_image);
        if share(unlabelled, labelled_or_not) > self.config.max_unlabelled_share {
            out.push(Finding::new(
                Check::NoLabels,
                format!(
                    "{unlabelled} of the last {labelled_or_not} clouds had no label image within \
                     ros.sync.max_label_skew_s (largest skew of a labelled one so far: {} ms)",
                    sync.label_skew_max_ms
                ),
            ));
        }
        let points = sync.sampled_points.saturating_sub(w.sampled_points);
        let in_image = sync.sampled_in_image.saturating_sub(w.sampled_in_image);
        if points > 0 && share(in_image, points) < self.config.min_points_in_image_share {
            out.push(Finding::new(
                Check::PointsOutsideImage,
                format!(
                    "{in_image} of {points} points sampled from the last labelled frames project into the \
                     label image ({:.2} %)",
                    100.0 * share(in_image, points)
                ),
            ));
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

    fn tf() -> TfStatus {
        crate::tf::listener::TfListener::pinned(sgm_model::geometry::Pose3::identity()).status()
    }

    /// Feeds `sync` and `objects` with no other news.
    fn update(h: &mut Health, now: f64, sync: &SyncCounts, objects: usize) -> Vec<Finding> {
        let (inputs, tf) = (BTreeMap::new(), tf());
        h.update(now, &Observed { sync, inputs: &inputs, tf: &tf, missing_mount: None, objects: Some(objects) })
    }

    fn checks(f: &[Finding]) -> Vec<Check> {
        f.iter().map(|f| f.check).collect()
    }

    #[test]
    fn healthy_streams_raise_nothing() {
        let mut h = Health::new(HealthConfig::default());
        for k in 1..=100u64 {
            assert!(update(&mut h, k as f64, &counts(k, k / 10, 0), 5).is_empty());
        }
    }

    /// A segmenter that dies after 100 frames: the next window says so, though the mission's
    /// whole share is still under half; it stays listed while it holds and clears after.
    #[test]
    fn a_segmenter_that_stops_is_seen_within_a_window() {
        let mut h = Health::new(HealthConfig::default());
        assert!(update(&mut h, 10.0, &counts(100, 0, 0), 3).is_empty());
        let f = update(&mut h, 20.0, &counts(150, 50, 0), 3);
        assert_eq!(checks(&f), vec![Check::NoLabels]);
        assert!(f[0].detail.starts_with("50 of the last 50 clouds"), "{}", f[0].detail);
        assert!(f[0].likely_cause.contains("max_label_skew_s"));
        assert_eq!(
            checks(&update(&mut h, 21.0, &counts(160, 60, 0), 3)),
            vec![Check::NoLabels],
            "held until the window ends"
        );
        assert!(update(&mut h, 30.0, &counts(210, 60, 0), 3).is_empty(), "labels came back");
    }

    #[test]
    fn clouds_without_odometry_are_a_finding() {
        let mut h = Health::new(HealthConfig::default());
        let f = update(&mut h, 5.0, &counts(10, 0, 40), 1);
        assert_eq!(checks(&f), vec![Check::NoOdometry]);
        assert!(f[0].detail.contains("40 of the last 50 clouds"), "{}", f[0].detail);
    }

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

    /// An odometry whose frames the configuration does not expect: every message refused, said
    /// once with the topic and the reason.
    #[test]
    fn a_refused_input_is_named_with_its_reason() {
        let mut h = Health::new(HealthConfig { window_frames: 10, ..Default::default() });
        let mut inputs = BTreeMap::new();
        inputs.insert(
            "odometry".to_string(),
            TopicTally {
                accepted: 0,
                refused: 40,
                last_refusal: Some("frame `camera_init`, `alpha/odom` expected".into()),
            },
        );
        inputs.insert("points".to_string(), TopicTally { accepted: 40, ..Default::default() });
        let (sync, tf) = (SyncCounts { no_odometry: 40, ..Default::default() }, tf());
        let f =
            h.update(0.0, &Observed { sync: &sync, inputs: &inputs, tf: &tf, missing_mount: None, objects: Some(0) });
        assert_eq!(checks(&f), vec![Check::InputRefused, Check::NoOdometry]);
        assert_eq!(
            f[0].detail,
            "40 of the last 40 messages on odometry refused (last: frame `camera_init`, `alpha/odom` expected)"
        );
        assert!(f[0].likely_cause.contains("ros.frames.aliases"));
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
