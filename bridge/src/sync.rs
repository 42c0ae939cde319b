//! The synchroniser: three streams in (clouds, odometry, label images + camera info), typed
//! [`SensorFrame`]s out — the same code for the live node and the bag replay. A cloud gets the
//! odometry pose at its stamp (the pose stamped exactly then, else interpolated between the two
//! bracketing poses — linear in translation, slerp in rotation — if they are at most
//! `max_odometry_gap_s` apart) and the label image nearest its stamp. An image within
//! `image_tolerance_s` labels it as it is; one farther but within `max_label_skew_s` (a
//! segmenter slower than the LiDAR) labels it with the body's motion in between compensated:
//!
//! ```text
//! camera(t_img)_from_body(t) = camera_from_body · world_from_body(t_img)⁻¹ · world_from_body(t)
//! ```
//!
//! (what moves in the scene meanwhile is not compensated). A cloud no image reaches is
//! assembled without labels (`unlabelled = "keep"`) or dropped. Images come in stamp order, so
//! once one at or after the cloud's stamp is in, no later one can be nearer. A cloud waits
//! while its partners may still come; once the streams are `max_wait_s` past it, it takes what
//! there is, or is dropped and counted. Time here is the streams' own (header stamps), never the wall
//! clock, so a replay is deterministic. Every buffer is bounded.
//!
//! Stamps are checked first by the [`Timeline`]: a stamp far from its stream waits until others
//! confirm it (a jump: the timeline restarts, the buffers start afresh and mission time goes on)
//! or is dropped as an outlier (a glitch), so one bad stamp never stops the streams.

use crate::config::{LabelSource, SyncConfig, Unlabelled};
use crate::convert::cloud::{Scan, NO_LABEL};
use crate::convert::image::UnknownColours;
use crate::convert::time::Epoch;
use crate::inputs::{Inputs, Payload};
use crate::tf::listener::{TfListener, TfStatus};
use crate::tf::mounts::Mount;
use crate::timeline::{Timeline, TimelineConfig, TimelineCounts};
use serde::Serialize;
use sgm_actors::messages::{FrameLabels, SensorFrame};
use sgm_model::geometry::Pose3;
use sgm_model::perception::colour_ids::hex;
use sgm_model::perception::projection::{CameraModel, LabelImage};
use sgm_model::scene_graph::{LabelId, Stamp};
use std::collections::{BTreeMap, VecDeque};

/// Every this-many-th point of a labelled frame is projected to count the share that lands in
/// the label image (a share needs no more; the full projection is Fusion's).
pub const PROJECTION_SAMPLE: usize = 16;

/// At most this many messages wait in each stream's buffer (the oldest goes first).
const MAX_BUFFERED: usize = 1000;

/// What became of the clouds.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct SyncCounts {
    pub frames: u64,
    pub no_odometry: u64,
    pub no_image: u64,
    pub no_camera_info: u64,
    pub no_label_field: u64,
    pub out_of_order: u64,
    pub overflow: u64,
    /// Clouds still waiting for partners when the timeline restarted (dropped).
    pub at_restart: u64,
    /// Frames labelled by an image farther than `image_tolerance_s`, motion-compensated.
    pub compensated: u64,
    /// Frames assembled without labels: no image within `max_label_skew_s`, or no odometry at
    /// the image's stamp to compensate with (`unlabelled = "keep"`).
    pub unlabelled: u64,
    /// The largest |image stamp − cloud stamp| of a labelled frame, ms (rounded up).
    pub label_skew_max_ms: u64,
    /// Sum of |image stamp − cloud stamp| over labelled frames, ms (mean = sum / labelled).
    pub label_skew_sum_ms: u64,
    /// Clouds dropped because the LiDAR's mount is unknown (not pinned, not in tf).
    pub no_lidar_mount: u64,
    /// Clouds that found their image but not the camera's mount (then kept unlabelled or
    /// dropped as `unlabelled` says; counted there too).
    pub no_camera_mount: u64,
    /// A sample of the points of labelled frames (every [`PROJECTION_SAMPLE`]-th), and those of
    /// them that project into the label image (`points_outside_image`).
    pub sampled_points: u64,
    pub sampled_in_image: u64,
    /// Pixels of colour label images whose colour the palette lacks (no class), and per
    /// colour (`#rrggbb`, the first 32 colours seen).
    pub unknown_colour_pixels: u64,
    pub unknown_colours: BTreeMap<String, u64>,
}

