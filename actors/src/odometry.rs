//! `Odometry` (when `odometry.source = "internal"`): a thin actor over [`OdometryStage`], which
//! runs SGM's LiDAR-inertial odometry (`model::odometry`) on every frame's timed sweep and IMU
//! samples. A labelled frame goes on to Fusion with the odometry's pose and its deskewed points;
//! an unlabelled one ([`FrameLabels::Unlabelled`]) is registered and goes no further. A frame the
//! odometry refuses (before the IMU has found gravity, a stamp that does not advance) is not
//! handed on, and is counted; coasting and resets are counted and logged, the first of each kind
//! at `warn`. Whoever attached an output ([`AttachOdometryOutput`]: the ROS node, which publishes
//! `nav_msgs/Odometry` and the world → body tf) gets every estimate as an [`OdometryPose`].

use crate::containment::contained;
use crate::messages::{FrameLabels, SensorFrame};
use actix::{Actor, Context, Handler, Message, MessageResult, Recipient, Supervised};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use sgm_model::geometry::lie::Matrix6;
use sgm_model::geometry::Pose3;
use sgm_model::odometry::config::{OdometryConfig, OdometryConfigError};
use sgm_model::odometry::estimator::{LidarInertialOdometry, OdometryCounts, ScanOutcome, ScanRefusal};
use sgm_model::odometry::local_map::LocalMapSize;
use sgm_model::scene_graph::Stamp;

/// What the odometry has done since the robot started (not part of a snapshot).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct OdometryStatus {
    /// The estimator's counts: scans, refused, registered, coasted, degenerate, resets, IMU.
    pub counts: OdometryCounts,
    /// Labelled frames handed on to Fusion with the odometry's pose.
    pub handed_on: u64,
    /// The stamp of the scan at which the odometry started: its frame is the body's pose then,
    /// levelled, yaw zero (`model::odometry::estimator`).
    pub origin_stamp: Option<f64>,
    /// The local map's points and voxels now, its peak and its budget.
    #[serde(default)]
    pub local_map: LocalMapSize,
}

/// Odometry → an attached output: the estimate at one scan (registered or coasted).
#[derive(Message, Clone, Debug, PartialEq)]
#[rtype(result = "()")]
pub struct OdometryPose {
    pub stamp: Stamp,
    pub odom_from_body: Pose3,
    /// m/s, in the odometry frame.
    pub velocity: Vector3<f64>,
    /// rad/s, in the body frame: the mean of the sweep's gyro samples, the estimated bias
    /// removed (`None` when the frame brought no sample).
    pub angular_velocity: Option<Vector3<f64>>,
    /// Covariance of e = Log(T̂⁻¹ T), ordered (ω, v), in the body frame.
    pub covariance: Matrix6,
}

impl OdometryPose {
    /// Every value finite: only such a pose leaves the actor.
    pub fn is_finite(&self) -> bool {
        let p = &self.odom_from_body;
        p.translation.vector.iter().chain(p.rotation.coords.iter()).chain(self.velocity.iter()).all(|v| v.is_finite())
            && self.angular_velocity.is_none_or(|w| w.iter().all(|v| v.is_finite()))
            && self.covariance.iter().all(|v| v.is_finite())
    }
}

/// Sends every later estimate to `0` as well.
#[derive(Message)]
#[rtype(result = "()")]
pub struct AttachOdometryOutput(pub Recipient<OdometryPose>);

/// What became of a frame.
#[derive(Debug)]
pub enum StageOutput {
    /// Registered (or coasted); labelled, so it goes on with the odometry's pose.
    HandOn(Box<SensorFrame>),
    /// Registered (or coasted); unlabelled, so it goes no further.
    Kept,
    Refused(ScanRefusal),
}

/// The odometry stage as plain state: the estimator and what it has done.
#[derive(Clone, Debug)]
pub struct OdometryStage {
    estimator: LidarInertialOdometry,
    handed_on: u64,
    origin_stamp: Option<f64>,
    /// Which kinds of event were already logged at `warn` (the rest are counted).
    warned: Warned,
    /// The estimate at the latest frame that produced one.
    latest: Option<OdometryPose>,
}

#[derive(Clone, Copy, Debug, Default)]
struct Warned {
    refused: bool,
    coasted: bool,
    saturated: bool,
    low_overlap: bool,
}

