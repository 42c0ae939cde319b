//! What a robot keeps of tf: the tree, the camera's and the LiDAR's mounts (and the IMU's, for
//! the internal odometry) resolved from it,
//! what was refused, and tf's own view of the odometry (the transform between the configured
//! world and body frames, when something publishes it) for the synchroniser to compare with
//! the odometry topic. Plain state fed by the synchroniser; nothing here reads a clock.

use super::mounts::{Disagreement, Mount, MountSource, MountStatus};
use super::tree::{frame_name, TfTree};
use super::{TfBatch, TfConfig};
use serde::Serialize;
use sgm_model::geometry::Pose3;
use sgm_model::scene_graph::Stamp;
use std::collections::{BTreeSet, VecDeque};

/// At most this many of tf's world → body samples wait for the odometry to catch up.
const MAX_ODOMETRY_SAMPLES: usize = 256;
/// At most this many distinct refusal reasons are remembered (each logged once).
const MAX_SAID: usize = 64;

/// Counts for the status.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TfCounts {
    /// Transforms taken into the tree.
    pub transforms: u64,
    /// Transforms refused (bad values, cycles, duplicate frames, too many frames).
    pub refused: u64,
    /// The latest refusal's reason, naming its frames.
    pub last_refusal: Option<String>,
    /// tf's world → body samples compared with the odometry topic's pose at their stamp.
    pub odometry_compared: u64,
    /// Of those, farther apart than `ros.tf.max_odometry_disagreement_*`.
    pub odometry_disagreed: u64,
    /// The largest difference seen, m and degrees.
    pub odometry_max_m: f64,
    pub odometry_max_deg: f64,
}

/// The status's `tf` object.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TfStatus {
    #[serde(flatten)]
    pub counts: TfCounts,
    /// The odometry's frames, whose transform on tf is compared with the odometry topic.
    pub world_frame: String,
    pub body_frame: String,
    pub mounts: Vec<MountStatus>,
    /// Mounts pinned by configuration that tf contradicts beyond tolerance.
    pub mounts_disagreeing: Vec<&'static str>,
}

#[derive(Clone, Debug)]
pub struct TfListener {
    config: TfConfig,
    tree: TfTree,
    camera: Mount,
    lidar: Mount,
    /// Only when the robot runs its own odometry on the IMU.
    imu: Option<Mount>,
    world_frame: String,
    body_frame: String,
    pub counts: TfCounts,
    said: BTreeSet<String>,
    /// tf's `world_from_body` samples not yet compared (mission time).
    odometry_samples: VecDeque<(Stamp, Pose3)>,
}

impl TfListener {
    pub fn new(config: TfConfig, world_frame: &str, body_frame: &str, camera: Mount, lidar: Mount) -> Self {
        Self {
            config,
            tree: TfTree::new(),
            camera,
            lidar,
            imu: None,
            world_frame: frame_name(world_frame).into(),
            body_frame: frame_name(body_frame).into(),
            counts: TfCounts::default(),
            said: BTreeSet::new(),
            odometry_samples: VecDeque::new(),
        }
    }

    /// The camera pinned at `camera_from_body` and the clouds in the body frame; tf unused.
    pub fn pinned(camera_from_body: Pose3) -> Self {
        let config = TfConfig { listen: false, ..TfConfig::default() };
        let camera = Mount::new("camera", "ros.body_from_camera", "body", "camera", Some(camera_from_body.inverse()));
        let lidar = Mount::new("lidar", "ros.body_from_lidar", "body", "body", None);
        Self::new(config, "world", "body", camera, lidar)
    }

    /// Also resolves the IMU's mount (the internal odometry's input).
    pub fn with_imu(mut self, imu: Mount) -> Self {
        self.imu = Some(imu);
        self.resolve();
        self
    }

    fn mounts(&self) -> impl Iterator<Item = &Mount> {
        [&self.lidar, &self.camera].into_iter().chain(self.imu.as_ref())
    }

    fn say_once(&mut self, reason: &str) {
        if self.said.len() < MAX_SAID && self.said.insert(reason.to_string()) {
            tracing::warn!("transform refused: {reason}");
        }
    }

