//! One robot's sensor inputs, checked: the node's subscribers and the bag replay both pass
//! every message through here, so a message refused live is refused in replay for the same
//! reason. Sizes are bounded before anything is allocated for the points.

use crate::config::RosConfig;
use crate::convert::cloud::{read_cloud, Scan};
use crate::convert::geometry::{check_frame, pose_from_msg, pose_from_odometry};
use crate::convert::image::{read_camera_info, read_label_image};
use crate::error::InputError;
use crate::msg::{nav_msgs, sensor_msgs};
use rosrust::Time;
use sgm_model::geometry::Pose3;
use sgm_model::perception::projection::{CameraModel, LabelImage};

/// A decoded, checked input message (header stamps in ROS time).
#[derive(Clone, Debug)]
pub enum Payload {
    Cloud(Time, Scan),
    Image(Time, LabelImage),
    CameraInfo(CameraModel),
    Odometry(Time, Pose3),
    GroundTruth(Time, Pose3),
    /// `/clock` (with `use_sim_time`): time passes, no data.
    Clock(Time),
}

/// The checks of one robot's inputs, with its frame names resolved.
#[derive(Clone, Debug)]
pub struct Inputs {
    world_frame: String,
    body_frame: String,
    lidar_frame: String,
    camera_frame: String,
    label_field: String,
    max_cloud_points: usize,
    max_image_pixels: usize,
}

impl Inputs {
    pub fn new(config: &RosConfig, robot: &str, id: u16) -> Self {
        let frame = |template: &str| RosConfig::resolve(template, robot, id);
        Self {
            world_frame: frame(&config.frames.world),
            body_frame: frame(&config.frames.body),
            lidar_frame: frame(&config.frames.lidar),
            camera_frame: frame(&config.frames.camera),
            label_field: if config.labels == crate::config::LabelSource::Cloud {
                config.label_field.clone()
            } else {
                String::new()
            },
            max_cloud_points: config.max_cloud_points,
            max_image_pixels: config.max_image_pixels,
        }
    }

    pub fn cloud(&self, msg: &sensor_msgs::PointCloud2) -> Result<Payload, InputError> {
        check_frame(&msg.header.frame_id, &self.lidar_frame)?;
        let count = u64::from(msg.width) * u64::from(msg.height);
        if count > self.max_cloud_points as u64 {
            return Err(InputError::invalid(format!("{count} points, at most {} accepted", self.max_cloud_points)));
        }
        Ok(Payload::Cloud(msg.header.stamp, read_cloud(msg, &self.label_field)?))
    }

    pub fn image(&self, msg: &sensor_msgs::Image) -> Result<Payload, InputError> {
        check_frame(&msg.header.frame_id, &self.camera_frame)?;
        let pixels = u64::from(msg.width) * u64::from(msg.height);
        if pixels > self.max_image_pixels as u64 {
            return Err(InputError::invalid(format!("{pixels} pixels, at most {} accepted", self.max_image_pixels)));
        }
        Ok(Payload::Image(msg.header.stamp, read_label_image(msg)?))
    }

    pub fn camera_info(&self, msg: &sensor_msgs::CameraInfo) -> Result<Payload, InputError> {
        check_frame(&msg.header.frame_id, &self.camera_frame)?;
        Ok(Payload::CameraInfo(read_camera_info(msg)?))
    }

    pub fn odometry(&self, msg: &nav_msgs::Odometry) -> Result<Payload, InputError> {
        Ok(Payload::Odometry(msg.header.stamp, pose_from_odometry(msg, &self.world_frame, &self.body_frame)?))
    }

    /// A true pose (frames are the simulator's, not checked).
    pub fn ground_truth(&self, msg: &nav_msgs::Odometry) -> Result<Payload, InputError> {
        Ok(Payload::GroundTruth(msg.header.stamp, pose_from_msg(&msg.pose.pose)?))
    }

    pub fn world_frame(&self) -> &str {
        &self.world_frame
    }

    pub fn body_frame(&self) -> &str {
        &self.body_frame
    }

    pub fn lidar_frame(&self) -> &str {
        &self.lidar_frame
    }

    pub fn camera_frame(&self) -> &str {
        &self.camera_frame
    }
}
