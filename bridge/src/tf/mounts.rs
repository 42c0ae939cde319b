//! Where a sensor sits on the body: `body_from_sensor` (p_body = body_from_sensor · p_sensor),
//! pinned by configuration or read from tf between the body frame and the frame the sensor's
//! messages carry. When both exist, tf is compared with the pin, which is kept: a disagreement
//! beyond tolerance is a finding, said once, naming the key and the frames.
//!
//! A sensor whose frame is the body frame needs no tf (the identity). Otherwise, with no pin,
//! the mount is unknown until tf connects the two frames; the error names the frames and what
//! tf holds.

use super::tree::{frame_name, TfError, TfTree};
use serde::Serialize;
use sgm_model::geometry::Pose3;

/// Where a mount's value came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum MountSource {
    /// A configuration key pins it.
    Config,
    /// Looked up in tf.
    Tf,
    /// The sensor's frame is the body frame.
    SameFrame,
    /// Not known yet: no pin, and tf does not connect the frames.
    Missing,
}

/// tf's value against the pinned one.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Disagreement {
    pub translation_m: f64,
    pub rotation_deg: f64,
}

impl Disagreement {
    pub fn between(a: &Pose3, b: &Pose3) -> Self {
        let d = a.inverse() * b;
        Self { translation_m: d.translation.vector.norm(), rotation_deg: d.rotation.angle().to_degrees() }
    }

    pub fn exceeds(&self, max_m: f64, max_deg: f64) -> bool {
        self.translation_m > max_m || self.rotation_deg > max_deg
    }
}

/// One sensor's mounting.
#[derive(Clone, Debug)]
pub struct Mount {
    /// `camera` or `lidar`.
    pub sensor: &'static str,
    /// The configuration key that pins it (`ros.body_from_camera`, `ros.body_from_lidar`).
    pub key: &'static str,
    body_frame: String,
    sensor_frame: String,
    pinned: Option<Pose3>,
    /// tf's latest answer (an error while tf cannot give one).
    from_tf: Result<Pose3, TfError>,
}

/// A mount for the status and reports.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MountStatus {
    pub sensor: &'static str,
    /// The key that would pin it.
    pub key: &'static str,
    /// `body ← sensor` frames.
    pub body_frame: String,
    pub sensor_frame: String,
    pub source: MountSource,
    /// `body_from_sensor` as [x, y, z, qx, qy, qz, qw], when known.
    pub body_from_sensor: Option<[f64; 7]>,
    /// Why tf gives no value (when it matters: no pin and not the same frame).
    pub tf_error: Option<String>,
    /// tf against the pin, when both exist.
    pub disagreement: Option<Disagreement>,
}

pub fn pose_values(pose: &Pose3) -> [f64; 7] {
    let (t, q) = (pose.translation.vector, pose.rotation.quaternion());
    [t.x, t.y, t.z, q.i, q.j, q.k, q.w]
}

impl Mount {
    pub fn new(
        sensor: &'static str,
        key: &'static str,
        body_frame: &str,
        sensor_frame: &str,
        pinned: Option<Pose3>,
    ) -> Self {
        let (body_frame, sensor_frame) = (frame_name(body_frame).to_string(), frame_name(sensor_frame).to_string());
        let from_tf = Err(TfError::Unknown { frame: sensor_frame.clone(), known: "tf holds no frame yet".into() });
        Self { sensor, key, body_frame, sensor_frame, pinned, from_tf }
    }

    fn same_frame(&self) -> bool {
        self.body_frame == self.sensor_frame
    }

    /// Looks the mount up again in `tree`.
    pub fn update(&mut self, tree: &TfTree) {
        if !self.same_frame() {
            self.from_tf = tree.lookup(&self.body_frame, &self.sensor_frame);
        }
    }

    pub fn source(&self) -> MountSource {
        if self.pinned.is_some() {
            MountSource::Config
        } else if self.same_frame() {
            MountSource::SameFrame
        } else if self.from_tf.is_ok() {
            MountSource::Tf
        } else {
            MountSource::Missing
        }
    }

