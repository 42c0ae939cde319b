//! Semantic fusion's projection (paper §IV-A): LiDAR points into the segmented camera image
//! through `camera_from_lidar` and a pinhole camera with ROS `plumb_bob` distortion; each point
//! takes the class of the nearest pixel. Points behind the camera or outside the image get none.
//!
//! plumb_bob (ROS `sensor_msgs/CameraInfo`, OpenCV's 5-parameter model), with x = X/Z, y = Y/Z,
//! r² = x² + y²:
//!   x_d = x (1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2 x²)
//!   y_d = y (1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2 y²) + 2 p2 x y
//!   u = fx x_d + cx,  v = fy y_d + cy.

use crate::geometry::Pose3;
use crate::scene_graph::LabelId;
use nalgebra::Point3;
use serde::{Deserialize, Serialize};

/// `camera_from_body` of a camera at the body origin looking along the body's +x (x forward,
/// y left, z up) with the ROS optical-frame convention (z forward, x right, y down). The
/// simulator's camera and the bridge's default extrinsic.
pub fn optical_from_forward_body() -> Pose3 {
    let r = nalgebra::Matrix3::new(0.0, -1.0, 0.0, 0.0, 0.0, -1.0, 1.0, 0.0, 0.0);
    Pose3::from_parts(
        nalgebra::Translation3::identity(),
        nalgebra::UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(r)),
    )
}

/// Intrinsics and distortion of a camera (as in `sensor_msgs/CameraInfo`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraModel {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// plumb_bob (k1, k2, p1, p2, k3); zeros for an ideal pinhole.
    pub distortion: [f64; 5],
}

/// A segmented image: one class id per pixel (mono8 or mono16), row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelImage {
    pub width: u32,
    pub height: u32,
    pub labels: Vec<u16>,
}

/// Why a label image cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ImageError {
    #[error("label image has {got} pixels, {width} × {height} = {expected} expected")]
    Size { width: u32, height: u32, expected: usize, got: usize },
    #[error("label image is {image_width} × {image_height} but the camera is {camera_width} × {camera_height}")]
    Mismatch { image_width: u32, image_height: u32, camera_width: u32, camera_height: u32 },
}

impl LabelImage {
    pub fn new(width: u32, height: u32, labels: Vec<u16>) -> Result<Self, ImageError> {
        let expected = width as usize * height as usize;
        if labels.len() != expected {
            return Err(ImageError::Size { width, height, expected, got: labels.len() });
        }
        Ok(Self { width, height, labels })
    }

    /// From mono8 or mono16 (little-endian) bytes.
    pub fn from_bytes(width: u32, height: u32, bytes: &[u8], sixteen_bit: bool) -> Result<Self, ImageError> {
        let labels = if sixteen_bit {
            bytes.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])).collect()
        } else {
            bytes.iter().map(|&b| b as u16).collect()
        };
        Self::new(width, height, labels)
    }
}

impl CameraModel {
    /// Pixel (u, v) of a point in the camera frame (z forward); `None` behind the camera.
    pub fn project(&self, p: &Point3<f64>) -> Option<(f64, f64)> {
        if !p.z.is_finite() || p.z <= 1e-9 || !p.x.is_finite() || !p.y.is_finite() {
            return None;
        }
        let (x, y) = (p.x / p.z, p.y / p.z);
        let [k1, k2, p1, p2, k3] = self.distortion;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        let xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
        let yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
        Some((self.fx * xd + self.cx, self.fy * yd + self.cy))
    }

    /// Nearest pixel index of a projection, if inside the image.
    pub fn pixel(&self, (u, v): (f64, f64)) -> Option<(u32, u32)> {
        let (col, row) = (u.round(), v.round());
        (col >= 0.0 && row >= 0.0 && col < self.width as f64 && row < self.height as f64)
            .then_some((col as u32, row as u32))
    }
}

