//! The synchroniser: three streams in (clouds, odometry, label images + camera info), typed
//! [`SensorFrame`](sgm_actors::messages::SensorFrame)s out — the same code for the live node and
//! the bag replay. A cloud gets the odometry pose at its stamp (the pose stamped exactly then, else
//! interpolated between the two bracketing poses — linear in translation, slerp in rotation — if
//! they are at most `max_odometry_gap_s` apart) and the label image nearest its stamp. An image
//! within `image_tolerance_s` labels it as it is; one farther but within `max_label_skew_s` (a
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
//! confirm it (a jump: the timeline restarts, the buffers start afresh and mission time goes on) or
//! is dropped as an outlier (a glitch), so one bad stamp never stops the streams.
//!
//! With the robot's own odometry (`odometry.source = "internal"`) there is no odometry stream:
//! the IMU's is kept instead (`imu.rs`), and a cloud waits for the IMU to pass the end of its
//! sweep (its stamp plus its latest point's time), not for a pose. Each frame carries the IMU's
//! samples since the previous frame, in the body frame; its pose is left for the Odometry actor
//! to set. Every cloud then reaches the odometry: one that no label reaches (no label field, no
//! image in time with `unlabelled = "drop"`) goes as a sweep for the odometry alone
//! ([`FrameLabels::Unlabelled`](sgm_actors::messages::FrameLabels), counted as `sweeps`), and an
//! image beyond `image_tolerance_s` is handed on with its offset for Fusion to compensate at the
//! odometry's velocity (there are no odometry poses here to compensate with).
//!
//! [`Synchroniser`] (here) takes the streams in and owns their buffers; a cloud meets its
//! odometry pose and is assembled in `assemble.rs`, and finds its labels (from the cloud, or the
//! nearest image, motion-compensated) in `labels.rs`; what became of the clouds is counted in
//! [`SyncCounts`] (`counts.rs`).

mod assemble;
mod counts;
mod imu;
mod labels;

pub use counts::SyncCounts;
pub use imu::MAX_IMU_BUFFERED;
pub use labels::PROJECTION_SAMPLE;

use crate::config::{LabelSource, RosConfig, RosConfigError, SyncConfig};
use crate::convert::cloud::Scan;
use crate::convert::image::UnknownColours;
use crate::convert::imu::ImuReading;
use crate::convert::time::Epoch;
use crate::inputs::{Inputs, Payload};
use crate::tf::listener::{TfListener, TfStatus};
use crate::tf::mounts::Mount;
use crate::timeline::{Timeline, TimelineConfig, TimelineCounts};
use imu::{ImuStream, Pushed};
use sgm_actors::config::OdometrySource;
use sgm_model::geometry::Pose3;
use sgm_model::perception::colour_ids::hex;
use sgm_model::perception::deskew::sweep_end_s;
use sgm_model::perception::projection::{CameraModel, LabelImage};
use sgm_model::scene_graph::Stamp;
use std::collections::VecDeque;

/// At most this many messages wait in each stream's buffer (the oldest goes first).
const MAX_BUFFERED: usize = 1000;

pub struct Synchroniser {
    config: SyncConfig,
    labels: LabelSource,
    /// The sensors' mounts (pinned or from tf) and tf's view of the odometry.
    tf: TfListener,
    odometry: VecDeque<(Stamp, Pose3)>,
    images: VecDeque<(Stamp, LabelImage)>,
    camera: Option<CameraModel>,
    clouds: VecDeque<(Stamp, Waiting)>,
    /// Where the frames' poses come from: the odometry stream, or the robot's own odometry
    /// (then the IMU stream is kept, and clouds wait for it instead).
    source: OdometrySource,
    imu: ImuStream,
    latest: Stamp,
    /// No more input will come (a bag's end): nothing waits for a partner any longer.
    ended: bool,
    timeline: Timeline<Payload>,
    /// Newest `/clock` time passed by the timeline (mission time).
    clock: Option<Stamp>,
    pub counts: SyncCounts,
}

