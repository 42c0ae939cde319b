//! One robot's sensor inputs, checked: the node's subscribers and the bag replay both pass
//! every message through here, so a message refused live is refused in replay for the same
//! reason. Sizes are bounded before anything is allocated for the points.

use crate::config::RosConfig;
use crate::convert::cloud::{read_cloud, Scan};
use crate::convert::geometry::{check_frame, pose_from_msg};
use crate::convert::image::{read_camera_info, read_label_image, UnknownColours};
use crate::convert::imu::{reading_from_msg, ImuReading};
use crate::error::InputError;
use crate::msg::{nav_msgs, sensor_msgs, tf2_msgs};
use crate::tf::{TfBatch, TfTransform};
use rosrust::Time;
use sgm_model::geometry::Pose3;
use sgm_model::perception::colour_ids::ColourIds;
use sgm_model::perception::projection::{CameraModel, LabelImage};
use std::collections::BTreeMap;
use std::sync::Arc;

/// A decoded, checked input message (header stamps in ROS time).
#[derive(Clone, Debug)]
pub enum Payload {
    Cloud(Time, Scan),
    /// A label image, and the pixels of colours its palette lacks (colour images).
    Image(Time, LabelImage, UnknownColours),
    CameraInfo(CameraModel),
    Odometry(Time, Pose3),
    GroundTruth(Time, Pose3),
    /// `/clock` (with `use_sim_time`): time passes, no data.
    Clock(Time),
    /// A TFMessage from `/tf` or `/tf_static` (its own stamps; not checked by the timeline).
    Tf(TfBatch),
    /// An IMU sample (`sensor_msgs/Imu`, in the IMU's frame), rates and specific force checked.
    /// The robot's own odometry's input (`odometry.source = "internal"`).
    Imu(Time, ImuReading),
}

impl Payload {
    /// The input it came on, as the status and the health checks name it.
    pub fn input_name(&self) -> &'static str {
        match self {
            Payload::Cloud(..) => "points",
            Payload::Image(..) => "labels",
            Payload::CameraInfo(_) => "camera_info",
            Payload::Odometry(..) => "odometry",
            Payload::GroundTruth(..) => "ground_truth",
            Payload::Clock(_) => "clock",
            Payload::Tf(batch) if batch.is_static => "tf_static",
            Payload::Tf(_) => "tf",
            Payload::Imu(..) => "imu",
        }
    }
}

/// The checks of one robot's inputs, with its frame names resolved.
#[derive(Clone, Debug)]
pub struct Inputs {
    world_frame: String,
    body_frame: String,
    lidar_frame: String,
    camera_frame: String,
    imu_frame: String,
    label_field: String,
    max_cloud_points: usize,
    max_image_pixels: usize,
    /// `ros.frames.aliases`, resolved: input frame (no leading `/`) → SGM's name.
    aliases: BTreeMap<String, String>,
    /// Colour label images back to pixel values (`[classes]`); none: colour images refused.
    colours: Option<Arc<ColourIds>>,
}

impl Inputs {
    pub fn new(config: &RosConfig, robot: &str, id: u16) -> Self {
        let frame = |template: &str| RosConfig::resolve(template, robot, id);
        Self {
            world_frame: frame(&config.frames.world),
            body_frame: frame(&config.frames.body),
            lidar_frame: frame(&config.frames.lidar),
            camera_frame: frame(&config.frames.camera),
            imu_frame: frame(&config.frames.imu),
            label_field: if config.labels == crate::config::LabelSource::Cloud {
                config.label_field.clone()
            } else {
                String::new()
            },
            max_cloud_points: config.max_cloud_points,
            max_image_pixels: config.max_image_pixels,
            aliases: config
                .frames
                .aliases
                .iter()
                .map(|(from, to)| (from.trim_start_matches('/').to_string(), frame(to)))
                .collect(),
            colours: None,
        }
    }

    /// Colour label images read back through `colours` (the robot's `[classes]` palette).
    pub fn with_colours(mut self, colours: ColourIds) -> Self {
        self.colours = Some(Arc::new(colours));
        self
    }

