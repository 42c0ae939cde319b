//! `[ros.topics]` and `[ros.frames]`: the names a robot's node reads and writes.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RosTopics {
    /// sensor_msgs/PointCloud2 in. Default `points`.
    pub points: String,
    /// sensor_msgs/Image (mono8/mono16 class ids) in. Default `labels`.
    pub labels: String,
    /// sensor_msgs/CameraInfo in. Default `camera_info`.
    pub camera_info: String,
    /// nav_msgs/Odometry in (with `odometry.source = "external"`). Default `odometry`.
    pub odometry: String,
    /// sensor_msgs/Imu in (with `odometry.source = "internal"`): the robot's own odometry's
    /// input; also written into bags from scenarios with an IMU (`[imu]`). Default `imu`.
    pub imu: String,
    /// nav_msgs/Odometry out (with `odometry.source = "internal"`): the robot's own odometry at
    /// every sweep, its world → body also on `tf`. Default `sgm/odometry`.
    pub odometry_out: String,
    /// nav_msgs/Odometry of the true pose, in bags written from scenarios (replay's ATE).
    /// Default `ground_truth`.
    pub ground_truth: String,
    /// visualization_msgs/MarkerArray out. Default `sgm/markers`.
    pub markers: String,
    /// nav_msgs/Path out. Default `sgm/path`.
    pub path: String,
    /// sensor_msgs/PointCloud2 semantic map out. Default `sgm/map`.
    pub map: String,
    /// std_msgs/String (JSON) status out. Default `sgm/status`.
    pub status: String,
    /// tf2_msgs/TFMessage out. Default `/tf`.
    pub tf: String,
    /// sgm_msgs/Envelope broadcasts between robots (object data). Default `/sgm/team`.
    pub team: String,
    /// rosgraph_msgs/Clock in, followed only when the parameter `/use_sim_time` is true.
    /// Default `/clock`.
    pub clock: String,
    /// sgm_msgs/Deliver service of each robot (requests and replies addressed to it).
    /// Default `/sgm/robot_{id}/deliver`.
    pub deliver: String,
}

impl Default for RosTopics {
    fn default() -> Self {
        Self {
            points: "points".into(),
            labels: "labels".into(),
            camera_info: "camera_info".into(),
            odometry: "odometry".into(),
            imu: "imu".into(),
            odometry_out: "sgm/odometry".into(),
            ground_truth: "ground_truth".into(),
            markers: "sgm/markers".into(),
            path: "sgm/path".into(),
            map: "sgm/map".into(),
            status: "sgm/status".into(),
            tf: "/tf".into(),
            team: "/sgm/team".into(),
            clock: "/clock".into(),
            deliver: "/sgm/robot_{id}/deliver".into(),
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RosFrames {
    /// The robot's world (odometry) frame: odometry's `header.frame_id`, and the frame of
    /// everything published. Default `{robot}/odom`.
    pub world: String,
    /// The body frame: odometry's `child_frame_id`. Default `{robot}/base_link`.
    pub body: String,
    /// The clouds' frame (points are taken as in the body frame). Default `{robot}/base_link`.
    pub lidar: String,
    /// The label image's and camera info's frame. Default `{robot}/camera`.
    pub camera: String,
    /// The IMU messages' frame (with `odometry.source = "internal"`). Default
    /// `{robot}/base_link`: the IMU at the body origin, its axes the body's.
    pub imu: String,
    /// Frame ids renamed as they come in (messages' headers and tf), before any check: input
    /// name → SGM's name (`{robot}` and `{id}` allowed). For odometry with hard-coded frames on a
    /// one-master fleet: `camera_init = "{robot}/odom"`, `body = "{robot}/base_link"`. The keys
    /// above name frames after renaming. Default none.
    pub aliases: BTreeMap<String, String>,
}

impl Default for RosFrames {
    fn default() -> Self {
        Self {
            world: "{robot}/odom".into(),
            body: "{robot}/base_link".into(),
            lidar: "{robot}/base_link".into(),
            camera: "{robot}/camera".into(),
            imu: "{robot}/base_link".into(),
            aliases: BTreeMap::new(),
        }
    }
}