/// The class of every LiDAR point: the label of its nearest pixel, `None` where it does not
/// project into the image.
pub fn label_points(
    points_in_lidar: &[Point3<f64>],
    camera_from_lidar: &Pose3,
    camera: &CameraModel,
    image: &LabelImage,
) -> Result<Vec<Option<LabelId>>, ImageError> {
    if image.width != camera.width || image.height != camera.height {
        return Err(ImageError::Mismatch {
            image_width: image.width,
            image_height: image.height,
            camera_width: camera.width,
            camera_height: camera.height,
        });
    }
    Ok(points_in_lidar
        .iter()
        .map(|p| {
            let (col, row) = camera.pixel(camera.project(&(camera_from_lidar * p))?)?;
            Some(LabelId(image.labels[row as usize * image.width as usize + col as usize]))
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn camera(distortion: [f64; 5]) -> CameraModel {
        CameraModel { width: 640, height: 480, fx: 500.0, fy: 400.0, cx: 320.0, cy: 240.0, distortion }
    }

    #[test]
    fn pinhole_pixels_by_hand() {
        let c = camera([0.0; 5]);
        // (1, -0.5, 4): x = 0.25, y = -0.125 → u = 500·0.25 + 320 = 445, v = 400·(-0.125) + 240 = 190.
        assert_eq!(c.project(&Point3::new(1.0, -0.5, 4.0)), Some((445.0, 190.0)));
        assert_eq!(c.project(&Point3::new(1.0, 0.0, -1.0)), None);
        assert_eq!(c.pixel((639.4, 479.4)), Some((639, 479)));
        assert_eq!(c.pixel((639.6, 10.0)), None);
    }

    #[test]
    fn plumb_bob_by_hand() {
        // x = 0.2, y = 0.1, r² = 0.05; radial = 1 + 0.1·0.05 + 0.01·0.0025 + 0.001·0.000125.
        let c = camera([0.1, 0.01, 0.002, -0.003, 0.001]);
        let radial = 1.0 + 0.1 * 0.05 + 0.01 * 0.0025 + 0.001 * 0.000125;
        let xd = 0.2 * radial + 2.0 * 0.002 * 0.02 - 0.003 * (0.05 + 0.08);
        let yd = 0.1 * radial + 0.002 * (0.05 + 0.02) + 2.0 * -0.003 * 0.02;
        let (u, v) = c.project(&Point3::new(0.4, 0.2, 2.0)).unwrap();
        assert!((u - (500.0 * xd + 320.0)).abs() < 1e-12 && (v - (400.0 * yd + 240.0)).abs() < 1e-12);
    }

    #[test]
    fn lidar_points_take_the_label_of_their_pixel() {
        // Camera looking along the LiDAR's x axis: camera z = lidar x, camera x = −lidar y,
        // camera y = −lidar z.
        let r = nalgebra::Matrix3::new(0.0, -1.0, 0.0, 0.0, 0.0, -1.0, 1.0, 0.0, 0.0);
        let rotation = nalgebra::UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(r));
        let camera_from_lidar = Pose3::from_parts(nalgebra::Translation3::from(Vector3::zeros()), rotation);
        let c = camera([0.0; 5]);
        let mut labels = vec![0u16; 640 * 480];
        labels[240 * 640 + 320] = 7; // the principal point
        labels[190 * 640 + 445] = 3;
        let image = LabelImage::new(640, 480, labels).unwrap();
        let points = [Point3::new(5.0, 0.0, 0.0), Point3::new(4.0, -1.0, 0.5), Point3::new(-5.0, 0.0, 0.0)];
        let got = label_points(&points, &camera_from_lidar, &c, &image).unwrap();
        assert_eq!(got, vec![Some(LabelId(7)), Some(LabelId(3)), None]);
        assert!(matches!(LabelImage::new(2, 2, vec![0; 3]), Err(ImageError::Size { .. })));
        let small = LabelImage::from_bytes(2, 1, &[1, 0, 2, 0], true).unwrap();
        assert_eq!(small.labels, vec![1, 2]);
        assert!(matches!(label_points(&points, &camera_from_lidar, &c, &small), Err(ImageError::Mismatch { .. })));
    }
}