/// A cloud waiting for its partners.
struct Waiting {
    scan: Scan,
    /// The stamp its sweep ends at: its own plus its latest point's time.
    sweep_end: Stamp,
}

/// What a cloud's partner lookup gives: found, not yet (it may still come), or never.
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
    /// between the frames `inputs` resolved, stamps checked by `ros.timeline`; the IMU stream
    /// and its mount kept when `source` is the robot's own odometry.
    pub fn for_robot(ros: &RosConfig, inputs: &Inputs, source: OdometrySource) -> Result<Self, RosConfigError> {
        let body = inputs.body_frame();
        let camera = Mount::new("camera", "ros.body_from_camera", body, inputs.camera_frame(), ros.camera_pin()?);
        let lidar = Mount::new("lidar", "ros.body_from_lidar", body, inputs.lidar_frame(), ros.lidar_pin()?);
        let mut tf = TfListener::new(ros.tf.clone(), inputs.world_frame(), body, camera, lidar);
        if source == OdometrySource::Internal {
            tf = tf.with_imu(Mount::new("imu", "ros.body_from_imu", body, inputs.imu_frame(), ros.imu_pin()?));
        }
        let mut sync = Self::with_mounts(ros.sync.clone(), ros.labels, tf).with_timeline(ros.timeline.clone());
        sync.source = source;
        Ok(sync)
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
            source: OdometrySource::External,
            imu: ImuStream::default(),
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
        self.imu.clear();
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
        let sweep_end = t + sweep_end_s(scan.times.as_deref());
        if !push_bounded(&mut self.clouds, t, Waiting { scan, sweep_end }, &mut self.counts.overflow) {
            self.counts.out_of_order += 1;
        }
    }

    /// An IMU sample in the IMU's frame (kept only for the robot's own odometry).
    pub fn imu(&mut self, t: Stamp, reading: ImuReading) {
        if self.source != OdometrySource::Internal {
            return;
        }
        self.saw(t);
        match self.imu.push(t, reading) {
            Pushed::Kept => {}
            Pushed::KeptOverflowing => self.counts.overflow += 1,
            Pushed::OutOfOrder => self.counts.out_of_order += 1,
        }
    }

    /// Feeds a checked input, its stamp taken from `epoch`. A true pose is not the
    /// synchroniser's business: it is handed back (stamped) to the caller.
    pub fn feed(&mut self, epoch: Epoch, payload: Payload) -> Option<(Stamp, Pose3)> {
        let stamp = match &payload {
            Payload::Cloud(t, _) | Payload::Image(t, ..) | Payload::Odometry(t, _) | Payload::Clock(t) => *t,
            Payload::Imu(t, _) if self.source == OdometrySource::Internal => *t,
            Payload::CameraInfo(_) => {
                self.feed_checked(epoch, payload);
                return None;
            }
            Payload::GroundTruth(t, pose) => {
                return Some((epoch.stamp(self.timeline.to_mission(*t)), *pose));
            }
            // Only the robot's own odometry uses the IMU.
            Payload::Imu(..) => return None,
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
            Payload::Imu(t, reading) => self.imu(epoch.stamp(t), reading),
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
        Payload::Imu(_, reading) => Payload::Imu(t, reading),
    }
}

#[cfg(test)]
mod fixtures;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sync::fixtures::scan;
    use nalgebra::{Point3, UnitQuaternion, Vector3};

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
        let mut s = Synchroniser::for_robot(&ros, &inputs, OdometrySource::External).unwrap();
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
        let mut s = Synchroniser::for_robot(&ros, &inputs, OdometrySource::External).unwrap();
        s.feed(epoch, Payload::Odometry(at(0.0), Pose3::identity()));
        s.feed(epoch, Payload::Cloud(at(0.0), scan(2)));
        s.feed(epoch, Payload::Odometry(at(2.0), Pose3::identity()));
        assert!(s.ready().is_empty());
        assert_eq!(s.counts.no_lidar_mount, 1);
        assert_eq!(s.pending(), 0);
    }
}
