//! `sgm run --bag-out DIR`: each robot's simulated sensor streams as a ROS 1 bag
//! (`DIR/NAME.bag`), on the `[ros]` section's topics under the robot's namespace, stamped from
//! [`SCENARIO_EPOCH`]: the LiDAR cloud (float32 x y z, plus the label field when the camera is
//! off), the label image and camera info (camera on, at the image's own stamp), the IMU's
//! samples (`[imu]` on, `sensor_msgs/Imu` at their stamps), the drifting odometry, the true pose
//! (`ground_truth`, for the replay's ATE), and the sensors' mounts on `/tf_static` (latched,
//! once, before the first frame), as a robot's `robot_state_publisher` would publish them.
//! `sgm replay` of these bags gives the scenario's run.

use crate::output_error::OutputError;
use crate::scenario::ImuSpec;
use crate::sim::imu::ImuSample;
use sgm_bridge::bag::writer::BagWriter;
use sgm_bridge::config::RosConfig;
use sgm_bridge::convert::cloud::{cloud_msg, with_times};
use sgm_bridge::convert::geometry::{odometry_msg, transform_msg};
use sgm_bridge::convert::image::{camera_info_msg, label_image_msg};
use sgm_bridge::convert::imu::{imu_msg, ImuReading};
use sgm_bridge::convert::time::SCENARIO_EPOCH;
use sgm_bridge::msg::geometry_msgs::TransformStamped;
use sgm_bridge::msg::std_msgs::Header;
use sgm_bridge::msg::tf2_msgs::TFMessage;
use sgm_model::geometry::Pose3;
use sgm_model::perception::projection::{CameraModel, LabelImage};
use sgm_model::scene_graph::{RobotId, Stamp};
use std::path::{Path, PathBuf};

/// One simulated frame, as the sensors would publish it.
pub struct RecordedFrame<'a> {
    pub t: Stamp,
    pub odometry: &'a Pose3,
    pub truth: &'a Pose3,
    pub points: &'a [nalgebra::Point3<f64>],
    /// Per-point class ids (camera off).
    pub labels: Option<&'a [u16]>,
    /// The label image (camera on).
    pub image: Option<RecordedImage<'a>>,
    /// Each point's time after `t`, s (`lidar.sweep_s` > 0): written as a `time` field.
    pub times: Option<&'a [f32]>,
    /// The IMU's samples since the last frame (`[imu]`), each at its own stamp.
    pub imu: &'a [ImuSample],
}

/// A label image as the camera publishes it.
pub struct RecordedImage<'a> {
    pub image: &'a LabelImage,
    pub camera: &'a CameraModel,
    /// Its stamp (`camera.exposure_offset_s` and `clock_offset_s` after the scan's).
    pub stamp: Stamp,
    /// The mount the robot is told (written on `/tf_static`).
    pub camera_from_body: Pose3,
}

struct RobotBag {
    writer: BagWriter,
    /// points, labels, camera_info, odometry, ground_truth, imu.
    topics: [String; 6],
    /// world, body, lidar, camera.
    frames: [String; 4],
    /// `ros.tf.static_topic`, resolved.
    tf_static: String,
    /// The mounts are written (once, before the first frame).
    mounts_written: bool,
}

pub struct BagRecorder {
    dir: PathBuf,
    bags: Vec<Option<RobotBag>>,
    ros: RosConfig,
    names: Vec<String>,
    /// Per-sample white noise variances of the IMU, gyro (rad²/s²) and accelerometer (m²/s⁴),
    /// written as the messages' covariances.
    imu_variances: [f64; 2],
}

