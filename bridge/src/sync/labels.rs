//! A cloud's labels: its own label field (`labels = "cloud"`), or the label image nearest its
//! stamp. An image within `image_tolerance_s` labels it with the skew left to Fusion (which
//! compensates it at the odometry's velocity); one farther but within `max_label_skew_s` labels
//! it with the body's motion in between compensated here (the odometry at both stamps), or by
//! Fusion at the odometry's velocity with the robot's own odometry (no poses here); a cloud no
//! image reaches is kept without labels or dropped (`unlabelled`), or with the robot's own
//! odometry handed to it alone as a sweep. The share of a labelled frame's points that lands in the image is sampled.

use super::{Outcome, Synchroniser};
use crate::config::{LabelSource, Unlabelled};
use crate::convert::cloud::{Scan, NO_LABEL};
use sgm_actors::config::OdometrySource;
use sgm_actors::messages::FrameLabels;
use sgm_model::geometry::Pose3;
use sgm_model::perception::projection::LabelImage;
use sgm_model::scene_graph::{LabelId, Stamp};

/// Every this-many-th point of a labelled frame is projected to count the share that lands in
/// the label image (a share needs no more; the full projection is Fusion's).
pub const PROJECTION_SAMPLE: usize = 16;

impl Synchroniser {
    /// The label image nearest `t` within `max_label_skew_s`, with its stamp; `Ready(None)`
    /// when none is or will be; `Wait` while a nearer one may still come (never once `stale`).
    pub(super) fn image_near(&self, t: Stamp, stale: bool) -> Outcome<Option<(Stamp, LabelImage)>> {
        let reach = self.config.max_label_skew_s.max(self.config.image_tolerance_s);
        let after = self.images.partition_point(|(s, _)| *s < t);
        let next = self.images.get(after);
        let previous = after.checked_sub(1).and_then(|k| self.images.get(k));
        let nearest = [previous, next]
            .into_iter()
            .flatten()
            .filter(|(s, _)| (s - t).abs() <= reach)
            .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()));
        // Images come in stamp order: one at or after t settles it, as does the input's end.
        let settled = next.is_some() || self.ended || stale;
        match nearest {
            Some((s, image)) if settled => Outcome::Ready(Some((*s, image.clone()))),
            Some(_) => Outcome::Wait,
            None if settled => Outcome::Ready(None),
            None => Outcome::Wait,
        }
    }

    /// A cloud no image labels: assembled without labels, or dropped, as configured.
    pub(super) fn without_image(&mut self, scan: &Scan) -> Outcome<FrameLabels> {
        match self.config.unlabelled {
            Unlabelled::Keep => {
                self.counts.unlabelled += 1;
                Outcome::Ready(FrameLabels::PerPoint(vec![None; scan.points.len()]))
            }
            // The robot's own odometry still registers it (counted as a sweep).
            Unlabelled::Drop if self.source == OdometrySource::Internal => Outcome::Ready(FrameLabels::Unlabelled),
            Unlabelled::Drop => {
                self.counts.no_image += 1;
                Outcome::Drop
            }
        }
    }

    /// The labels of `scan` (points still in the LiDAR's frame, `body_from_lidar` away).
    pub(super) fn labels_for(
        &mut self,
        t: Stamp,
        world_from_body: &Pose3,
        scan: &Scan,
        body_from_lidar: &Pose3,
        stale: bool,
    ) -> Outcome<FrameLabels> {
        match self.labels {
            LabelSource::Cloud => match &scan.labels {
                Some(labels) => Outcome::Ready(FrameLabels::PerPoint(
                    labels.iter().map(|&l| (l != NO_LABEL).then_some(LabelId(l))).collect(),
                )),
                None if self.source == OdometrySource::Internal => Outcome::Ready(FrameLabels::Unlabelled),
                None => {
                    self.counts.no_label_field += 1;
                    Outcome::Drop
                }
            },
            LabelSource::Image => {
                let Some(camera) = self.camera.clone() else { return Outcome::Wait };
                let (t_image, image) = match self.image_near(t, stale) {
                    Outcome::Ready(Some(found)) => found,
                    Outcome::Ready(None) => return self.without_image(scan),
                    Outcome::Wait => return Outcome::Wait,
                    Outcome::Drop => return Outcome::Drop,
                };
                let Some(mounted) = self.tf.camera_from_body() else {
                    if !stale {
                        return Outcome::Wait;
                    }
                    self.counts.no_camera_mount += 1;
                    return self.without_image(scan);
                };
                let skew = (t_image - t).abs();
                // Within the tolerance Fusion compensates the skew at the odometry's velocity; so
                // it does beyond it with the robot's own odometry, whose poses are not here.
                let internal = self.source == OdometrySource::Internal;
                let (camera_from_body, image_offset_s) = if skew <= self.config.image_tolerance_s || internal {
                    (mounted, t_image - t)
                } else {
                    match self.pose_at(t_image) {
                        Outcome::Ready(world_from_body_at_image) => {
                            self.counts.compensated += 1;
                            (mounted * world_from_body_at_image.inverse() * world_from_body, 0.0)
                        }
                        Outcome::Wait if !stale => return Outcome::Wait,
                        // No odometry at the image's stamp: its labels cannot be placed.
                        _ => return self.without_image(scan),
                    }
                };
                let skew_ms = (skew * 1000.0).ceil() as u64;
                self.counts.label_skew_max_ms = self.counts.label_skew_max_ms.max(skew_ms);
                self.counts.label_skew_sum_ms = self.counts.label_skew_sum_ms.saturating_add(skew_ms);
                let camera_from_lidar = camera_from_body * body_from_lidar;
                let sample = scan.points.iter().step_by(PROJECTION_SAMPLE);
                let in_image = sample
                    .clone()
                    .filter(|p| camera.project(&(camera_from_lidar * *p)).and_then(|uv| camera.pixel(uv)).is_some())
                    .count();
                self.counts.sampled_points += sample.count() as u64;
                self.counts.sampled_in_image += in_image as u64;
                Outcome::Ready(FrameLabels::Image { image, camera, camera_from_body, image_offset_s })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::SyncConfig;
    use crate::convert::time::Epoch;
    use crate::inputs::{Inputs, Payload};
    use crate::sync::fixtures::{camera, image, scan};
    use nalgebra::{Point3, UnitQuaternion, Vector3};

    /// A segmenter at 2 Hz beside a LiDAR at 10 Hz: every cloud is assembled. Those within
    /// `image_tolerance_s` of an image take it as it is, those within `max_label_skew_s` take
    /// the nearest with the motion compensated, and the skew is counted.
    #[test]
    fn a_slow_segmenter_labels_every_cloud_with_the_motion_compensated() {
        let mut s = Synchroniser::new(SyncConfig::default(), LabelSource::Image, Pose3::identity());
        s.camera_info(camera());
        // The body moves along x at 1 m/s.
        let at = |t: f64| Pose3::from_parts(Vector3::new(t, 0.0, 0.0).into(), UnitQuaternion::identity());
        let mut frames = Vec::new();
        for k in 0..=20 {
            let t = k as f64 * 0.1;
            s.odometry(t, at(t));
            if k % 5 == 0 {
                s.image(t, image());
            }
            s.cloud(t, scan(2));
            frames.extend(s.ready());
        }
        frames.extend(s.finish(Epoch { sec: 0 }));
        assert_eq!(frames.len(), 21);
        assert_eq!((s.counts.frames, s.counts.compensated, s.counts.unlabelled, s.counts.no_image), (21, 16, 0, 0));
        assert_eq!(s.counts.label_skew_max_ms, 201); // 0.2 s, rounded up through the float
                                                     // The cloud at 0.3 s takes the image at 0.5 s: the body moves 0.2 m forward (+x) in
                                                     // between, so a body point at the cloud's time is 0.2 m nearer along the optical axis
                                                     // (camera_from_body is the identity here): x_camera = x_body(0.3) − 0.2 (closed form).
        let FrameLabels::Image { camera_from_body, .. } = &frames[3].labels else { panic!("labelled") };
        assert!((frames[3].stamp - 0.3).abs() < 1e-12);
        let p = camera_from_body * Point3::new(1.0, 0.0, 0.0);
        assert!((p.x - 0.8).abs() < 1e-9, "{p}");
        // The cloud at 0.5 s is the image's own: as it is.
        let FrameLabels::Image { camera_from_body, .. } = &frames[5].labels else { panic!("labelled") };
        assert_eq!(*camera_from_body, Pose3::identity());
    }

    /// No image within reach: the cloud still feeds the map, without labels; with no odometry
    /// at the image's stamp to compensate with, the same.
    #[test]
    fn a_cloud_no_image_reaches_is_kept_without_labels() {
        let mut s = Synchroniser::new(SyncConfig::default(), LabelSource::Image, Pose3::identity());
        s.camera_info(camera());
        s.odometry(0.0, Pose3::identity());
        s.odometry(0.2, Pose3::identity());
        s.image(0.0, image());
        s.cloud(0.1, scan(3)); // the image 0.1 s before; odometry brackets it: compensated
        s.odometry(2.0, Pose3::identity());
        s.cloud(1.5, scan(3)); // the odometry gap (0.2 → 2.0) is too wide: no pose, dropped
        s.odometry(2.1, Pose3::identity());
        s.cloud(2.05, scan(3)); // the last image is 2.05 s before: unlabelled
        s.image(3.0, image());
        let frames = s.ready();
        assert_eq!(frames.len(), 2);
        assert!(matches!(&frames[1].labels, FrameLabels::PerPoint(l) if l == &vec![None; 3]));
        assert_eq!((s.counts.compensated, s.counts.unlabelled, s.counts.no_odometry), (1, 1, 1));
    }

    /// The camera's mount missing: a cloud with its image is kept without labels once stale
    /// (counted as `no_camera_mount`); with tf it is labelled, and the share of its points
    /// in the image is counted (closed form: the point 1 m ahead projects, the one behind not).
    #[test]
    fn a_missing_camera_mount_leaves_frames_unlabelled_and_projection_is_counted() {
        use crate::config::RosConfig;
        use crate::tf::{TfBatch, TfTransform};
        let mut ros = RosConfig::default();
        ros.timeline.confirm_messages = 1;
        let inputs = Inputs::new(&ros, "alpha", 1);
        let mut s = Synchroniser::for_robot(&ros, &inputs, OdometrySource::External).unwrap();
        let epoch = Epoch { sec: 100 };
        let at = |t: f64| epoch.time(t);
        // Sampled: the 1st and the 17th point, one ahead and one behind.
        let mut points = vec![Point3::new(1.0, 0.0, 0.0); PROJECTION_SAMPLE];
        points.push(Point3::new(-1.0, 0.0, 0.0));
        let two_points = Scan { points, labels: None, dropped_non_finite: 0, times: None };
        s.camera_info(camera());
        s.feed(epoch, Payload::Odometry(at(0.0), Pose3::identity()));
        s.feed(epoch, Payload::Image(at(0.0), image(), Default::default()));
        s.feed(epoch, Payload::Cloud(at(0.0), two_points.clone()));
        s.feed(epoch, Payload::Odometry(at(2.0), Pose3::identity()));
        let frames = s.ready();
        assert_eq!(frames.len(), 1);
        assert!(matches!(frames[0].labels, FrameLabels::PerPoint(_)), "kept without labels");
        assert_eq!((s.counts.no_camera_mount, s.counts.unlabelled), (1, 1));
        assert!(s.missing_mount().unwrap().contains("camera mount `alpha/base_link` ← `alpha/camera`"));

        let optical = sgm_model::perception::projection::optical_from_forward_body().inverse();
        let mount = TfTransform {
            stamp: rosrust::Time::default(),
            parent: "alpha/base_link".into(),
            child: "alpha/camera".into(),
            parent_from_child: optical,
        };
        s.feed(epoch, Payload::Tf(TfBatch { is_static: true, transforms: vec![mount], refused: vec![] }));
        s.feed(epoch, Payload::Image(at(2.0), image(), Default::default()));
        s.feed(epoch, Payload::Cloud(at(2.0), two_points));
        s.feed(epoch, Payload::Odometry(at(2.1), Pose3::identity()));
        let frames = s.ready();
        assert!(matches!(frames[0].labels, FrameLabels::Image { .. }), "labelled");
        assert_eq!((s.counts.sampled_points, s.counts.sampled_in_image), (2, 1));
    }
}
