//! The robot's own odometry out (`odometry.source = "internal"`). Every estimate of the
//! Odometry actor ([`OdometryPose`]) goes out as `nav_msgs/Odometry` on `ros.topics.odometry_out`
//! and as the world → body transform on `ros.topics.tf`, both stamped with the sweep's ROS time
//! (`convert::odometry`). The Odometry actor hands on only finite poses, and this actor checks
//! again, so a NaN pose is never published. Publications rosrust did not take are counted for
//! the status.

use super::sensors::SensorSide;
use crate::convert::odometry::{odometry_pose_msg, odometry_transform};
use crate::msg::{nav_msgs, std_msgs, tf2_msgs};
use actix::{Actor, Context, Handler};
use sgm_actors::odometry::OdometryPose;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// For the status's `odometry_out`: estimates published, publications rosrust did not take
/// (odometry or tf), estimates refused as not finite.
#[derive(Debug, Default)]
pub(super) struct OdometryOutCounts {
    pub(super) published: AtomicU64,
    pub(super) failed: AtomicU64,
    pub(super) not_finite: AtomicU64,
}

impl OdometryOutCounts {
    pub(super) fn snapshot(&self) -> BTreeMap<&'static str, u64> {
        [("published", &self.published), ("failed", &self.failed), ("not_finite", &self.not_finite)]
            .into_iter()
            .map(|(k, v)| (k, v.load(Ordering::Relaxed)))
            .collect()
    }
}

pub(super) struct OdometryPublisher {
    pub(super) side: Arc<SensorSide>,
    pub(super) odometry: rosrust::Publisher<nav_msgs::Odometry>,
    pub(super) tf: rosrust::Publisher<tf2_msgs::TFMessage>,
    pub(super) world_frame: String,
    pub(super) body_frame: String,
    pub(super) counts: Arc<OdometryOutCounts>,
}

impl Actor for OdometryPublisher {
    type Context = Context<Self>;
}

impl Handler<OdometryPose> for OdometryPublisher {
    type Result = ();
    fn handle(&mut self, pose: OdometryPose, _: &mut Context<Self>) {
        if !pose.is_finite() {
            self.counts.not_finite.fetch_add(1, Ordering::Relaxed);
            return;
        }
        let header =
            std_msgs::Header { seq: 0, stamp: self.side.ros_time(pose.stamp), frame_id: self.world_frame.clone() };
        let transform = odometry_transform(header.clone(), &self.body_frame, &pose);
        let odometry = self.odometry.send(odometry_pose_msg(header, &self.body_frame, &pose));
        if odometry.is_ok() {
            self.counts.published.fetch_add(1, Ordering::Relaxed);
        }
        let tf = self.tf.send(tf2_msgs::TFMessage { transforms: vec![transform] });
        for e in [odometry.err(), tf.err()].into_iter().flatten() {
            if self.counts.failed.fetch_add(1, Ordering::Relaxed) == 0 {
                tracing::warn!("publishing the odometry failed: {e} (counted in the status's odometry_out)");
            }
        }
    }
}