impl OdometryStage {
    pub fn new(config: OdometryConfig) -> Result<Self, OdometryConfigError> {
        Ok(Self {
            estimator: LidarInertialOdometry::new(config)?,
            handed_on: 0,
            origin_stamp: None,
            warned: Warned::default(),
            latest: None,
        })
    }

    pub fn status(&self) -> OdometryStatus {
        OdometryStatus {
            counts: self.estimator.counts(),
            handed_on: self.handed_on,
            origin_stamp: self.origin_stamp,
            local_map: self.estimator.local_map().size(),
        }
    }

    /// The estimate at the latest frame that produced one.
    pub fn latest(&self) -> Option<&OdometryPose> {
        self.latest.as_ref()
    }

    /// Registers `frame`'s sweep after its IMU samples; a labelled frame comes back with the
    /// estimate as its pose and its points deskewed into the body at its stamp.
    pub fn frame(&mut self, mut frame: SensorFrame) -> StageOutput {
        self.estimator.push_imu(&frame.imu);
        let saturated = self.estimator.counts().imu.saturated;
        if saturated > 0 && !self.warned.saturated {
            self.warned.saturated = true;
            tracing::warn!(
                stamp = frame.stamp,
                "the IMU read at full scale (a jolt beyond its range): such samples are used clipped, and the \
                 scans re-learn the velocity (counted in its status, imu.saturated)"
            );
        }
        let result = self.estimator.process_scan(frame.stamp, &frame.points_in_body, frame.point_times.as_deref());
        let estimate = match result {
            Ok(estimate) => estimate,
            Err(refusal) => {
                if !self.warned.refused {
                    self.warned.refused = true;
                    tracing::warn!(stamp = frame.stamp, "odometry refused a frame: {refusal} (counted in its status)");
                }
                return StageOutput::Refused(refusal);
            }
        };
        let angular_velocity = (!frame.imu.is_empty()).then(|| {
            let sum: Vector3<f64> = frame.imu.iter().map(|s| s.angular_velocity).sum();
            sum / frame.imu.len() as f64 - estimate.gyro_bias
        });
        self.latest = Some(OdometryPose {
            stamp: frame.stamp,
            odom_from_body: estimate.odom_from_body,
            velocity: estimate.velocity,
            angular_velocity,
            covariance: estimate.covariance,
        });
        match &estimate.outcome {
            ScanOutcome::First => self.origin_stamp = Some(frame.stamp),
            ScanOutcome::Coasted(reason) if !self.warned.coasted => {
                self.warned.coasted = true;
                tracing::warn!(stamp = frame.stamp, "odometry coasted on the IMU: {reason} (counted in its status)");
            }
            ScanOutcome::Registered { points, correspondences, .. }
                if !self.warned.low_overlap && self.estimator.counts().low_overlap > 0 =>
            {
                self.warned.low_overlap = true;
                tracing::warn!(
                    stamp = frame.stamp,
                    points,
                    correspondences,
                    "odometry: a scan overlapped its local map little (new ground all around, or an estimate that \
                     left its map; counted in its status, low_overlap)"
                );
            }
            ScanOutcome::Reset { speed_mps } => {
                tracing::warn!(
                    stamp = frame.stamp,
                    speed_mps,
                    "odometry diverged and was reset to its last registered state"
                );
            }
            _ => {}
        }
        if matches!(frame.labels, FrameLabels::Unlabelled) {
            return StageOutput::Kept;
        }
        self.handed_on += 1;
        // The next frame handed on carries the motion's covariance from this one.
        frame.motion_covariance = estimate.motion_covariance;
        frame.measured_up = Some(estimate.measured_up);
        self.estimator.mark();
        frame.odom_from_body = estimate.odom_from_body;
        frame.points_deskewed = estimate.deskew.is_ok();
        frame.points_in_body = estimate.points_in_body;
        StageOutput::HandOn(Box::new(frame))
    }
}

pub struct Odometry {
    stage: OdometryStage,
    fusion: Recipient<SensorFrame>,
    output: Option<Recipient<OdometryPose>>,
}

impl Odometry {
    pub fn new(stage: OdometryStage, fusion: Recipient<SensorFrame>) -> Self {
        Self { stage, fusion, output: None }
    }
}