pub struct Synchroniser {
    config: SyncConfig,
    labels: LabelSource,
    /// The sensors' mounts (pinned or from tf) and tf's view of the odometry.
    tf: TfListener,
    odometry: VecDeque<(Stamp, Pose3)>,
    images: VecDeque<(Stamp, LabelImage)>,
    camera: Option<CameraModel>,
    clouds: VecDeque<(Stamp, Scan)>,
    latest: Stamp,
    /// No more input will come (a bag's end): nothing waits for a partner any longer.
    ended: bool,
    timeline: Timeline<Payload>,
    /// Newest `/clock` time passed by the timeline (mission time).
    clock: Option<Stamp>,
    pub counts: SyncCounts,
}

enum Outcome<T> {
    Ready(T),
    Wait,
    Drop,
}

fn push_bounded<T>(queue: &mut VecDeque<(Stamp, T)>, t: Stamp, value: T, overflow: &mut u64) -> bool {
    if queue.back().is_some_and(|(last, _)| t < *last) {
        return false;
    }
    if queue.len() == MAX_BUFFERED {
        queue.pop_front();
        *overflow += 1;
    }
    queue.push_back((t, value));
    true
}

impl Synchroniser {
    /// Clouds in the body frame and the camera pinned at `camera_from_body` (tf unused).
    pub fn new(config: SyncConfig, labels: LabelSource, camera_from_body: Pose3) -> Self {
        Self::with_mounts(config, labels, TfListener::pinned(camera_from_body))
    }

    /// A robot's synchroniser as its `[ros]` section says: mounts pinned there or read from tf
    /// between the frames `inputs` resolved, stamps checked by `ros.timeline`.
    pub fn for_robot(ros: &crate::config::RosConfig, inputs: &Inputs) -> Result<Self, crate::error::InputError> {
        let body = inputs.body_frame();
        let camera = Mount::new("camera", "ros.body_from_camera", body, inputs.camera_frame(), ros.camera_pin()?);
        let lidar = Mount::new("lidar", "ros.body_from_lidar", body, inputs.lidar_frame(), ros.lidar_pin()?);
        let tf = TfListener::new(ros.tf.clone(), inputs.world_frame(), body, camera, lidar);
        Ok(Self::with_mounts(ros.sync.clone(), ros.labels, tf).with_timeline(ros.timeline.clone()))
    }

    fn with_mounts(config: SyncConfig, labels: LabelSource, tf: TfListener) -> Self {
        Self {
            config,
            labels,
            tf,
            odometry: VecDeque::new(),
            images: VecDeque::new(),
            camera: None,
            clouds: VecDeque::new(),
            latest: f64::NEG_INFINITY,
            ended: false,
            timeline: Timeline::new(TimelineConfig::default()),
            clock: None,
            counts: SyncCounts::default(),
        }
    }

    /// With stamps checked by `config` (`[ros.timeline]`) instead of its defaults.
    pub fn with_timeline(mut self, config: TimelineConfig) -> Self {
        self.timeline = Timeline::new(config);
        self
    }

    /// What the timeline did: restarts, outliers, messages waiting.
    pub fn timeline(&self) -> &TimelineCounts {
        &self.timeline.counts
    }

    /// What tf gave: mounts, refusals, the odometry compared with tf.
    pub fn tf(&self) -> TfStatus {
        self.tf.status()
    }

    /// Why a mount the frames need is unknown (naming the frames), if one is.
    pub fn missing_mount(&self) -> Option<String> {
        self.tf.missing(self.labels == LabelSource::Image)
    }

