//! The IMU stream, kept when the robot runs its own odometry (`odometry.source = "internal"`).
//! Readings wait in stamp order, bounded, still in the IMU's frame; a frame takes those after
//! the previous frame's, up to the end of its sweep, brought into the body through the IMU's
//! mount then ([`sample_in_body`]), so a mount that tf gives late still applies to every sample.
//! A cloud dropped on the way leaves its samples to the next frame: the odometry's propagation
//! sees every sample once, in order.

use crate::convert::imu::{sample_in_body, ImuReading};
use sgm_model::geometry::Pose3;
use sgm_model::perception::imu::ImuSample;
use sgm_model::scene_graph::Stamp;
use std::collections::VecDeque;

/// At most this many samples wait (10 s of a 400 Hz IMU); the oldest goes first.
pub const MAX_IMU_BUFFERED: usize = 4000;

#[derive(Clone, Debug, Default)]
pub(super) struct ImuStream {
    samples: VecDeque<(Stamp, ImuReading)>,
    /// The newest stamp seen (taken samples included): a sweep ending at or before it is covered.
    newest: Option<Stamp>,
}

/// What [`ImuStream::push`] did with a sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Pushed {
    Kept,
    /// Kept, and the oldest waiting sample went to make room.
    KeptOverflowing,
    /// Not after the newest sample: refused.
    OutOfOrder,
}

impl ImuStream {
    pub(super) fn push(&mut self, t: Stamp, reading: ImuReading) -> Pushed {
        if self.newest.is_some_and(|newest| t <= newest) {
            return Pushed::OutOfOrder;
        }
        self.newest = Some(t);
        let overflowing = self.samples.len() == MAX_IMU_BUFFERED;
        if overflowing {
            self.samples.pop_front();
        }
        self.samples.push_back((t, reading));
        if overflowing {
            Pushed::KeptOverflowing
        } else {
            Pushed::Kept
        }
    }

    /// The IMU has sampled up to `end`.
    pub(super) fn covers(&self, end: Stamp) -> bool {
        self.newest.is_some_and(|newest| newest >= end)
    }

    /// The waiting samples stamped at or before `end`, taken out, in the body frame.
    pub(super) fn take_until(&mut self, end: Stamp, body_from_imu: &Pose3) -> Vec<ImuSample> {
        let n = self.samples.partition_point(|(t, _)| *t <= end);
        self.samples.drain(..n).map(|(t, reading)| sample_in_body(t, &reading, body_from_imu)).collect()
    }

    /// Forgets everything (the timeline restarted).
    pub(super) fn clear(&mut self) {
        *self = Self::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn reading(z: f64) -> ImuReading {
        ImuReading { angular_velocity: Vector3::zeros(), linear_acceleration: Vector3::new(0.0, 0.0, z) }
    }

    /// Samples come out once each, in order, up to the sweep's end; one that does not advance
    /// is refused; the buffer keeps its bound, the oldest going first.
    #[test]
    fn samples_are_taken_once_in_order_and_bounded() {
        let mut imu = ImuStream::default();
        assert!(!imu.covers(0.0));
        for k in 0..10 {
            assert_eq!(imu.push(f64::from(k) * 0.01, reading(f64::from(k))), Pushed::Kept);
        }
        assert_eq!(imu.push(0.05, reading(0.0)), Pushed::OutOfOrder);
        assert_eq!(imu.push(0.09, reading(0.0)), Pushed::OutOfOrder, "a repeated stamp");
        assert!(imu.covers(0.09) && !imu.covers(0.0901));
        let first = imu.take_until(0.045, &Pose3::identity());
        assert_eq!(first.iter().map(|s| s.specific_force.z).collect::<Vec<_>>(), vec![0.0, 1.0, 2.0, 3.0, 4.0]);
        let rest = imu.take_until(1.0, &Pose3::identity());
        assert_eq!(rest.len(), 5);
        assert!(imu.take_until(1.0, &Pose3::identity()).is_empty());
        assert!(imu.covers(0.09), "taken samples still count as seen");

        let mut imu = ImuStream::default();
        for k in 0..=MAX_IMU_BUFFERED {
            let pushed = imu.push(k as f64 * 0.0025, reading(k as f64));
            assert_eq!(pushed == Pushed::KeptOverflowing, k == MAX_IMU_BUFFERED);
        }
        let all = imu.take_until(f64::INFINITY, &Pose3::identity());
        assert_eq!(all.len(), MAX_IMU_BUFFERED);
        assert_eq!(all[0].specific_force.z, 1.0, "the oldest went");
    }
}

/// The synchroniser with the robot's own odometry: no odometry stream, the IMU's instead.
#[cfg(test)]
mod internal_odometry {
    use crate::config::{LabelSource, RosConfig, Unlabelled};
    use crate::convert::cloud::Scan;
    use crate::convert::imu::ImuReading;
    use crate::convert::time::Epoch;
    use crate::inputs::{Inputs, Payload};
    use crate::sync::fixtures::{camera, scan};
    use crate::sync::Synchroniser;
    use nalgebra::Vector3;
    use sgm_actors::config::OdometrySource;
    use sgm_actors::messages::FrameLabels;
    use sgm_model::geometry::Pose3;