impl BagRecorder {
    pub fn new(dir: &Path, ros: &RosConfig, names: Vec<String>) -> Result<Self, OutputError> {
        std::fs::create_dir_all(dir).map_err(OutputError::at(dir))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            bags: names.iter().map(|_| None).collect(),
            ros: ros.clone(),
            names,
            imu_variances: [0.0; 2],
        })
    }

    /// The IMU's noise densities, for the covariances of its messages (`[imu]`).
    pub fn with_imu(mut self, imu: &ImuSpec) -> Self {
        self.imu_variances = [imu.gyro_noise.powi(2) * imu.rate_hz, imu.accel_noise.powi(2) * imu.rate_hz];
        self
    }

    fn bag(&mut self, k: usize) -> Result<&mut RobotBag, OutputError> {
        let (name, id) = (&self.names[k], RobotId::from_index(k).0);
        let bag = match self.bags[k].take() {
            Some(bag) => bag,
            None => {
                let path = self.dir.join(format!("{name}.bag"));
                let writer = BagWriter::create(&path).map_err(OutputError::at(&path))?;
                let t = &self.ros.topics;
                let topic = |template: &str| {
                    let resolved = RosConfig::resolve(template, name, id);
                    if resolved.starts_with('/') {
                        resolved
                    } else {
                        format!("/{name}/{resolved}")
                    }
                };
                let inputs = sgm_bridge::inputs::Inputs::new(&self.ros, name, id);
                RobotBag {
                    writer,
                    topics: [
                        topic(&t.points),
                        topic(&t.labels),
                        topic(&t.camera_info),
                        topic(&t.odometry),
                        topic(&t.ground_truth),
                        topic(&t.imu),
                    ],
                    frames: [inputs.world_frame(), inputs.body_frame(), inputs.lidar_frame(), inputs.camera_frame()]
                        .map(str::to_string),
                    tf_static: topic(&self.ros.tf.static_topic),
                    mounts_written: false,
                }
            }
        };
        Ok(self.bags[k].insert(bag))
    }

    pub fn record(&mut self, k: usize, frame: RecordedFrame<'_>) -> Result<(), OutputError> {
        let path = self.dir.join(format!("{}.bag", self.names[k]));
        let [gyro_variance, accel_variance] = self.imu_variances;
        let bag = self.bag(k)?;
        let time = SCENARIO_EPOCH.time(frame.t);
        let header = |frame_id: &str| Header { seq: 0, stamp: time, frame_id: frame_id.to_string() };
        let [world, body, lidar, camera] = &bag.frames;
        let [points_topic, labels_topic, info_topic, odometry_topic, truth_topic, imu_topic] = &bag.topics;
        let e = OutputError::at(&path);
        if !bag.mounts_written {
            bag.mounts_written = true;
            let camera_mount = frame.image.as_ref().map(|i| (camera.as_str(), i.camera_from_body));
            let mounts = mounts(header(body), lidar, camera_mount);
            if !mounts.transforms.is_empty() {
                bag.writer.write_latched(&bag.tf_static, time, &mounts).map_err(&e)?;
            }
        }
        let w = &mut bag.writer;
        // Camera info first, as a camera driver publishes it: a replay must not take its epoch
        // from a message without a stamp (regression: `replay_bags.rs`).
        if let Some(shot) = frame.image {
            let time = SCENARIO_EPOCH.time(shot.stamp);
            let header = Header { seq: 0, stamp: time, frame_id: camera.to_string() };
            w.write(info_topic, time, &camera_info_msg(header.clone(), shot.camera)).map_err(&e)?;
            w.write(labels_topic, time, &label_image_msg(header, shot.image)).map_err(&e)?;
        }
        write_imu(w, imu_topic, body, frame.imu, [gyro_variance, accel_variance]).map_err(&e)?;
        w.write(odometry_topic, time, &odometry_msg(header(world), body, frame.odometry)).map_err(&e)?;
        w.write(truth_topic, time, &odometry_msg(header("truth"), body, frame.truth)).map_err(&e)?;
        let cloud = sweep_msg(header(lidar), frame.points, frame.labels, frame.times);
        w.write(points_topic, time, &cloud).map_err(&e)?;
        Ok(())
    }

    /// An unlabelled sweep between two frames (the internal odometry's, `odometry.source =
    /// "internal"`): the IMU's samples since the last record, then the cloud, with its points'
    /// times and no label field. A replay hands it to the odometry alone, as the run did.
    pub fn record_sweep(
        &mut self,
        k: usize,
        t: f64,
        points: &[nalgebra::Point3<f64>],
        times: Option<&[f32]>,
        imu: &[ImuSample],
    ) -> Result<(), OutputError> {
        let path = self.dir.join(format!("{}.bag", self.names[k]));
        let [gyro_variance, accel_variance] = self.imu_variances;
        let bag = self.bag(k)?;
        let e = OutputError::at(&path);
        let [_, body, lidar, _] = &bag.frames;
        let [points_topic, .., imu_topic] = &bag.topics;
        write_imu(&mut bag.writer, imu_topic, body, imu, [gyro_variance, accel_variance]).map_err(&e)?;
        let time = SCENARIO_EPOCH.time(t);
        let header = Header { seq: 0, stamp: time, frame_id: lidar.to_string() };
        bag.writer.write(points_topic, time, &sweep_msg(header, points, None, times)).map_err(&e)
    }

    /// Closes every bag; returns their paths.
    pub fn finish(self) -> Result<Vec<PathBuf>, OutputError> {
        let mut paths = Vec::new();
        for (bag, name) in self.bags.into_iter().zip(&self.names) {
            if let Some(bag) = bag {
                let path = self.dir.join(format!("{name}.bag"));
                bag.writer.finish().map_err(OutputError::at(&path))?;
                paths.push(path);
            }
        }
        Ok(paths)
    }
}