    /// The ROS time of mission time `t` (for outputs), given the epoch stamps are counted from.
    pub fn ros_time(&self, epoch: Epoch, t: Stamp) -> rosrust::Time {
        self.timeline.to_ros(epoch.time(t))
    }

    /// The timeline restarted: nothing buffered can meet what comes next.
    fn restart(&mut self) {
        self.counts.at_restart += self.clouds.len() as u64;
        self.clouds.clear();
        self.odometry.clear();
        self.images.clear();
        self.latest = f64::NEG_INFINITY;
        self.clock = None;
    }

    fn saw(&mut self, t: Stamp) {
        self.latest = self.latest.max(t);
    }

    pub fn odometry(&mut self, t: Stamp, odom_from_body: Pose3) {
        self.saw(t);
        if !push_bounded(&mut self.odometry, t, odom_from_body, &mut self.counts.overflow) {
            self.counts.out_of_order += 1;
        }
        self.compare_odometry_with_tf();
    }

    /// tf's world → body samples the odometry now reaches, compared with its pose then.
    fn compare_odometry_with_tf(&mut self) {
        let Some(&(latest, _)) = self.odometry.back() else { return };
        for (t, tf_pose) in self.tf.odometry_samples_until(latest) {
            if let Outcome::Ready(pose) = self.pose_at(t) {
                self.tf.compared(&tf_pose, &pose);
            }
        }
    }

    /// Counts the pixels of colours the palette lacks; each colour is logged once.
    fn unknown_colours(&mut self, unknown: &UnknownColours) {
        for (rgb, n) in &unknown.colours {
            let name = hex(*rgb);
            self.counts.unknown_colour_pixels += u64::from(*n);
            if let Some(count) = self.counts.unknown_colours.get_mut(&name) {
                *count += u64::from(*n);
            } else if self.counts.unknown_colours.len() < 32 {
                tracing::warn!(colour = %name, "label image colour in no palette entry: its pixels carry no class (map it in [classes.palette])");
                self.counts.unknown_colours.insert(name, u64::from(*n));
            }
        }
        self.counts.unknown_colour_pixels += u64::from(unknown.other);
    }

    pub fn image(&mut self, t: Stamp, image: LabelImage) {
        self.saw(t);
        if !push_bounded(&mut self.images, t, image, &mut self.counts.overflow) {
            self.counts.out_of_order += 1;
        }
    }

    pub fn camera_info(&mut self, camera: CameraModel) {
        self.camera = Some(camera);
    }

    pub fn cloud(&mut self, t: Stamp, scan: Scan) {
        self.saw(t);
        if !push_bounded(&mut self.clouds, t, scan, &mut self.counts.overflow) {
            self.counts.out_of_order += 1;
        }
    }

    /// Feeds a checked input, its stamp taken from `epoch`. A true pose is not the
    /// synchroniser's business: it is handed back (stamped) to the caller.
    pub fn feed(&mut self, epoch: Epoch, payload: Payload) -> Option<(Stamp, Pose3)> {
        let stamp = match &payload {
            Payload::Cloud(t, _) | Payload::Image(t, ..) | Payload::Odometry(t, _) | Payload::Clock(t) => *t,
            Payload::CameraInfo(_) => {
                self.feed_checked(epoch, payload);
                return None;
            }
            Payload::GroundTruth(t, pose) => {
                return Some((epoch.stamp(self.timeline.to_mission(*t)), *pose));
            }
            // tf carries its own stamps (static ones are often 0): not the timeline's business.
            Payload::Tf(_) => {
                let Payload::Tf(batch) = payload else { return None };
                let timeline = &self.timeline;
                self.tf.feed(batch, |t| epoch.stamp(timeline.to_mission(t)));
                self.compare_odometry_with_tf();
                return None;
            }
        };
        let admitted = self.timeline.admit(stamp, payload);
        if let Some(restart) = admitted.restart {
            tracing::warn!(
                from_s = restart.from_s,
                to_s = restart.to_s,
                "sensor stamps jumped by {:.3} s and stayed there: the timeline restarts (mission time goes on)",
                restart.to_s - restart.from_s
            );
            self.restart();
        }
        for (t, payload) in admitted.released {
            self.feed_checked(epoch, with_stamp(payload, t));
        }
        None
    }

