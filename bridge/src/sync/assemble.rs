//! A cloud meets its odometry pose and the LiDAR's mount and is assembled into a
//! [`SensorFrame`]: the pose stamped exactly at the cloud's stamp, else interpolated between
//! the two bracketing poses if they are at most `max_odometry_gap_s` apart. A cloud waits while
//! its partners may still come, and once the streams are `max_wait_s` past it (or the input has
//! ended) takes what there is or is dropped and counted. With the robot's own odometry a cloud
//! waits for the IMU to pass its sweep's end instead of a pose, takes the samples since the
//! previous frame, and reaches the odometry even when no label does (a sweep).

use super::{with_stamp, Outcome, Synchroniser, Waiting};
use crate::convert::time::Epoch;
use sgm_actors::config::OdometrySource;
use sgm_actors::messages::{FrameLabels, SensorFrame};
use sgm_model::geometry::Pose3;
use sgm_model::scene_graph::Stamp;

impl Synchroniser {
    pub(super) fn pose_at(&self, t: Stamp) -> Outcome<Pose3> {
        let after = self.odometry.partition_point(|(s, _)| *s < t);
        match (after.checked_sub(1).and_then(|k| self.odometry.get(k)), self.odometry.get(after)) {
            (_, Some((s1, p1))) if *s1 == t => Outcome::Ready(*p1),
            (Some((s0, p0)), Some((s1, p1))) if s1 - s0 <= self.config.max_odometry_gap_s => {
                Outcome::Ready(sgm_model::geometry::interpolate(p0, p1, (t - s0) / (s1 - s0)))
            }
            (Some(_), Some(_)) => Outcome::Drop,
            (_, None) => Outcome::Wait,
            (None, Some(_)) => Outcome::Drop,
        }
    }

    /// The frames that can be assembled now, oldest first; stale clouds are dropped.
    pub fn ready(&mut self) -> Vec<SensorFrame> {
        let internal = self.source == OdometrySource::Internal;
        let mut frames = Vec::new();
        while let Some((t, waiting)) = self.clouds.front() {
            let (t, sweep_end) = (*t, waiting.sweep_end);
            let stale = self.ended || self.latest - t > self.config.max_wait_s;
            // The robot's own odometry sets the pose: the cloud waits for its sweep's IMU samples.
            let imu_covered = self.imu.covers(sweep_end);
            let pose = match internal {
                true if !imu_covered && !stale => break,
                true => Pose3::identity(),
                false => match self.pose_at(t) {
                    Outcome::Ready(pose) => pose,
                    Outcome::Wait if !stale => break,
                    _ => {
                        self.counts.no_odometry += 1;
                        self.clouds.pop_front();
                        continue;
                    }
                },
            };
            let Some(body_from_lidar) = self.tf.body_from_lidar() else {
                if !stale {
                    break;
                }
                self.counts.no_lidar_mount += 1;
                self.clouds.pop_front();
                continue;
            };
            let body_from_imu = match self.tf.body_from_imu() {
                Some(mount) => Some(mount),
                None if !internal => None,
                None if !stale => break,
                None => {
                    if self.counts.no_imu_mount == 0 {
                        let why = self.tf.missing(false).unwrap_or_default();
                        tracing::warn!(stamp = t, "a cloud dropped: {why} (counted in the status's sync.no_imu_mount)");
                    }
                    self.counts.no_imu_mount += 1;
                    self.clouds.pop_front();
                    continue;
                }
            };
            let Some((_, Waiting { mut scan, .. })) = self.clouds.pop_front() else { break };
            let labels = match self.labels_for(t, &pose, &scan, &body_from_lidar, stale) {
                Outcome::Ready(labels) => labels,
                Outcome::Wait if !stale => {
                    self.clouds.push_front((t, Waiting { scan, sweep_end }));
                    break;
                }
                // The odometry still registers a sweep whose labels never came.
                Outcome::Wait | Outcome::Drop if internal => FrameLabels::Unlabelled,
                Outcome::Wait => {
                    if self.camera.is_none() {
                        self.counts.no_camera_info += 1;
                    } else {
                        self.counts.no_image += 1;
                    }
                    continue;
                }
                Outcome::Drop => continue,
            };
            if matches!(labels, FrameLabels::Unlabelled) {
                self.counts.sweeps += 1;
            } else {
                self.counts.frames += 1;
            }
            if internal && !imu_covered {
                if self.counts.imu_short == 0 {
                    tracing::warn!(
                        stamp = t,
                        "a cloud went to the odometry before the IMU covered its sweep: the \
                        IMU is silent, late or on another clock (counted in the status's sync.imu_short)"
                    );
                }
                self.counts.imu_short += 1;
            }
            // Points into the body frame (the labels stay with their points).
            if body_from_lidar != Pose3::identity() {
                for p in &mut scan.points {
                    *p = body_from_lidar * *p;
                }
            }
            let imu = body_from_imu.map(|mount| self.imu.take_until(sweep_end, &mount)).unwrap_or_default();
            frames.push(SensorFrame {
                stamp: t,
                odom_from_body: pose,
                points_in_body: scan.points,
                point_times: scan.times,
                points_deskewed: false,
                labels,
                imu,
                motion_covariance: None,
                measured_up: None,
            });
        }
        self.prune();
        frames
    }