    /// Takes a TFMessage's transforms into the tree (`stamp` maps their stamps into mission
    /// time), resolves the mounts again if anything changed, and keeps tf's world → body.
    pub fn feed(&mut self, batch: TfBatch, stamp: impl Fn(rosrust::Time) -> Stamp) {
        for reason in &batch.refused {
            self.counts.refused += 1;
            self.counts.last_refusal = Some(reason.clone());
            self.say_once(reason);
        }
        let mut changed = false;
        for t in batch.transforms {
            if frame_name(&t.parent) == self.world_frame && frame_name(&t.child) == self.body_frame {
                if self.odometry_samples.len() == MAX_ODOMETRY_SAMPLES {
                    self.odometry_samples.pop_front();
                }
                self.odometry_samples.push_back((stamp(t.stamp), t.parent_from_child));
            }
            match self.tree.insert(&t.parent, &t.child, t.parent_from_child, batch.is_static) {
                Ok(c) => {
                    self.counts.transforms += 1;
                    changed |= c;
                }
                Err(e) => {
                    let reason = e.to_string();
                    self.counts.refused += 1;
                    self.counts.last_refusal = Some(reason.clone());
                    self.say_once(&reason);
                }
            }
        }
        if changed {
            self.resolve();
        }
    }

    fn resolve(&mut self) {
        let (max_m, max_deg) = (self.config.max_mount_disagreement_m, self.config.max_mount_disagreement_deg);
        for mount in [&mut self.camera, &mut self.lidar].into_iter().chain(self.imu.as_mut()) {
            let before = (mount.source(), mount.body_from_sensor());
            mount.update(&self.tree);
            let (body, sensor) = mount.frames();
            if mount.source() == MountSource::Tf && before.0 != MountSource::Tf {
                tracing::info!(sensor = mount.sensor, body, frame = sensor,
                    body_from_sensor = ?super::mounts::pose_values(&mount.body_from_sensor().unwrap_or_default()),
                    "mount read from tf");
            } else if mount.source() == MountSource::Tf && before.1 != mount.body_from_sensor() {
                tracing::info!(sensor = mount.sensor, body, frame = sensor, "mount changed in tf");
            }
            if let Some(d) = mount.disagreement().filter(|d| d.exceeds(max_m, max_deg)) {
                let key = format!("{} disagrees", mount.key);
                if self.said.len() < MAX_SAID && self.said.insert(key) {
                    tracing::warn!(
                        "{} disagrees with tf's `{body}` → `{sensor}` by {:.3} m and {:.2}°: the configured value is used; \
                         correct one of the two (or remove the key to take tf's)",
                        mount.key, d.translation_m, d.rotation_deg);
                }
            }
        }
    }

    /// `camera_from_body`, once known.
    pub fn camera_from_body(&self) -> Option<Pose3> {
        self.camera.body_from_sensor().map(|p| p.inverse())
    }

    /// `body_from_lidar`, once known.
    pub fn body_from_lidar(&self) -> Option<Pose3> {
        self.lidar.body_from_sensor()
    }

    /// `body_from_imu`, once known (`None` as well when no IMU mount is kept).
    pub fn body_from_imu(&self) -> Option<Pose3> {
        self.imu.as_ref().and_then(Mount::body_from_sensor)
    }

    /// Why a mount the frames need is unknown (the camera's only when `camera` is needed).
    pub fn missing(&self, camera: bool) -> Option<String> {
        self.lidar.missing_reason().or_else(|| self.imu.as_ref().and_then(Mount::missing_reason)).or_else(|| {
            if camera {
                self.camera.missing_reason()
            } else {
                None
            }
        })
    }

    /// tf's world → body samples stamped at or before `t`, oldest first (taken out).
    pub fn odometry_samples_until(&mut self, t: Stamp) -> Vec<(Stamp, Pose3)> {
        let n = self.odometry_samples.partition_point(|(s, _)| *s <= t);
        self.odometry_samples.drain(..n).collect()
    }

    /// Counts one comparison of tf's world → body with the odometry topic's pose; the first
    /// disagreement beyond tolerance is logged, naming the frames.
    pub fn compared(&mut self, tf: &Pose3, odometry: &Pose3) {
        let d = Disagreement::between(tf, odometry);
        let c = &mut self.counts;
        c.odometry_compared += 1;
        c.odometry_max_m = c.odometry_max_m.max(d.translation_m);
        c.odometry_max_deg = c.odometry_max_deg.max(d.rotation_deg);
        if d.exceeds(self.config.max_odometry_disagreement_m, self.config.max_odometry_disagreement_deg) {
            c.odometry_disagreed += 1;
        }
    }

    pub fn frames(&self) -> (&str, &str) {
        (&self.world_frame, &self.body_frame)
    }