    /// Feeds an input whose stamp the timeline passed (in mission time).
    fn feed_checked(&mut self, epoch: Epoch, payload: Payload) {
        match payload {
            Payload::Cloud(t, scan) => self.cloud(epoch.stamp(t), scan),
            Payload::Image(t, image, unknown) => {
                self.unknown_colours(&unknown);
                self.image(epoch.stamp(t), image)
            }
            Payload::CameraInfo(camera) => self.camera_info(camera),
            Payload::Odometry(t, pose) => self.odometry(epoch.stamp(t), pose),
            Payload::Clock(t) => {
                let t = epoch.stamp(t);
                self.clock = Some(self.clock.map_or(t, |c: Stamp| c.max(t)));
            }
            Payload::GroundTruth(..) | Payload::Tf(_) => {}
        }
    }

    /// The newest `/clock` time that passed the timeline, in mission time: the robot's clock
    /// may move on to it even while no sensor frame comes.
    pub fn clock(&self) -> Option<Stamp> {
        self.clock
    }

    /// The newest odometry pose, and its stamp.
    pub fn latest_odometry(&self) -> Option<(Stamp, Pose3)> {
        self.odometry.back().copied()
    }

    /// Clouds still waiting for a partner.
    pub fn pending(&self) -> usize {
        self.clouds.len()
    }