/// The Odometry actor's [`OdometryStatus`].
#[derive(Message)]
#[rtype(result = "OdometryStatus")]
pub struct GetOdometryStatus;

impl Actor for Odometry {
    type Context = Context<Self>;
}

impl Supervised for Odometry {}

impl Handler<SensorFrame> for Odometry {
    type Result = ();
    fn handle(&mut self, frame: SensorFrame, ctx: &mut Context<Self>) {
        contained(ctx, "odometry", || {
            let output = self.stage.frame(frame);
            if let (Some(to), false) = (&self.output, matches!(output, StageOutput::Refused(_))) {
                if let Some(pose) = self.stage.latest().filter(|p| p.is_finite()) {
                    to.do_send(pose.clone());
                }
            }
            if let StageOutput::HandOn(frame) = output {
                self.fusion.do_send(*frame);
            }
        });
    }
}

impl Handler<AttachOdometryOutput> for Odometry {
    type Result = ();
    fn handle(&mut self, AttachOdometryOutput(to): AttachOdometryOutput, _: &mut Context<Self>) {
        self.output = Some(to);
    }
}

impl Handler<GetOdometryStatus> for Odometry {
    type Result = MessageResult<GetOdometryStatus>;
    fn handle(&mut self, _: GetOdometryStatus, _: &mut Context<Self>) -> Self::Result {
        MessageResult(self.stage.status())
    }
}