    /// A frame id as SGM names it: its alias, if it has one.
    pub fn frame<'a>(&'a self, id: &'a str) -> &'a str {
        self.aliases.get(id.trim_start_matches('/')).map_or(id, String::as_str)
    }

    pub fn cloud(&self, msg: &sensor_msgs::PointCloud2) -> Result<Payload, InputError> {
        check_frame(self.frame(&msg.header.frame_id), &self.lidar_frame)?;
        let count = u64::from(msg.width) * u64::from(msg.height);
        if count > self.max_cloud_points as u64 {
            return Err(InputError::invalid(format!("{count} points, at most {} accepted", self.max_cloud_points)));
        }
        Ok(Payload::Cloud(msg.header.stamp, read_cloud(msg, &self.label_field)?))
    }

    pub fn image(&self, msg: &sensor_msgs::Image) -> Result<Payload, InputError> {
        check_frame(self.frame(&msg.header.frame_id), &self.camera_frame)?;
        let pixels = u64::from(msg.width) * u64::from(msg.height);
        if pixels > self.max_image_pixels as u64 {
            return Err(InputError::invalid(format!("{pixels} pixels, at most {} accepted", self.max_image_pixels)));
        }
        let (image, unknown) = read_label_image(msg, self.colours.as_deref())?;
        Ok(Payload::Image(msg.header.stamp, image, unknown))
    }

    pub fn camera_info(&self, msg: &sensor_msgs::CameraInfo) -> Result<Payload, InputError> {
        check_frame(self.frame(&msg.header.frame_id), &self.camera_frame)?;
        Ok(Payload::CameraInfo(read_camera_info(msg)?))
    }

    pub fn odometry(&self, msg: &nav_msgs::Odometry) -> Result<Payload, InputError> {
        check_frame(self.frame(&msg.header.frame_id), &self.world_frame)?;
        check_frame(self.frame(&msg.child_frame_id), &self.body_frame)?;
        Ok(Payload::Odometry(msg.header.stamp, pose_from_msg(&msg.pose.pose)?))
    }

    /// A TFMessage: each transform checked on its own (a bad one is refused, naming its
    /// frames, and the others kept), frames aliased. Refused whole only when none passes.
    pub fn tf(&self, msg: &tf2_msgs::TFMessage, is_static: bool) -> Result<Payload, InputError> {
        let mut batch =
            TfBatch { is_static, transforms: Vec::with_capacity(msg.transforms.len()), refused: Vec::new() };
        for t in &msg.transforms {
            let (parent, child) = (self.frame(&t.header.frame_id), self.frame(&t.child_frame_id));
            let r = &t.transform;
            let pose = crate::msg::geometry_msgs::Pose {
                position: crate::msg::geometry_msgs::Point {
                    x: r.translation.x,
                    y: r.translation.y,
                    z: r.translation.z,
                },
                orientation: r.rotation.clone(),
            };
            match pose_from_msg(&pose) {
                Ok(parent_from_child) => batch.transforms.push(TfTransform {
                    stamp: t.header.stamp,
                    parent: parent.trim_start_matches('/').to_string(),
                    child: child.trim_start_matches('/').to_string(),
                    parent_from_child,
                }),
                Err(e) => batch.refused.push(format!("`{parent}` → `{child}`: {e}")),
            }
        }
        if batch.transforms.is_empty() && !batch.refused.is_empty() {
            return Err(InputError::invalid(batch.refused.join("; ")));
        }
        Ok(Payload::Tf(batch))
    }

    /// An IMU sample: its frame must be `frames.imu`, its values finite and within any IMU's
    /// range (`convert::imu::reading_from_msg`). It stays in the IMU's frame; the
    /// synchroniser brings it to the body through the IMU's mount.
    pub fn imu(&self, msg: &sensor_msgs::Imu) -> Result<Payload, InputError> {
        check_frame(self.frame(&msg.header.frame_id), &self.imu_frame)?;
        Ok(Payload::Imu(msg.header.stamp, reading_from_msg(msg)?))
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

    pub fn imu_frame(&self) -> &str {
        &self.imu_frame
    }
}