    fn pose_at(&self, t: Stamp) -> Outcome<Pose3> {
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

    /// The label image nearest `t` within `max_label_skew_s`, with its stamp; `Ready(None)`
    /// when none is or will be; `Wait` while a nearer one may still come (never once `stale`).
    fn image_near(&self, t: Stamp, stale: bool) -> Outcome<Option<(Stamp, LabelImage)>> {
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
    fn without_image(&mut self, scan: &Scan) -> Outcome<FrameLabels> {
        match self.config.unlabelled {
            Unlabelled::Keep => {
                self.counts.unlabelled += 1;
                Outcome::Ready(FrameLabels::PerPoint(vec![None; scan.points.len()]))
            }
            Unlabelled::Drop => {
                self.counts.no_image += 1;
                Outcome::Drop
            }
        }
    }

    /// The labels of `scan` (points still in the LiDAR's frame, `body_from_lidar` away).
    fn labels_for(
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
                let camera_from_body = if skew <= self.config.image_tolerance_s {
                    mounted
                } else {
                    match self.pose_at(t_image) {
                        Outcome::Ready(world_from_body_at_image) => {
                            self.counts.compensated += 1;
                            mounted * world_from_body_at_image.inverse() * world_from_body
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
                Outcome::Ready(FrameLabels::Image { image, camera, camera_from_body })
            }
        }
    }

    /// The frames that can be assembled now, oldest first; stale clouds are dropped.
    pub fn ready(&mut self) -> Vec<SensorFrame> {
        let mut frames = Vec::new();
        while let Some((t, _)) = self.clouds.front() {
            let t = *t;
            let stale = self.ended || self.latest - t > self.config.max_wait_s;
            let pose = match self.pose_at(t) {
                Outcome::Ready(pose) => pose,
                Outcome::Wait if !stale => break,
                _ => {
                    self.counts.no_odometry += 1;
                    self.clouds.pop_front();
                    continue;
                }
            };
            let Some(body_from_lidar) = self.tf.body_from_lidar() else {
                if !stale {
                    break;
                }
                self.counts.no_lidar_mount += 1;
                self.clouds.pop_front();
                continue;
            };
            let Some((_, mut scan)) = self.clouds.pop_front() else { break };
            match self.labels_for(t, &pose, &scan, &body_from_lidar, stale) {
                Outcome::Ready(labels) => {
                    self.counts.frames += 1;
                    // Points into the body frame (the labels stay with their points).
                    if body_from_lidar != Pose3::identity() {
                        for p in &mut scan.points {
                            *p = body_from_lidar * *p;
                        }
                    }
                    frames.push(SensorFrame { stamp: t, odom_from_body: pose, points_in_body: scan.points, labels });
                }
                Outcome::Wait if !stale => {
                    self.clouds.push_front((t, scan));
                    break;
                }
                Outcome::Wait => {
                    if self.camera.is_none() {
                        self.counts.no_camera_info += 1;
                    } else {
                        self.counts.no_image += 1;
                    }
                }
                Outcome::Drop => {}
            }
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

/// `payload` restamped `t`.
fn with_stamp(payload: Payload, t: rosrust::Time) -> Payload {
    match payload {
        Payload::Cloud(_, scan) => Payload::Cloud(t, scan),
        Payload::Image(_, image, unknown) => Payload::Image(t, image, unknown),
        Payload::Odometry(_, pose) => Payload::Odometry(t, pose),
        Payload::GroundTruth(_, pose) => Payload::GroundTruth(t, pose),
        Payload::Clock(_) => Payload::Clock(t),
        Payload::CameraInfo(c) => Payload::CameraInfo(c),
        Payload::Tf(batch) => Payload::Tf(batch),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, UnitQuaternion, Vector3};

    fn scan(n: usize) -> Scan {
        Scan { points: vec![Point3::new(1.0, 0.0, 0.0); n], labels: Some(vec![3; n]), dropped_non_finite: 0 }
    }

    fn camera() -> CameraModel {
        CameraModel { width: 2, height: 2, fx: 1.0, fy: 1.0, cx: 1.0, cy: 1.0, distortion: [0.0; 5] }
    }

    fn image() -> LabelImage {
        LabelImage::new(2, 2, vec![1; 4]).unwrap()
    }

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

    fn ros(s: f64) -> rosrust::Time {
        rosrust::Time { sec: s.floor() as u32, nsec: ((s - s.floor()) * 1e9).round() as u32 }
    }

    /// The field case: one odometry stamped years ahead before the stream, then a bag played
    /// twice in a row (`rosbag play --loop`). Before the timeline, the first refused every
    /// later message as out of order (0 frames); now it is an outlier, and the loop restarts
    /// the timeline: every frame of both passes is assembled, mission time going on.
    #[test]
    fn a_stamp_years_ahead_and_a_looped_bag_do_not_stop_the_frames() {
        let mut s = Synchroniser::new(SyncConfig::default(), LabelSource::Cloud, Pose3::identity());
        let epoch = Epoch { sec: 0 };
        s.feed(epoch, Payload::Odometry(ros(2_000_000_000.0), Pose3::identity()));
        let mut frames = Vec::new();
        for pass in 0..2 {
            // 20 s a pass: the loop jumps back farther than `ros.timeline.max_jump_s`.
            for k in 0..200 {
                let t = 1_700_000_000.0 + 0.1 * f64::from(k);
                s.feed(epoch, Payload::Odometry(ros(t), Pose3::identity()));
                s.feed(epoch, Payload::Cloud(ros(t), scan(2)));
                frames.extend(s.ready());
            }
            if pass == 1 {
                frames.extend(s.finish(epoch));
            }
        }
        let timeline = s.timeline();
        assert_eq!((timeline.outliers, timeline.restarts), (1, 1));
        assert_eq!(s.counts.out_of_order, 0);
        // Every cloud of both passes but those waiting when the loop came round.
        assert_eq!(s.counts.frames + s.counts.at_restart, 400, "{:?}", s.counts);
        assert!(s.counts.frames >= 398, "{:?}", s.counts);
        let stamps: Vec<f64> = frames.iter().map(|f| f.stamp).collect();
        assert!(stamps.windows(2).all(|w| w[1] > w[0]), "mission time only goes forward");
        assert!((stamps[0] - 1_700_000_000.0).abs() < 1e-6, "no offset before the restart");
    }

    #[test]
    fn out_of_order_messages_are_counted_not_buffered() {
        let mut s = Synchroniser::new(SyncConfig::default(), LabelSource::Cloud, Pose3::identity());
        s.odometry(1.0, Pose3::identity());
        s.odometry(0.5, Pose3::identity());
        s.cloud(1.0, Scan { labels: None, ..scan(1) });
        assert!(s.ready().is_empty());
        assert_eq!((s.counts.out_of_order, s.counts.no_label_field), (1, 1));
    }

    /// A robot whose LiDAR sits 1 m ahead of the body and whose camera's mount comes from tf:
    /// clouds wait for tf, then their points come out in the body frame (closed form: a point
    /// 1 m ahead of the LiDAR is 2 m ahead of the body); the camera mount composes through its
    /// chain. Without tf the clouds are dropped once stale and counted, and the reason names
    /// the frames.
    #[test]
    fn mounts_come_from_tf_and_clouds_wait_for_them() {
        use crate::config::RosConfig;
        use crate::tf::{TfBatch, TfTransform};
        let mut ros = RosConfig { labels: LabelSource::Cloud, ..RosConfig::default() };
        ros.frames.lidar = "{robot}/velodyne".into();
        ros.timeline.confirm_messages = 1;
        let inputs = Inputs::new(&ros, "alpha", 1);
        let mut s = Synchroniser::for_robot(&ros, &inputs).unwrap();
        let epoch = Epoch { sec: 100 };
        let at = |t: f64| epoch.time(t);
        s.feed(epoch, Payload::Odometry(at(0.0), Pose3::identity()));
        s.feed(epoch, Payload::Cloud(at(0.0), scan(2)));
        s.feed(epoch, Payload::Odometry(at(0.5), Pose3::identity()));
        assert!(s.ready().is_empty(), "waits for the LiDAR's mount");
        assert!(s.missing_mount().unwrap().contains("`alpha/base_link` ← `alpha/velodyne`"));
        let offset = Pose3::from_parts(Vector3::new(1.0, 0.0, 0.0).into(), UnitQuaternion::identity());
        let mount = TfTransform {
            stamp: rosrust::Time::default(),
            parent: "alpha/base_link".into(),
            child: "alpha/velodyne".into(),
            parent_from_child: offset,
        };
        s.feed(epoch, Payload::Tf(TfBatch { is_static: true, transforms: vec![mount], refused: vec![] }));
        let frames = s.ready();
        assert_eq!(frames.len(), 1);
        assert_eq!(frames[0].points_in_body[0], Point3::new(2.0, 0.0, 0.0));
        assert_eq!(s.missing_mount(), None);

        // No tf at all: dropped once stale, counted, the reason kept.
        let mut s = Synchroniser::for_robot(&ros, &inputs).unwrap();
        s.feed(epoch, Payload::Odometry(at(0.0), Pose3::identity()));
        s.feed(epoch, Payload::Cloud(at(0.0), scan(2)));
        s.feed(epoch, Payload::Odometry(at(2.0), Pose3::identity()));
        assert!(s.ready().is_empty());
        assert_eq!(s.counts.no_lidar_mount, 1);
        assert_eq!(s.pending(), 0);
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
        let mut s = Synchroniser::for_robot(&ros, &inputs).unwrap();
        let epoch = Epoch { sec: 100 };
        let at = |t: f64| epoch.time(t);
        // Sampled: the 1st and the 17th point, one ahead and one behind.
        let mut points = vec![Point3::new(1.0, 0.0, 0.0); PROJECTION_SAMPLE];
        points.push(Point3::new(-1.0, 0.0, 0.0));
        let two_points = Scan { points, labels: None, dropped_non_finite: 0 };
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
