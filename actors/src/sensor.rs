//! `Sensor`: frames in (scenario simulator, bag replay or the ROS bridge) → checked
//! [`SensorFrame`]s to `Odometry` (`odometry.source = "internal"`) or straight to `Fusion`. A
//! frame with a non-finite pose or stamp, a label count that does not match its points, or an
//! out-of-order stamp is dropped and counted, as is an unlabelled sweep when there is no internal
//! odometry to take it; the robot keeps running.

use crate::containment::contained;
use crate::messages::SensorFrame;
use actix::{Actor, Context, Handler, Message, Recipient, Supervised};
use sgm_model::scene_graph::Stamp;

pub struct Sensor {
    /// Odometry when internal, else Fusion.
    next: Recipient<SensorFrame>,
    gate: FrameGate,
}

#[derive(Message)]
#[rtype(result = "u64")]
pub struct GetDroppedFrames;

/// Which frames go on, as plain state: the latest stamp let through, and how many were dropped.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameGate {
    last_stamp: Option<Stamp>,
    dropped: u64,
    /// Whether unlabelled sweeps have a taker (the internal odometry).
    takes_unlabelled: bool,
}

impl FrameGate {
    /// A gate for a robot whose odometry is internal (`takes_unlabelled`) or external.
    pub fn new(takes_unlabelled: bool) -> Self {
        Self { takes_unlabelled, ..Self::default() }
    }

    /// Lets `frame` through, or says why not (and counts it).
    pub fn admit(&mut self, frame: &SensorFrame) -> Result<(), &'static str> {
        let checked = self.check(frame);
        match checked {
            Ok(()) => self.last_stamp = Some(frame.stamp),
            Err(_) => self.dropped += 1,
        }
        checked
    }

    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    fn check(&self, frame: &SensorFrame) -> Result<(), &'static str> {
        let pose_finite = frame
            .odom_from_body
            .translation
            .vector
            .iter()
            .chain(frame.odom_from_body.rotation.coords.iter())
            .all(|v| v.is_finite());
        if !frame.stamp.is_finite() || !pose_finite {
            return Err("non-finite stamp or pose");
        }
        if self.last_stamp.is_some_and(|t| frame.stamp <= t) {
            return Err("stamp not after the previous frame's");
        }
        match &frame.labels {
            crate::messages::FrameLabels::PerPoint(labels) if labels.len() != frame.points_in_body.len() => {
                return Err("label count differs from point count");
            }
            crate::messages::FrameLabels::Unlabelled if !self.takes_unlabelled => {
                return Err("an unlabelled sweep, and no internal odometry to take it");
            }
            _ => {}
        }
        Ok(())
    }
}

impl Sensor {
    /// `next`: the Odometry actor (`internal`: unlabelled sweeps are let through) or Fusion.
    pub fn new(next: Recipient<SensorFrame>, internal_odometry: bool) -> Self {
        Self { next, gate: FrameGate::new(internal_odometry) }
    }
}

impl Actor for Sensor {
    type Context = Context<Self>;
}

impl Supervised for Sensor {}

impl Handler<SensorFrame> for Sensor {
    type Result = ();
    fn handle(&mut self, frame: SensorFrame, ctx: &mut Context<Self>) {
        contained(ctx, "sensor", || match self.gate.admit(&frame) {
            Ok(()) => self.next.do_send(frame),
            Err(why) => tracing::warn!(stamp = frame.stamp, "sensor frame dropped: {why}"),
        });
    }
}

impl Handler<GetDroppedFrames> for Sensor {
    type Result = u64;
    fn handle(&mut self, _: GetDroppedFrames, _: &mut Context<Self>) -> u64 {
        self.gate.dropped()
    }
}

stops_on_injected_failure!(Sensor => "sensor");

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::FrameLabels;
    use nalgebra::Point3;
    use sgm_model::geometry::Pose3;
    use sgm_model::scene_graph::LabelId;

    fn frame(stamp: Stamp, labels: usize) -> SensorFrame {
        SensorFrame {
            stamp,
            odom_from_body: Pose3::identity(),
            points_in_body: vec![Point3::origin(); 2],
            point_times: None,
            points_deskewed: false,
            labels: FrameLabels::PerPoint(vec![Some(LabelId(1)); labels]),
            imu: Vec::new(),
            motion_covariance: None,
            measured_up: None,
        }
    }

    #[test]
    fn frames_go_through_in_stamp_order_and_bad_ones_are_counted() {
        let mut gate = FrameGate::default();
        assert_eq!(gate.admit(&frame(1.0, 2)), Ok(()));
        assert_eq!(gate.admit(&frame(1.0, 2)), Err("stamp not after the previous frame's"));
        assert_eq!(gate.admit(&frame(0.5, 2)), Err("stamp not after the previous frame's"));
        assert_eq!(gate.admit(&frame(2.0, 3)), Err("label count differs from point count"));
        assert_eq!(gate.admit(&frame(f64::NAN, 2)), Err("non-finite stamp or pose"));
        let mut far = frame(3.0, 2);
        far.odom_from_body.translation.vector.x = f64::INFINITY;
        assert_eq!(gate.admit(&far), Err("non-finite stamp or pose"));
        assert_eq!(gate.dropped(), 5);
        // A dropped frame does not move the gate: the next good stamp after 1.0 goes through.
        assert_eq!(gate.admit(&frame(1.5, 2)), Ok(()));
        assert_eq!(gate.dropped(), 5);
    }

    #[test]
    fn unlabelled_sweeps_go_through_only_to_an_internal_odometry() {
        let sweep = |stamp| SensorFrame { labels: FrameLabels::Unlabelled, ..frame(stamp, 2) };
        let mut external = FrameGate::new(false);
        assert_eq!(external.admit(&sweep(1.0)), Err("an unlabelled sweep, and no internal odometry to take it"));
        assert_eq!(external.dropped(), 1);
        let mut internal = FrameGate::new(true);
        assert_eq!(internal.admit(&sweep(1.0)), Ok(()));
        assert_eq!(internal.admit(&frame(1.1, 2)), Ok(()));
        assert_eq!(internal.dropped(), 0);
    }
}
