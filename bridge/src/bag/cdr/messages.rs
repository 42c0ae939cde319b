//! The ROS 2 messages SGM reads, decoded from CDR into the ROS 1 types the rest of the bridge
//! checks and converts (`crate::msg`), field by field as ROS 2 Humble defines them:
//!
//! - `std_msgs/Header` has no `seq` (0 here) and its stamp is `builtin_interfaces/Time`
//!   (`int32 sec`, `uint32 nanosec`): a negative `sec` has no ROS 1 time and is refused;
//! - `sensor_msgs/CameraInfo` names its matrices `d`, `k`, `r`, `p` (ROS 1: `D`, `K`, `R`, `P`),
//!   same order and sizes;
//! - the others (`PointCloud2`, `Image`, `Odometry`, `Imu`, `TFMessage`) have the same fields.

use super::reader::{CdrError, CdrReader};
use crate::msg::{geometry_msgs, nav_msgs, sensor_msgs, std_msgs, tf2_msgs};
use rosrust::Time;

/// A message decodable from CDR, with its ROS 2 type name.
pub trait FromCdr: Sized {
    /// `package/msg/Name`, as rosbag2 records it.
    const ROS2_TYPE: &'static str;
    fn read(r: &mut CdrReader) -> Result<Self, CdrError>;
}

/// Decodes a whole CDR message of at most `max_bytes`.
pub fn decode<M: FromCdr>(bytes: &[u8], max_bytes: usize) -> Result<M, CdrError> {
    let mut r = CdrReader::new(bytes, max_bytes)?;
    let msg = M::read(&mut r)?;
    r.finish()?;
    Ok(msg)
}

fn header(r: &mut CdrReader) -> Result<std_msgs::Header, CdrError> {
    let sec = r.i32("header.stamp.sec")?;
    let nsec = r.u32("header.stamp.nanosec")?;
    let sec = u32::try_from(sec)
        .map_err(|_| CdrError::Value { field: "header.stamp.sec", what: format!("{sec} is before 1970") })?;
    Ok(std_msgs::Header { seq: 0, stamp: Time { sec, nsec }, frame_id: r.string("header.frame_id")? })
}

fn vector3(r: &mut CdrReader, field: &'static str) -> Result<geometry_msgs::Vector3, CdrError> {
    let [x, y, z] = r.f64_array::<3>(field)?;
    Ok(geometry_msgs::Vector3 { x, y, z })
}

fn quaternion(r: &mut CdrReader, field: &'static str) -> Result<geometry_msgs::Quaternion, CdrError> {
    let [x, y, z, w] = r.f64_array::<4>(field)?;
    Ok(geometry_msgs::Quaternion { x, y, z, w })
}

impl FromCdr for sensor_msgs::PointCloud2 {
    const ROS2_TYPE: &'static str = "sensor_msgs/msg/PointCloud2";
    fn read(r: &mut CdrReader) -> Result<Self, CdrError> {
        let header = header(r)?;
        let (height, width) = (r.u32("height")?, r.u32("width")?);
        // A PointField is at least 13 bytes: a string's length, offset, datatype, count.
        let count = r.count("fields", 13)?;
        let mut fields = Vec::new();
        for _ in 0..count {
            fields.push(sensor_msgs::PointField {
                name: r.string("fields.name")?,
                offset: r.u32("fields.offset")?,
                datatype: r.u8("fields.datatype")?,
                count: r.u32("fields.count")?,
            });
        }
        Ok(Self {
            header,
            height,
            width,
            fields,
            is_bigendian: r.bool("is_bigendian")?,
            point_step: r.u32("point_step")?,
            row_step: r.u32("row_step")?,
            data: r.bytes("data")?.to_vec(),
            is_dense: r.bool("is_dense")?,
        })
    }
}