/// A sweep's cloud as the driver publishes it: float32 points, a label field when labelled, a
/// `time` field when its points carry their times.
fn sweep_msg(
    header: Header,
    points: &[nalgebra::Point3<f64>],
    labels: Option<&[u16]>,
    times: Option<&[f32]>,
) -> sgm_bridge::msg::sensor_msgs::PointCloud2 {
    let points: Vec<nalgebra::Point3<f32>> = points.iter().map(|p| p.map(|v| v as f32)).collect();
    let cloud = cloud_msg(header, &points, labels, |_| [200, 200, 200]);
    match times {
        Some(times) => with_times(cloud, times),
        None => cloud,
    }
}

/// IMU samples as `sensor_msgs/Imu` in the body frame, each at its own stamp, with the
/// variances `[gyro, accel]` per sample on its covariances' diagonals.
fn write_imu(
    w: &mut BagWriter,
    topic: &str,
    body: &str,
    samples: &[ImuSample],
    [gyro_variance, accel_variance]: [f64; 2],
) -> std::io::Result<()> {
    for sample in samples {
        let time = SCENARIO_EPOCH.time(sample.stamp);
        let header = Header { seq: 0, stamp: time, frame_id: body.to_string() };
        let reading =
            ImuReading { angular_velocity: sample.angular_velocity, linear_acceleration: sample.specific_force };
        w.write(topic, time, &imu_msg(header, &reading, gyro_variance, accel_variance))?;
    }
    Ok(())
}

/// The simulated sensors' mounts as tf gives them (`header` names the body frame): the LiDAR at
/// the body origin (written only when its frame has another name), the camera's optical frame
/// where the robot is told it is (`camera_from_body`, inverted).
fn mounts(header: Header, lidar: &str, camera: Option<(&str, Pose3)>) -> TFMessage {
    let body = header.frame_id.clone();
    let mount = |child: &str, body_from_child: &Pose3| TransformStamped {
        header: header.clone(),
        child_frame_id: child.to_string(),
        transform: transform_msg(body_from_child),
    };
    let mut transforms = Vec::new();
    if lidar.trim_start_matches('/') != body.trim_start_matches('/') {
        transforms.push(mount(lidar, &Pose3::identity()));
    }
    if let Some((camera, camera_from_body)) =
        camera.filter(|(c, _)| c.trim_start_matches('/') != body.trim_start_matches('/'))
    {
        transforms.push(mount(camera, &camera_from_body.inverse()));
    }
    TFMessage { transforms }
}
