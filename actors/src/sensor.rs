//! `Sensor`: frames in (scenario simulator, bag replay or the ROS bridge) → checked
//! [`SensorFrame`]s to `Fusion`. A frame with a non-finite pose or stamp, a label count that does
//! not match its points, or an out-of-order stamp is dropped and counted; the robot keeps running.

use crate::containment::contained;
use crate::messages::SensorFrame;
use actix::{Actor, Context, Handler, Message, Recipient, Supervised};
use sgm_model::scene_graph::Stamp;

pub struct Sensor {
    fusion: Recipient<SensorFrame>,
    last_stamp: Option<Stamp>,
    pub(crate) dropped: u64,
}

#[derive(Message)]
#[rtype(result = "u64")]
pub struct GetDroppedFrames;

impl Sensor {
    pub fn new(fusion: Recipient<SensorFrame>) -> Self {
        Self { fusion, last_stamp: None, dropped: 0 }
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
        if let crate::messages::FrameLabels::PerPoint(labels) = &frame.labels {
            if labels.len() != frame.points_in_body.len() {
                return Err("label count differs from point count");
            }
        }
        Ok(())
    }
}

impl Actor for Sensor {
    type Context = Context<Self>;
}

impl Supervised for Sensor {}

impl Handler<SensorFrame> for Sensor {
    type Result = ();
    fn handle(&mut self, frame: SensorFrame, ctx: &mut Context<Self>) {
        contained(ctx, "sensor", || match self.check(&frame) {
            Ok(()) => {
                self.last_stamp = Some(frame.stamp);
                self.fusion.do_send(frame);
            }
            Err(why) => {
                self.dropped += 1;
                tracing::warn!(stamp = frame.stamp, "sensor frame dropped: {why}");
            }
        });
    }
}

impl Handler<GetDroppedFrames> for Sensor {
    type Result = u64;
    fn handle(&mut self, _: GetDroppedFrames, _: &mut Context<Self>) -> u64 {
        self.dropped
    }
}

stops_on_injected_failure!(Sensor => "sensor");