impl FromCdr for sensor_msgs::Image {
    const ROS2_TYPE: &'static str = "sensor_msgs/msg/Image";
    fn read(r: &mut CdrReader) -> Result<Self, CdrError> {
        Ok(Self {
            header: header(r)?,
            height: r.u32("height")?,
            width: r.u32("width")?,
            encoding: r.string("encoding")?,
            is_bigendian: r.u8("is_bigendian")?,
            step: r.u32("step")?,
            data: r.bytes("data")?.to_vec(),
        })
    }
}

impl FromCdr for sensor_msgs::CameraInfo {
    const ROS2_TYPE: &'static str = "sensor_msgs/msg/CameraInfo";
    fn read(r: &mut CdrReader) -> Result<Self, CdrError> {
        Ok(Self {
            header: header(r)?,
            height: r.u32("height")?,
            width: r.u32("width")?,
            distortion_model: r.string("distortion_model")?,
            D: r.f64_seq("d")?,
            K: r.f64_array("k")?,
            R: r.f64_array("r")?,
            P: r.f64_array("p")?,
            binning_x: r.u32("binning_x")?,
            binning_y: r.u32("binning_y")?,
            roi: sensor_msgs::RegionOfInterest {
                x_offset: r.u32("roi.x_offset")?,
                y_offset: r.u32("roi.y_offset")?,
                height: r.u32("roi.height")?,
                width: r.u32("roi.width")?,
                do_rectify: r.bool("roi.do_rectify")?,
            },
        })
    }
}

impl FromCdr for nav_msgs::Odometry {
    const ROS2_TYPE: &'static str = "nav_msgs/msg/Odometry";
    fn read(r: &mut CdrReader) -> Result<Self, CdrError> {
        let header = header(r)?;
        let child_frame_id = r.string("child_frame_id")?;
        let [x, y, z] = r.f64_array::<3>("pose.pose.position")?;
        let pose = geometry_msgs::PoseWithCovariance {
            pose: geometry_msgs::Pose {
                position: geometry_msgs::Point { x, y, z },
                orientation: quaternion(r, "pose.pose.orientation")?,
            },
            covariance: r.f64_array("pose.covariance")?,
        };
        let twist = geometry_msgs::TwistWithCovariance {
            twist: geometry_msgs::Twist {
                linear: vector3(r, "twist.twist.linear")?,
                angular: vector3(r, "twist.twist.angular")?,
            },
            covariance: r.f64_array("twist.covariance")?,
        };
        Ok(Self { header, child_frame_id, pose, twist })
    }
}

impl FromCdr for sensor_msgs::Imu {
    const ROS2_TYPE: &'static str = "sensor_msgs/msg/Imu";
    fn read(r: &mut CdrReader) -> Result<Self, CdrError> {
        Ok(Self {
            header: header(r)?,
            orientation: quaternion(r, "orientation")?,
            orientation_covariance: r.f64_array("orientation_covariance")?,
            angular_velocity: vector3(r, "angular_velocity")?,
            angular_velocity_covariance: r.f64_array("angular_velocity_covariance")?,
            linear_acceleration: vector3(r, "linear_acceleration")?,
            linear_acceleration_covariance: r.f64_array("linear_acceleration_covariance")?,
        })
    }
}

impl FromCdr for tf2_msgs::TFMessage {
    const ROS2_TYPE: &'static str = "tf2_msgs/msg/TFMessage";
    fn read(r: &mut CdrReader) -> Result<Self, CdrError> {
        // A TransformStamped is at least 72 bytes: stamp, two string lengths, 7 float64.
        let count = r.count("transforms", 72)?;
        let mut transforms = Vec::new();
        for _ in 0..count {
            transforms.push(geometry_msgs::TransformStamped {
                header: header(r)?,
                child_frame_id: r.string("transforms.child_frame_id")?,
                transform: geometry_msgs::Transform {
                    translation: vector3(r, "transforms.transform.translation")?,
                    rotation: quaternion(r, "transforms.transform.rotation")?,
                },
            });
        }
        Ok(Self { transforms })
    }
}