    /// `body_from_sensor`: the pin, else the identity for the body's own frame, else tf's.
    pub fn body_from_sensor(&self) -> Option<Pose3> {
        match self.source() {
            MountSource::Config => self.pinned,
            MountSource::SameFrame => Some(Pose3::identity()),
            MountSource::Tf => self.from_tf.as_ref().ok().copied(),
            MountSource::Missing => None,
        }
    }

    /// Why the mount is unknown, naming the frames and the fix.
    pub fn missing_reason(&self) -> Option<String> {
        match (&self.from_tf, self.source()) {
            (Err(e), MountSource::Missing) => Some(format!(
                "the {} mount `{}` ← `{}` is unknown: {e}; publish it on tf (/tf_static) or pin {}",
                self.sensor, self.body_frame, self.sensor_frame, self.key
            )),
            _ => None,
        }
    }

    /// tf against the pin, when both exist.
    pub fn disagreement(&self) -> Option<Disagreement> {
        match (&self.pinned, &self.from_tf) {
            (Some(pinned), Ok(tf)) if !self.same_frame() => Some(Disagreement::between(pinned, tf)),
            _ => None,
        }
    }

    pub fn frames(&self) -> (&str, &str) {
        (&self.body_frame, &self.sensor_frame)
    }

    pub fn status(&self) -> MountStatus {
        let source = self.source();
        MountStatus {
            sensor: self.sensor,
            key: self.key,
            body_frame: self.body_frame.clone(),
            sensor_frame: self.sensor_frame.clone(),
            source,
            body_from_sensor: self.body_from_sensor().as_ref().map(pose_values),
            tf_error: match (&self.from_tf, source) {
                (Err(e), MountSource::Missing | MountSource::Config) if !self.same_frame() => Some(e.to_string()),
                _ => None,
            },
            disagreement: self.disagreement(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use sgm_model::geometry::pose_from_rpy_translation;

    fn offset(x: f64) -> Pose3 {
        pose_from_rpy_translation(0.0, 0.0, 0.0, Vector3::new(x, 0.0, 0.0))
    }

    #[test]
    fn a_mount_comes_from_the_pin_the_body_frame_or_tf() {
        let mut tree = TfTree::new();
        let mut camera = Mount::new("camera", "ros.body_from_camera", "base_link", "camera_optical", None);
        camera.update(&tree);
        assert_eq!(camera.source(), MountSource::Missing);
        let reason = camera.missing_reason().unwrap();
        assert_eq!(
            reason,
            "the camera mount `base_link` ← `camera_optical` is unknown: no frame `base_link` in tf (tf holds no \
             frame yet); publish it on tf (/tf_static) or pin ros.body_from_camera"
        );
        tree.insert("base_link", "camera_optical", offset(0.2), true).unwrap();
        camera.update(&tree);
        assert_eq!(camera.source(), MountSource::Tf);
        assert_eq!(camera.body_from_sensor(), Some(offset(0.2)));
        assert_eq!(camera.status().body_from_sensor, Some([0.2, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]));

        let lidar = Mount::new("lidar", "ros.body_from_lidar", "/base_link", "base_link", None);
        assert_eq!((lidar.source(), lidar.body_from_sensor()), (MountSource::SameFrame, Some(Pose3::identity())));
    }

    /// A pin that tf contradicts by 5 cm is kept, and the disagreement is measured.
    #[test]
    fn a_pin_is_checked_against_tf() {
        let mut tree = TfTree::new();
        tree.insert("base_link", "camera_optical", offset(0.25), true).unwrap();
        let mut camera = Mount::new("camera", "ros.body_from_camera", "base_link", "camera_optical", Some(offset(0.2)));
        assert_eq!(camera.disagreement(), None, "tf not looked up yet");
        camera.update(&tree);
        assert_eq!(camera.body_from_sensor(), Some(offset(0.2)));
        let d = camera.disagreement().unwrap();
        assert!((d.translation_m - 0.05).abs() < 1e-12 && d.rotation_deg == 0.0, "{d:?}");
        assert!(d.exceeds(0.02, 1.0) && !d.exceeds(0.1, 1.0));
        assert_eq!(camera.status().source, MountSource::Config);
    }
}
