//! The sensors' mountings pinned in `[ros]` (`camera_from_body` or `body_from_camera`,
//! `body_from_lidar`, `body_from_imu`), checked; unpinned ones are read from tf.

use super::{RosConfig, RosConfigError};
use sgm_model::geometry::Pose3;

/// A pose key's [x, y, z, qx, qy, qz, qw], checked; errors name `ros.KEY`.
fn pose_key([x, y, z, qx, qy, qz, qw]: [f64; 7], key: &'static str) -> Result<Pose3, RosConfigError> {
    let pose = crate::msg::geometry_msgs::Pose {
        position: crate::msg::geometry_msgs::Point { x, y, z },
        orientation: crate::msg::geometry_msgs::Quaternion { x: qx, y: qy, z: qz, w: qw },
    };
    crate::convert::geometry::pose_from_msg(&pose).map_err(|source| RosConfigError::Mount { key, source })
}

impl RosConfig {
    /// The camera mounting pinned by configuration, as `body_from_camera`: `body_from_camera`,
    /// or the inverse of `camera_from_body` (checked: finite, unit quaternion, not both set).
    /// `None`: read from tf.
    pub fn camera_pin(&self) -> Result<Option<Pose3>, RosConfigError> {
        match (self.camera_from_body, self.body_from_camera) {
            (Some(_), Some(_)) => Err(RosConfigError::BothCameraMounts),
            (Some(values), None) => pose_key(values, "camera_from_body").map(|c| Some(c.inverse())),
            (None, Some(values)) => pose_key(values, "body_from_camera").map(Some),
            (None, None) => Ok(None),
        }
    }

    /// The LiDAR mounting pinned by configuration (`body_from_lidar`); `None`: from tf.
    pub fn lidar_pin(&self) -> Result<Option<Pose3>, RosConfigError> {
        self.body_from_lidar.map(|values| pose_key(values, "body_from_lidar")).transpose()
    }

    /// The IMU mounting pinned by configuration (`body_from_imu`); `None`: from tf.
    pub fn imu_pin(&self) -> Result<Option<Pose3>, RosConfigError> {
        self.body_from_imu.map(|values| pose_key(values, "body_from_imu")).transpose()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    fn close(a: Point3<f64>, b: [f64; 3]) -> bool {
        (a - Point3::from(b)).norm() < 1e-12
    }

    /// Unset, the camera's mounting comes from tf; the optical frame of a camera at the body
    /// origin looking along +x, as tf gives it (`[0, 0, 0, -0.5, 0.5, -0.5, 0.5]`), closed form:
    /// a point 5 m ahead of the body (+x) is 5 m down the optical axis (+z); one to the body's
    /// left (+y) is to the image's left (−x); one above (+z) is up in the image (−y).
    #[test]
    fn body_from_camera_is_the_optical_frames_pose() {
        assert_eq!(RosConfig::default().camera_pin(), Ok(None));
        let tf_pose = [0.0, 0.0, 0.0, -0.5, 0.5, -0.5, 0.5];
        let body_from_camera =
            RosConfig { body_from_camera: Some(tf_pose), ..Default::default() }.camera_pin().unwrap().unwrap();
        let c = body_from_camera.inverse();
        assert!(close(c * Point3::new(5.0, 0.0, 0.0), [0.0, 0.0, 5.0]));
        assert!(close(c * Point3::new(0.0, 1.0, 0.0), [-1.0, 0.0, 0.0]));
        assert!(close(c * Point3::new(0.0, 0.0, 1.0), [0.0, -1.0, 0.0]));
        let optical = sgm_model::perception::projection::optical_from_forward_body();
        assert!((c.to_homogeneous() - optical.to_homogeneous()).norm() < 1e-12);
    }

    /// A camera 0.2 m ahead of and 0.1 m above the body origin, given as tf gives it: its
    /// origin maps to the camera's origin and a point 5 m further ahead to 5 m down its axis;
    /// the same mounting as `camera_from_body` (the inverse) gives the same transform.
    #[test]
    fn camera_from_body_is_the_inverse_mounting() {
        let tf_pose = [0.2, 0.0, 0.1, -0.5, 0.5, -0.5, 0.5];
        let from_tf =
            RosConfig { body_from_camera: Some(tf_pose), ..Default::default() }.camera_pin().unwrap().unwrap();
        let camera_from_body = from_tf.inverse();
        assert!(close(camera_from_body * Point3::new(0.2, 0.0, 0.1), [0.0, 0.0, 0.0]));
        assert!(close(camera_from_body * Point3::new(5.2, 0.0, 0.1), [0.0, 0.0, 5.0]));
        let t = camera_from_body.translation.vector;
        let q = camera_from_body.rotation.coords;
        let direct = RosConfig { camera_from_body: Some([t.x, t.y, t.z, q.x, q.y, q.z, q.w]), ..Default::default() }
            .camera_pin()
            .unwrap()
            .unwrap();
        assert!((direct.to_homogeneous() - from_tf.to_homogeneous()).norm() < 1e-12);
    }
}