    fn ros(s: f64) -> rosrust::Time {
        let nanos = (s * 1e9).round() as u64;
        rosrust::Time { sec: (nanos / 1_000_000_000) as u32, nsec: (nanos % 1_000_000_000) as u32 }
    }

    /// A 10 Hz sweep at `t` whose points were measured over 0.09 s.
    fn sweep(labelled: bool) -> Scan {
        let mut s = scan(10);
        s.times = Some((0..10).map(|k| k as f32 * 0.01).collect());
        if !labelled {
            s.labels = None;
        }
        s
    }

    /// An IMU mounted upside down (180° about x), 0.2 m ahead of the body origin, its
    /// readings in its own frame: a body at rest, level.
    fn upside_down() -> [f64; 7] {
        [0.2, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
    }

    fn at_rest() -> ImuReading {
        ImuReading {
            angular_velocity: Vector3::new(0.0, 0.0, -0.1),
            linear_acceleration: Vector3::new(0.0, 0.0, -9.81),
        }
    }

    fn synchroniser(ros_config: &RosConfig) -> Synchroniser {
        let inputs = Inputs::new(ros_config, "alpha", 1);
        Synchroniser::for_robot(ros_config, &inputs, OdometrySource::Internal).unwrap()
    }

    fn config() -> RosConfig {
        let mut config =
            RosConfig { labels: LabelSource::Cloud, body_from_imu: Some(upside_down()), ..Default::default() };
        config.frames.imu = "{robot}/imu".into();
        config.timeline.confirm_messages = 1;
        config
    }

    /// Clouds need no odometry: each waits for the IMU to pass its sweep's end, then takes the
    /// samples since the previous frame, brought into the body (closed form: upside down, the
    /// rate and gravity's reaction flip to +z; the turn's 2 mm/s² pull is taken out). A cloud
    /// without labels reaches the odometry as a sweep, counted apart from the frames; every
    /// sample goes to exactly one frame.
    #[test]
    fn clouds_wait_for_the_imu_and_take_its_samples_in_the_body() {
        let mut s = synchroniser(&config());
        let epoch = Epoch { sec: 100 };
        let mut frames = Vec::new();
        let mut samples = 0;
        for k in 0..=200 {
            let t = f64::from(k) * 0.005;
            if k % 20 == 0 && k < 200 {
                s.feed(epoch, Payload::Cloud(ros(100.0 + t), sweep(k % 40 == 0)));
                assert!(s.ready().is_empty(), "waits for its sweep's samples");
            }
            s.feed(epoch, Payload::Imu(ros(100.0 + t), at_rest()));
            samples += 1;
            frames.extend(s.ready());
        }
        assert_eq!(frames.len(), 10);
        assert_eq!((s.counts.frames, s.counts.sweeps, s.counts.imu_short, s.counts.no_odometry), (5, 5, 0, 0));
        for (k, frame) in frames.iter().enumerate() {
            assert!((frame.stamp - k as f64 * 0.1).abs() < 1e-9);
            assert_eq!(frame.odom_from_body, Pose3::identity(), "the Odometry actor sets it");
            assert_eq!(matches!(frame.labels, FrameLabels::Unlabelled), k % 2 == 1);
            let end = frame.stamp + sgm_model::perception::deskew::sweep_end_s(frame.point_times.as_deref());
            assert!(frame.imu.iter().all(|i| i.stamp <= end), "only up to the sweep's end");
            assert!(frame.imu.last().is_some_and(|i| i.stamp > end - 0.005 - 1e-9), "all of the sweep");
            for i in &frame.imu {
                assert!((i.angular_velocity - Vector3::new(0.0, 0.0, 0.1)).norm() < 1e-12, "{i:?}");
                assert!((i.specific_force - Vector3::new(0.002, 0.0, 9.81)).norm() < 1e-12, "{i:?}");
            }
        }
        let taken: usize = frames.iter().map(|f| f.imu.len()).sum();
        // The last sweep ends just before 0.99 s (its latest point at 0.09 s in f32).
        assert_eq!(taken, 198, "every sample up to the last sweep's end, once");
        assert!(samples > taken, "the samples after the last sweep wait");
    }

    /// The IMU stops: a cloud goes once the streams are `max_wait_s` past it, counted as short
    /// (the odometry coasts). No IMU mount (not pinned, not in tf): clouds wait, then are
    /// dropped and counted, and the reason names the frames and the key.
    #[test]
    fn a_silent_imu_or_an_unknown_mount_is_counted() {
        let mut s = synchroniser(&config());
        let epoch = Epoch { sec: 0 };
        s.feed(epoch, Payload::Imu(ros(0.0), at_rest()));
        s.feed(epoch, Payload::Cloud(ros(0.1), sweep(true)));
        assert!(s.ready().is_empty());
        s.feed(epoch, Payload::Cloud(ros(1.2), sweep(true)));
        let frames = s.ready();
        assert_eq!(frames.len(), 1);
        assert_eq!(frames[0].imu.len(), 1);
        assert_eq!((s.counts.frames, s.counts.imu_short), (1, 1));

        let mut unpinned = config();
        unpinned.body_from_imu = None;
        let mut s = synchroniser(&unpinned);
        assert!(s.missing_mount().unwrap().contains("the imu mount `alpha/base_link` ← `alpha/imu` is unknown"));
        assert!(s.missing_mount().unwrap().contains("pin ros.body_from_imu"));
        s.feed(epoch, Payload::Imu(ros(0.0), at_rest()));
        s.feed(epoch, Payload::Cloud(ros(0.0), sweep(true)));
        s.feed(epoch, Payload::Imu(ros(0.5), at_rest()));
        assert!(s.ready().is_empty(), "waits for the mount");
        s.feed(epoch, Payload::Imu(ros(1.5), at_rest()));
        assert!(s.ready().is_empty());
        assert_eq!((s.counts.no_imu_mount, s.pending()), (1, 0));
        let status = serde_json::to_value(s.tf()).unwrap();
        assert_eq!(status["mounts"][2]["sensor"], "imu");
    }

    /// Label images with the robot's own odometry: a cloud no image reaches goes to the
    /// odometry alone with `unlabelled = "drop"`; an image beyond `image_tolerance_s` labels it
    /// with its offset left to Fusion (no odometry poses here to compensate with).
    #[test]
    fn images_beyond_tolerance_go_on_with_their_offset_and_unreached_clouds_as_sweeps() {
        let mut config = config();
        config.labels = LabelSource::Image;
        config.sync.unlabelled = Unlabelled::Drop;
        config.camera_from_body = Some([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
        let mut s = synchroniser(&config);
        s.camera_info(camera());
        let epoch = Epoch { sec: 0 };
        for k in 0..=240 {
            let t = f64::from(k) * 0.005;
            if k % 20 == 0 && k < 220 {
                s.feed(epoch, Payload::Cloud(ros(t), sweep(false)));
            }
            if k == 40 {
                let image = crate::sync::fixtures::image();
                s.feed(epoch, Payload::Image(ros(t + 0.2), image, Default::default()));
            }
            s.feed(epoch, Payload::Imu(ros(t), at_rest()));
        }
        let frames = s.finish(epoch);
        let labelled: Vec<_> = frames
            .iter()
            .filter_map(|f| match &f.labels {
                FrameLabels::Image { image_offset_s, .. } => Some((f.stamp, *image_offset_s)),
                _ => None,
            })
            .collect();
        // The image at 0.4 s reaches clouds up to 0.5 s away: 0.0 … 0.9 s.
        assert_eq!(labelled.len(), 10, "{labelled:?}");
        assert!(labelled.iter().all(|(t, offset)| (t + offset - 0.4).abs() < 1e-6));
        assert_eq!((s.counts.frames, s.counts.sweeps, s.counts.compensated, s.counts.no_image), (10, 1, 0, 0));
    }
}
