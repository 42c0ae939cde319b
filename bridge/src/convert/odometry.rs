//! The robot's own odometry as ROS gives odometry: a `nav_msgs/Odometry` and the world → body
//! transform for tf.
//!
//! `nav_msgs/Odometry` holds the pose in `header.frame_id` (the robot's world) and the twist in
//! `child_frame_id` (the body). Its pose covariance is ordered (x, y, z, rotation about x, y, z),
//! in the world's axes. The odometry's covariance is that of the right perturbation
//! e = (ω, ν) in T = T̂ · Exp(e), in the body's axes. To first order the world sees the
//! rotation error as R ω and the position error as R ν. With B = diag(R, R):
//!
//! ```text
//! Σ_ros = B · P Σ Pᵀ · Bᵀ,   P swaps (ω, ν) to (ν, ω)
//! ```
//!
//! The twist is the body's: linear Rᵀ v (v in the world), angular the sweep's gyro mean with its
//! bias removed. The filter does not give its covariance, so it is marked unknown: −1 first, as
//! REP 145 marks an unknown orientation.

use crate::convert::geometry::{pose_msg, transform_msg};
use crate::msg::{geometry_msgs, nav_msgs, std_msgs};
use nalgebra::{Matrix3, Vector3};
use sgm_actors::odometry::OdometryPose;
use sgm_model::geometry::lie::Matrix6;

/// `covariance` (of (ω, ν), body axes) as `nav_msgs/Odometry` orders it (x, y, z, rx, ry, rz,
/// world axes), row-major.
pub fn pose_covariance_msg(covariance: &Matrix6, world_from_body_rotation: &Matrix3<f64>) -> [f64; 36] {
    let mut b = Matrix6::zeros();
    // Rows 0..3 of the ROS order are positions (ν, body rows 3..6), rows 3..6 rotations (ω, 0..3).
    b.fixed_view_mut::<3, 3>(0, 3).copy_from(world_from_body_rotation);
    b.fixed_view_mut::<3, 3>(3, 0).copy_from(world_from_body_rotation);
    let ros = b * covariance * b.transpose();
    let mut out = [0.0; 36];
    for (k, value) in out.iter_mut().enumerate() {
        *value = ros[(k / 6, k % 6)];
    }
    out
}

fn vector_msg(v: &Vector3<f64>) -> geometry_msgs::Vector3 {
    geometry_msgs::Vector3 { x: v.x, y: v.y, z: v.z }
}

/// The estimate as `nav_msgs/Odometry`: `header` names the world frame, `body_frame` the child.
pub fn odometry_pose_msg(header: std_msgs::Header, body_frame: &str, pose: &OdometryPose) -> nav_msgs::Odometry {
    let rotation = pose.odom_from_body.rotation.to_rotation_matrix().into_inner();
    let mut msg = nav_msgs::Odometry { header, child_frame_id: body_frame.to_string(), ..Default::default() };
    msg.pose.pose = pose_msg(&pose.odom_from_body);
    msg.pose.covariance = pose_covariance_msg(&pose.covariance, &rotation);
    msg.twist.twist.linear = vector_msg(&(rotation.transpose() * pose.velocity));
    msg.twist.twist.angular = vector_msg(&pose.angular_velocity.unwrap_or_else(Vector3::zeros));
    msg.twist.covariance[0] = -1.0;
    msg
}

/// The estimate as the world → body transform for tf.
pub fn odometry_transform(
    header: std_msgs::Header,
    body_frame: &str,
    pose: &OdometryPose,
) -> geometry_msgs::TransformStamped {
    geometry_msgs::TransformStamped {
        header,
        child_frame_id: body_frame.to_string(),
        transform: transform_msg(&pose.odom_from_body),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};
    use sgm_model::geometry::Pose3;

    /// Closed form: a body turned 90° about z, moving at 1 m/s along the world's y (its own
    /// x), with variances 1…6 on (ωx, ωy, ωz, νx, νy, νz). In the world's axes the body's x is
    /// the world's y: the position variances come out (νy, νx, νz) = (5, 4, 6), the rotation
    /// ones (ωy, ωx, ωz) = (2, 1, 3); the twist is (1, 0, 0) in the body.
    #[test]
    fn the_covariance_and_twist_come_out_in_the_frames_ros_expects() {
        let turned = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let pose = OdometryPose {
            stamp: 1.0,
            odom_from_body: Pose3::from_parts(Translation3::new(1.0, 2.0, 3.0), turned),
            velocity: Vector3::new(0.0, 1.0, 0.0),
            angular_velocity: Some(Vector3::new(0.0, 0.0, 0.25)),
            covariance: Matrix6::from_diagonal(&nalgebra::Vector6::new(1.0, 2.0, 3.0, 4.0, 5.0, 6.0)),
        };
        let msg = odometry_pose_msg(std_msgs::Header::default(), "alpha/base_link", &pose);
        let diagonal: Vec<f64> = (0..6).map(|k| msg.pose.covariance[k * 7]).collect();
        for (got, expected) in diagonal.iter().zip([5.0, 4.0, 6.0, 2.0, 1.0, 3.0]) {
            assert!((got - expected).abs() < 1e-12, "{diagonal:?}");
        }
        let off: f64 = (0..36).filter(|k| k % 7 != 0).map(|k| msg.pose.covariance[k].abs()).sum();
        assert!(off < 1e-12, "{:?}", msg.pose.covariance);
        let linear = &msg.twist.twist.linear;
        assert!((linear.x - 1.0).abs() < 1e-12 && linear.y.abs() < 1e-12 && linear.z.abs() < 1e-12, "{linear:?}");
        assert_eq!(msg.twist.twist.angular.z, 0.25);
        assert_eq!(msg.twist.covariance[0], -1.0, "unknown");
        assert_eq!((msg.pose.pose.position.x, msg.child_frame_id.as_str()), (1.0, "alpha/base_link"));
        let t = odometry_transform(std_msgs::Header::default(), "alpha/base_link", &pose);
        assert_eq!((t.transform.translation.z, t.child_frame_id.as_str()), (3.0, "alpha/base_link"));
    }
}