    /// The input has ended (the last message of a bag): the frames that can still be
    /// assembled, with the nearest image in tolerance and no waiting for later partners; every
    /// other waiting cloud is dropped and counted. Afterwards nothing is pending.
    pub fn finish(&mut self, epoch: Epoch) -> Vec<SensorFrame> {
        for (t, payload) in self.timeline.finish() {
            self.feed_checked(epoch, with_stamp(payload, t));
        }
        self.ended = true;
        self.ready()
    }

    /// Forgets odometry and images no waiting or future cloud can use.
    fn prune(&mut self) {
        // A waiting cloud may take an image up to max_label_skew_s before it, and needs the
        // odometry around that image to compensate.
        let reach = self.config.max_label_skew_s.max(self.config.image_tolerance_s);
        let horizon = self.clouds.front().map_or(self.latest - self.config.max_wait_s, |(t, _)| *t)
            - self.config.max_odometry_gap_s.max(reach);
        while self.odometry.len() > 1 && self.odometry.get(1).is_some_and(|(t, _)| *t < horizon) {
            self.odometry.pop_front();
        }
        while self.images.front().is_some_and(|(t, _)| *t < horizon) {
            self.images.pop_front();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{LabelSource, SyncConfig, Unlabelled};
    use crate::sync::fixtures::{camera, image, scan};
    use nalgebra::{UnitQuaternion, Vector3};
    use sgm_actors::messages::FrameLabels;
    use sgm_model::scene_graph::LabelId;

    /// A bag that ends before a cloud's partners: the cloud waits until the input ends, then
    /// is assembled if it can be (an image in tolerance) or dropped and counted, never left
    /// pending (a replay waits for nothing pending).
    #[test]
    fn the_end_of_input_settles_every_waiting_cloud() {
        let pose = Pose3::identity();
        // Odometry stops before the last cloud: it can never get a pose.
        let mut s = Synchroniser::new(SyncConfig::default(), LabelSource::Cloud, Pose3::identity());
        s.odometry(0.0, pose);
        s.cloud(0.0, scan(3));
        s.cloud(0.5, scan(3));
        assert_eq!(s.ready().len(), 1);
        assert_eq!(s.pending(), 1, "the second cloud waits for odometry after it");
        assert!(s.finish(Epoch { sec: 0 }).is_empty());
        assert_eq!((s.pending(), s.counts.no_odometry, s.counts.frames), (0, 1, 1));

        // The only image is 10 ms before the cloud, in tolerance: a closer one might still come
        // after it, but the bag has ended, so the cloud takes it.
        let mut s = Synchroniser::new(SyncConfig::default(), LabelSource::Image, Pose3::identity());
        s.camera_info(camera());
        s.odometry(0.0, pose);
        s.odometry(0.4, pose);
        s.image(0.19, image());
        s.cloud(0.2, scan(3));
        assert!(s.ready().is_empty());
        assert_eq!(s.pending(), 1);
        let frames = s.finish(Epoch { sec: 0 });
        assert_eq!((frames.len(), s.pending(), s.counts.no_image), (1, 0, 0));
        assert!(matches!(frames[0].labels, FrameLabels::Image { .. }));
    }

    #[test]
    fn exact_odometry_is_used_as_is_and_gaps_are_interpolated() {
        let mut s = Synchroniser::new(SyncConfig::default(), LabelSource::Cloud, Pose3::identity());
        let p0 = Pose3::from_parts(Vector3::new(0.0, 0.0, 0.0).into(), UnitQuaternion::identity());
        let p1 =
            Pose3::from_parts(Vector3::new(2.0, 0.0, 0.0).into(), UnitQuaternion::from_euler_angles(0.0, 0.0, 0.4));
        s.cloud(0.15, scan(2));
        s.odometry(0.1, p0);
        assert!(s.ready().is_empty(), "waits for the odometry after it");
        s.odometry(0.2, p1);
        s.cloud(0.2, scan(1));
        let frames = s.ready();
        assert_eq!(frames.len(), 2);
        // Halfway: x = 1, yaw = 0.2 (closed form).
        assert!((frames[0].odom_from_body.translation.vector.x - 1.0).abs() < 1e-12);
        assert!((frames[0].odom_from_body.rotation.euler_angles().2 - 0.2).abs() < 1e-12);
        assert_eq!(frames[1].odom_from_body, p1);
        assert!(matches!(&frames[0].labels, FrameLabels::PerPoint(l) if l == &vec![Some(LabelId(3)); 2]));
    }

    #[test]
    fn clouds_without_partners_are_dropped_once_stale() {
        let config = SyncConfig { unlabelled: Unlabelled::Drop, ..SyncConfig::default() };
        let mut s = Synchroniser::new(config, LabelSource::Image, Pose3::identity());
        s.odometry(0.0, Pose3::identity());
        s.odometry(2.0, Pose3::identity());
        s.cloud(1.0, scan(1)); // odometry gap of 2 s > 0.5: no pose
        assert!(s.ready().is_empty());
        assert_eq!(s.counts.no_odometry, 1);
        s.odometry(2.1, Pose3::identity());
        s.cloud(2.05, scan(1)); // no camera info yet: waits, then stale
        assert!(s.ready().is_empty());
        assert_eq!(s.pending(), 1);
        s.odometry(3.5, Pose3::identity());
        assert!(s.ready().is_empty());
        assert_eq!(s.counts.no_camera_info, 1);
        s.camera_info(camera());
        s.odometry(3.6, Pose3::identity());
        s.image(3.52, image());
        s.cloud(3.55, scan(1)); // image 0.03 s before: within tolerance, but a closer one may come
        assert!(s.ready().is_empty());
        s.image(3.62, image()); // an image after the cloud: nothing nearer can come now
        s.odometry(3.7, Pose3::identity());
        assert_eq!(s.ready().len(), 1);
        s.cloud(3.65, scan(1));
        s.image(3.9, image()); // nearest images 3.62 (0.03 off) and 3.9: 3.62 wins
        assert_eq!(s.ready().len(), 1);
        s.odometry(4.4, Pose3::identity());
        s.odometry(4.6, Pose3::identity());
        s.cloud(4.5, scan(1)); // images at 3.9 and 5.2: both beyond max_label_skew_s (0.5)
        s.image(5.2, image());
        assert!(s.ready().is_empty());
        assert_eq!((s.counts.no_image, s.pending()), (1, 0));
        assert_eq!((s.counts.frames, s.counts.compensated, s.counts.unlabelled), (2, 0, 0));
    }
}