    pub fn config(&self) -> &TfConfig {
        &self.config
    }

    pub fn status(&self) -> TfStatus {
        let (max_m, max_deg) = (self.config.max_mount_disagreement_m, self.config.max_mount_disagreement_deg);
        TfStatus {
            counts: self.counts.clone(),
            world_frame: self.world_frame.clone(),
            body_frame: self.body_frame.clone(),
            mounts: self.mounts().map(Mount::status).collect(),
            mounts_disagreeing: self
                .mounts()
                .filter(|m| m.disagreement().is_some_and(|d| d.exceeds(max_m, max_deg)))
                .map(|m| m.key)
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tf::TfTransform;
    use nalgebra::Vector3;
    use sgm_model::geometry::pose_from_rpy_translation;

    fn offset(x: f64) -> Pose3 {
        pose_from_rpy_translation(0.0, 0.0, 0.0, Vector3::new(x, 0.0, 0.0))
    }

    fn transform(parent: &str, child: &str, pose: Pose3, sec: u32) -> TfTransform {
        TfTransform {
            stamp: rosrust::Time { sec, nsec: 0 },
            parent: parent.into(),
            child: child.into(),
            parent_from_child: pose,
        }
    }

    fn listener(camera_pin: Option<Pose3>) -> TfListener {
        TfListener::new(
            TfConfig::default(),
            "odom",
            "base_link",
            Mount::new("camera", "ros.body_from_camera", "base_link", "camera_optical", camera_pin),
            Mount::new("lidar", "ros.body_from_lidar", "base_link", "velodyne", None),
        )
    }

    /// robot_state_publisher's static mounts resolve both sensors through a chain
    /// (base_link → camera_link → camera_optical); refusals are counted by name, and tf's
    /// odom → base_link is kept for the odometry check.
    #[test]
    fn mounts_resolve_through_chains_and_refusals_are_counted() {
        let mut tf = listener(None);
        assert!(tf.missing(true).unwrap().contains("lidar mount `base_link` ← `velodyne` is unknown"));
        tf.feed(
            TfBatch {
                is_static: true,
                transforms: vec![
                    transform("base_link", "velodyne", offset(0.3), 0),
                    transform("base_link", "camera_link", offset(0.1), 0),
                    transform("camera_link", "camera_optical", offset(0.05), 0),
                    transform("camera_optical", "base_link", offset(0.0), 0),
                ],
                refused: vec!["`a` → `b`: orientation quaternion has norm 0.000000, 1 expected".into()],
            },
            |_| 0.0,
        );
        assert_eq!(tf.missing(true), None);
        assert_eq!(tf.body_from_lidar(), Some(offset(0.3)));
        let c = tf.camera_from_body().unwrap().inverse();
        assert!((c.translation.vector.x - 0.15).abs() < 1e-12);
        assert_eq!((tf.counts.transforms, tf.counts.refused), (3, 2));
        assert!(tf.counts.last_refusal.as_deref().unwrap().contains("would close a cycle"));
        tf.feed(
            TfBatch {
                is_static: false,
                transforms: vec![transform("/odom", "base_link", offset(2.0), 7)],
                refused: vec![],
            },
            |t| f64::from(t.sec) - 5.0,
        );
        assert_eq!(tf.odometry_samples_until(1.0), vec![]);
        assert_eq!(tf.odometry_samples_until(2.0), vec![(2.0, offset(2.0))]);
        assert_eq!(tf.status().mounts.iter().map(|m| m.source).collect::<Vec<_>>(), [MountSource::Tf; 2]);
    }

    #[test]
    fn a_contradicted_pin_is_listed() {
        let mut tf = listener(Some(offset(0.2)));
        tf.feed(
            TfBatch {
                is_static: true,
                transforms: vec![transform("base_link", "camera_optical", offset(0.3), 0)],
                refused: vec![],
            },
            |_| 0.0,
        );
        assert_eq!(tf.camera_from_body(), Some(offset(0.2).inverse()), "the pin is kept");
        assert_eq!(tf.status().mounts_disagreeing, vec!["ros.body_from_camera"]);
        tf.compared(&offset(1.0), &offset(1.01));
        tf.compared(&offset(1.0), &offset(1.5));
        assert_eq!((tf.counts.odometry_compared, tf.counts.odometry_disagreed), (2, 1));
        assert!((tf.counts.odometry_max_m - 0.5).abs() < 1e-12);
    }
}
