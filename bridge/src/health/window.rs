//! The shares judged over a window of `window_frames` clouds (assembled or dropped): refused
//! inputs, missing mounts, clouds without odometry or labels, odometry tf contradicts, points
//! outside the label image. Counts only grow, so a window is the difference between the counts
//! now and at its start.

use super::finding::{Check, Finding};
use super::observed::{Observed, TopicTally};
use super::Health;
use crate::sync::SyncCounts;
use crate::tf::listener::TfCounts;
use std::collections::BTreeMap;

/// Where the current window started.
#[derive(Clone, Debug, Default)]
pub(super) struct WindowStart {
    pub(super) sync: SyncCounts,
    pub(super) inputs: BTreeMap<String, TopicTally>,
    pub(super) tf: TfCounts,
}

/// Clouds the synchroniser settled (assembled or dropped for any reason).
pub(super) fn settled(c: &SyncCounts) -> u64 {
    c.frames
        + c.sweeps
        + c.no_odometry
        + c.no_image
        + c.no_camera_info
        + c.no_label_field
        + c.at_restart
        + c.no_lidar_mount
        + c.no_imu_mount
}

fn share(part: u64, whole: u64) -> f64 {
    if whole == 0 {
        0.0
    } else {
        part as f64 / whole as f64
    }
}

impl Health {
    pub(super) fn window(&self, observed: &Observed, clouds: u64) -> Vec<Finding> {
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
            + sync.no_camera_mount.saturating_sub(w.no_camera_mount)
            + sync.no_imu_mount.saturating_sub(w.no_imu_mount);
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
        let imu_short = sync.imu_short.saturating_sub(w.imu_short);
        if share(imu_short, clouds) > self.config.max_no_odometry_share {
            out.push(Finding::new(
                Check::ImuShort,
                format!("{imu_short} of the last {clouds} clouds came before the IMU covered their sweep"),
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
        // With the robot's own odometry a cloud without labels is a sweep, and many are by design
        // (a LiDAR faster than its segmenter): only a window without any labelled frame says the
        // labels stopped.
        let sweeps = sync.sweeps.saturating_sub(w.sweeps);
        if frames == 0 && sweeps > 0 && !out.iter().any(|f| f.check == Check::NoLabels) {
            out.push(Finding::new(
                Check::NoLabels,
                format!("none of the last {clouds} clouds was labelled: {sweeps} went to the odometry alone"),
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
    use crate::health::fixtures::{checks, counts, tf, update};
    use crate::health::HealthConfig;

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

    /// The robot's own odometry with a silent IMU: the clouds come short of it (each a sweep or a
    /// frame), and an unknown IMU mount drops them; both are findings, and both count as
    /// clouds in the window. A window of sweeps and no labelled frame says the labels stopped.
    #[test]
    fn clouds_short_of_the_imu_or_its_mount_are_findings() {
        let mut h = Health::new(HealthConfig::default());
        let sync = SyncCounts { frames: 10, sweeps: 40, imu_short: 45, ..Default::default() };
        let f = update(&mut h, 5.0, &sync, 1);
        assert_eq!(checks(&f), vec![Check::ImuShort]);
        assert!(f[0].detail.contains("45 of the last 50 clouds"), "{}", f[0].detail);
        assert!(f[0].likely_cause.contains("ros.topics.imu"));
        let sync = SyncCounts { no_imu_mount: 100, ..sync };
        let f = update(&mut h, 6.0, &sync, 1);
        assert_eq!(checks(&f), vec![Check::NoMount], "{f:?}");
        assert!(f[0].detail.starts_with("100 of the last 100 clouds without a sensor mount"), "{}", f[0].detail);
        // The segmenter stops: every cloud a sweep, none labelled.
        let sync = SyncCounts { sweeps: sync.sweeps + 50, ..sync };
        let f = update(&mut h, 7.0, &sync, 1);
        assert_eq!(checks(&f), vec![Check::NoLabels], "{f:?}");
        assert!(f[0].detail.starts_with("none of the last 50 clouds was labelled: 50 went to"), "{}", f[0].detail);
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
}