stops_on_injected_failure!(Odometry => "odometry");

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Vector3};
    use sgm_model::geometry::Pose3;
    use sgm_model::perception::imu::ImuSample;
    use sgm_model::scene_graph::LabelId;

    /// The inside of a 20 × 12 × 3 m room with a pillar, seen from (0, 0, 1): points on its
    /// walls, floor, ceiling and pillar, in the body frame of a body standing still there.
    fn room() -> Vec<Point3<f64>> {
        let mut points = Vec::new();
        let step = 0.25;
        let span = |lo: f64, hi: f64| (0..=((hi - lo) / step) as usize).map(move |k| lo + k as f64 * step);
        for x in span(-10.0, 10.0) {
            for z in span(-1.0, 2.0) {
                points.push(Point3::new(x, -6.0, z));
                points.push(Point3::new(x, 6.0, z));
            }
            for y in span(-6.0, 6.0) {
                points.push(Point3::new(x, y, -1.0));
                points.push(Point3::new(x, y, 2.0));
            }
        }
        for y in span(-6.0, 6.0) {
            for z in span(-1.0, 2.0) {
                points.push(Point3::new(-10.0, y, z));
                points.push(Point3::new(10.0, y, z));
            }
        }
        for z in span(-1.0, 2.0) {
            for y in span(2.0, 3.0) {
                points.push(Point3::new(4.0, y, z));
            }
        }
        points
    }

    /// 200 Hz samples of a body at rest, level, over (from, to].
    fn still_imu(from: f64, to: f64) -> Vec<ImuSample> {
        let first = (from * 200.0).floor() as i64 + 1;
        let last = (to * 200.0).floor() as i64;
        (first..=last)
            .map(|k| ImuSample {
                stamp: k as f64 / 200.0,
                angular_velocity: Vector3::zeros(),
                specific_force: Vector3::new(0.0, 0.0, 9.81),
            })
            .collect()
    }

    fn frame(stamp: f64, labels: FrameLabels) -> SensorFrame {
        let points = room();
        SensorFrame {
            stamp,
            odom_from_body: Pose3::identity(),
            point_times: Some(vec![0.0; points.len()]),
            points_in_body: points,
            points_deskewed: false,
            labels,
            imu: still_imu(stamp - 0.1, stamp),
            motion_covariance: None,
            measured_up: None,
        }
    }

    /// Closed form: a body standing still in a room stays at the odometry's origin. Sweeps
    /// before the IMU has found gravity are refused and counted, unlabelled ones are
    /// registered and kept, labelled ones go on with the odometry's pose and deskewed points.
    #[test]
    fn a_still_body_stays_at_the_origin_and_only_labelled_frames_go_on() {
        let mut stage = OdometryStage::new(OdometryConfig::default()).expect("the default configuration");
        let (mut handed_on, mut refused) = (Vec::new(), 0);
        for k in 1..=30 {
            let stamp = k as f64 * 0.1;
            let labels = match k % 5 {
                0 => FrameLabels::PerPoint(vec![Some(LabelId(1)); room().len()]),
                _ => FrameLabels::Unlabelled,
            };
            match stage.frame(frame(stamp, labels)) {
                StageOutput::HandOn(frame) => handed_on.push(*frame),
                StageOutput::Kept => assert!(k % 5 != 0, "a labelled frame at {stamp} s was kept"),
                // Gravity needs `level_window_s` (1 s) of samples before the first scan.
                StageOutput::Refused(ScanRefusal::WaitingForImu { .. }) if k < 10 => refused += 1,
                StageOutput::Refused(refusal) => panic!("a frame at {stamp} s was refused: {refusal}"),
            }
        }
        assert_eq!((refused, handed_on.len()), (9, 5));
        for frame in &handed_on {
            let moved = frame.odom_from_body.translation.vector.norm();
            let turned = frame.odom_from_body.rotation.angle();
            assert!(moved < 0.01 && turned < 1e-3, "at {} s: {moved} m, {turned} rad", frame.stamp);
            assert!(frame.points_deskewed);
            assert_eq!(frame.points_in_body.len(), room().len());
        }
        let status = stage.status();
        assert_eq!(status.handed_on, 5);
        assert_eq!(status.counts.refused, 9);
        assert_eq!(status.counts.scans, 21);
        assert_eq!(status.counts.resets, 0);
        assert_eq!(status.origin_stamp, Some(1.0));
        // What an attached output gets: the last frame's estimate, still, finite, with the
        // sweep's rate (zero, bias removed) and a covariance.
        let latest = stage.latest().expect("an estimate");
        assert!(latest.is_finite() && (latest.stamp - 3.0).abs() < 1e-12);
        assert!(latest.velocity.norm() < 0.05, "{latest:?}");
        assert!(latest.angular_velocity.is_some_and(|w| w.norm() < 1e-3), "{latest:?}");
        assert!((0..6).all(|k| latest.covariance[(k, k)] > 0.0), "{latest:?}");
    }

    /// A knock beyond the accelerometer's range (one 20 g sample) on a body standing still: the
    /// sample is used clipped and counted, the scans take the body back to where it stands, and
    /// nothing coasts or resets.
    #[test]
    fn a_knock_beyond_the_imus_range_is_counted_and_ridden_out() {
        let mut stage = OdometryStage::new(OdometryConfig::default()).expect("the default configuration");
        for k in 1..=40 {
            let stamp = k as f64 * 0.1;
            let mut f = frame(stamp, FrameLabels::Unlabelled);
            if k == 20 {
                f.imu[10].specific_force = Vector3::new(0.0, 0.0, 20.0 * 9.81);
            }
            stage.frame(f);
        }
        let status = stage.status();
        let c = status.counts;
        assert_eq!((c.imu.saturated, c.coasted, c.resets), (1, 0, 0), "{c:?}");
        assert_eq!(c.registered + 1, c.scans, "{c:?}");
        let latest = stage.latest().expect("an estimate");
        let moved = latest.odom_from_body.translation.vector.norm();
        assert!(moved < 0.01 && latest.velocity.norm() < 0.05, "{latest:?}");
    }

    /// A frame whose stamp does not advance is refused; nothing already estimated moves.
    #[test]
    fn a_stamp_that_goes_back_is_refused_and_counted() {
        let mut stage = OdometryStage::new(OdometryConfig::default()).expect("the default configuration");
        let labelled = || FrameLabels::PerPoint(vec![None; room().len()]);
        for k in 1..10 {
            stage.frame(frame(k as f64 * 0.1, FrameLabels::Unlabelled));
        }
        assert!(matches!(stage.frame(frame(1.0, labelled())), StageOutput::HandOn(_)));
        assert!(matches!(
            stage.frame(frame(0.95, labelled())),
            StageOutput::Refused(ScanRefusal::NotAfterPrevious { .. })
        ));
        assert!(matches!(stage.frame(frame(1.1, labelled())), StageOutput::HandOn(_)));
        assert_eq!(stage.status().counts.refused, 10);
    }
}
