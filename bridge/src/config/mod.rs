//! The `[ros]` section: topic names, frames, queue sizes and synchronisation, shared by the
//! node (`sgm ros`), the bag replay (`sgm replay`) and the bag writer (`sgm run --bag-out`).
//! `{robot}` in a topic or frame is replaced by the robot's name and `{id}` by its id.
//! Relative topic names resolve in the node's namespace (`__ns`, `ROS_NAMESPACE`).
//!
//! One file per part: [`RosConfig`] and its validation here (what it refuses: `error.rs`,
//! [`RosConfigError`]), `topics.rs` (topic and frame names), `sync.rs` (`[ros.sync]`),
//! `health.rs` (`[ros.health]`), `peers.rs` (`[ros.peers]`), `mounts.rs` (the sensors'
//! mountings pinned here). Sections of modules that need nothing of the bridge stay with them
//! (`[ros.tf]` in [`crate::tf`], `[ros.timeline]` in [`crate::timeline`]). Those of the
//! synchroniser, the health checks and the transport live here: those modules read this one
//! (the whole `[ros]` section, or the synchroniser that does), so this one must not read them.

mod error;
mod health;
mod mounts;
mod peers;
mod sync;
mod topics;

pub use error::RosConfigError;
pub use health::{HealthConfig, HealthConfigError};
pub use peers::PeerConfig;
pub use sync::{SyncConfig, Unlabelled};
pub use topics::{RosFrames, RosTopics};

use crate::tf::TfConfig;
use crate::timeline::TimelineConfig;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RosConfig {
    pub topics: RosTopics,
    pub frames: RosFrames,
    /// Subscriber and publisher queue length, messages. Default 10 (1 s of a 10 Hz LiDAR).
    pub queue_size: usize,
    /// Where the points' classes come from: `image` (project into the label image, paper
    /// §IV-A) or `cloud` (an integer field of the cloud, from an upstream fuser). Default image.
    pub labels: LabelSource,
    /// The cloud's label field when `labels = "cloud"`. Default `label`.
    pub label_field: String,
    /// `camera_from_body` as [x, y, z, qx, qy, qz, qw]: it takes a point of the body frame into
    /// the camera's optical frame (z forward, x right, y down), `p_camera = camera_from_body ·
    /// p_body`. Unset (and `body_from_camera` unset): a camera at the body origin looking along
    /// +x, `[0, 0, 0, 0.5, -0.5, 0.5, 0.5]`.
    pub camera_from_body: Option<[f64; 7]>,
    /// The same mounting the other way round, as tf and a URDF give it: the camera's optical
    /// frame's pose in the body frame, `body_from_camera = camera_from_body⁻¹`. Set one of the
    /// two, not both.
    pub body_from_camera: Option<[f64; 7]>,
    /// The LiDAR's mounting, as tf and a URDF give it: the clouds' frame's pose in the body
    /// frame, `p_body = body_from_lidar · p_lidar`. Unset: tf's transform between
    /// `frames.body` and `frames.lidar` (the identity when they are one frame).
    pub body_from_lidar: Option<[f64; 7]>,
    /// The IMU's mounting, as tf and a URDF give it: the IMU messages' frame's pose in the body
    /// frame. Its rotation turns the rates and specific force into the body's axes, its
    /// translation (the lever arm) takes the centripetal acceleration out of the specific
    /// force. Unset: tf's transform between `frames.body` and `frames.imu` (the identity when
    /// they are one frame). Read only with `odometry.source = "internal"`.
    pub body_from_imu: Option<[f64; 7]>,
    pub sync: SyncConfig,
    /// Publish the odometry's `frames.world` → `frames.body` on `topics.tf` (10 Hz at most), for
    /// robots whose odometry's own tf is remapped away or names frames every robot shares.
    /// Default false (the odometry publishes it).
    pub publish_body_tf: bool,
    /// Markers, path, map, tf and status are published every this many seconds. Default 1.
    pub publish_interval_s: f64,
    /// Voxel of the published semantic map cloud, m. Default 0.25.
    pub map_voxel_m: f64,
    /// Clouds with more points are refused (bounded memory per message). Default 2 000 000.
    pub max_cloud_points: usize,
    /// Label images with more pixels are refused. Default 16 777 216 (4096²).
    pub max_image_pixels: usize,
    /// Any received message longer than this is refused before it is decoded, bytes
    /// (`bounded`). Default 134 217 728 (128 MiB).
    pub max_message_bytes: usize,
    /// Envelopes addressed to one robot: per-peer queues, call timeout, back-off.
    pub peers: PeerConfig,
    /// When a sensor stamp is believed: jumps confirmed before the timeline restarts.
    pub timeline: TimelineConfig,
    /// Health checks: conditions said once in the log and listed in the status.
    pub health: HealthConfig,
    /// tf in: mounts not pinned here are read from it, pinned ones checked against it.
    pub tf: TfConfig,
}

/// Default of `ros.max_message_bytes`: 2 000 000 points of 64 bytes fit.
pub const DEFAULT_MAX_MESSAGE_BYTES: usize = 128 << 20;

impl Default for RosConfig {
    fn default() -> Self {
        Self {
            topics: RosTopics::default(),
            frames: RosFrames::default(),
            queue_size: 10,
            labels: LabelSource::Image,
            label_field: "label".into(),
            camera_from_body: None,
            body_from_camera: None,
            body_from_lidar: None,
            body_from_imu: None,
            sync: SyncConfig::default(),
            publish_body_tf: false,
            publish_interval_s: 1.0,
            map_voxel_m: 0.25,
            max_cloud_points: 2_000_000,
            max_image_pixels: 4096 * 4096,
            max_message_bytes: DEFAULT_MAX_MESSAGE_BYTES,
            peers: PeerConfig::default(),
            timeline: TimelineConfig::default(),
            health: HealthConfig::default(),
            tf: TfConfig::default(),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LabelSource {
    Image,
    Cloud,
}

impl RosConfig {
    /// `template` with `{robot}` and `{id}` filled in.
    pub fn resolve(template: &str, robot: &str, id: u16) -> String {
        template.replace("{robot}", robot).replace("{id}", &id.to_string())
    }

    /// Checks every key; errors name the key.
    pub fn validate(&self) -> Result<(), RosConfigError> {
        let positive = |value: f64, key: &'static str| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(RosConfigError::NotPositive { key, value })
            }
        };
        positive(self.sync.image_tolerance_s, "sync.image_tolerance_s")?;
        positive(self.sync.max_label_skew_s, "sync.max_label_skew_s")?;
        if self.sync.max_label_skew_s < self.sync.image_tolerance_s {
            return Err(RosConfigError::SkewBelowTolerance {
                skew: self.sync.max_label_skew_s,
                tolerance: self.sync.image_tolerance_s,
            });
        }
        positive(self.sync.max_odometry_gap_s, "sync.max_odometry_gap_s")?;
        positive(self.sync.max_wait_s, "sync.max_wait_s")?;
        positive(self.publish_interval_s, "publish_interval_s")?;
        positive(self.map_voxel_m, "map_voxel_m")?;
        positive(self.peers.call_timeout_s, "peers.call_timeout_s")?;
        positive(self.peers.backoff_initial_s, "peers.backoff_initial_s")?;
        positive(self.peers.backoff_max_s, "peers.backoff_max_s")?;
        positive(self.timeline.max_jump_s, "timeline.max_jump_s")?;
        self.health.validate()?;
        self.tf.validate()?;
        if self.timeline.confirm_messages == 0 {
            return Err(RosConfigError::Zero { key: "timeline.confirm_messages" });
        }
        if self.peers.queue == 0 {
            return Err(RosConfigError::Zero { key: "peers.queue" });
        }
        if self.peers.backoff_max_s < self.peers.backoff_initial_s {
            return Err(RosConfigError::BackoffBelowInitial {
                max: self.peers.backoff_max_s,
                initial: self.peers.backoff_initial_s,
            });
        }
        if self.queue_size == 0 || self.max_cloud_points == 0 || self.max_image_pixels == 0 {
            return Err(RosConfigError::NoRoom);
        }
        if self.max_message_bytes < 1024 {
            return Err(RosConfigError::MessageBytes(self.max_message_bytes));
        }
        let t = &self.topics;
        for (key, name) in [
            ("topics.points", &t.points),
            ("topics.labels", &t.labels),
            ("topics.camera_info", &t.camera_info),
            ("topics.odometry", &t.odometry),
            ("topics.imu", &t.imu),
            ("topics.odometry_out", &t.odometry_out),
            ("topics.markers", &t.markers),
            ("topics.path", &t.path),
            ("topics.map", &t.map),
            ("topics.status", &t.status),
            ("topics.tf", &t.tf),
            ("topics.team", &t.team),
            ("topics.clock", &t.clock),
            ("topics.deliver", &t.deliver),
            ("tf.topic", &self.tf.topic),
            ("tf.static_topic", &self.tf.static_topic),
        ] {
            let bad = name.is_empty()
                || !name.chars().all(|c| c.is_ascii_alphanumeric() || "_/{}~".contains(c))
                || name.contains("//");
            if bad {
                return Err(RosConfigError::Name { key, name: name.clone() });
            }
        }
        if !t.deliver.contains("{id}") {
            return Err(RosConfigError::DeliverWithoutId);
        }
        for (from, to) in &self.frames.aliases {
            if from.trim_start_matches('/').is_empty() || to.trim_start_matches('/').is_empty() {
                return Err(RosConfigError::EmptyAlias { from: from.clone(), to: to.clone() });
            }
        }
        self.camera_pin()?;
        self.imu_pin()?;
        self.lidar_pin().map(|_| ())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_mountings_or_a_bad_quaternion_are_refused_by_name() {
        let both = RosConfig {
            camera_from_body: Some([0.0, 0.0, 0.0, 0.5, -0.5, 0.5, 0.5]),
            body_from_camera: Some([0.0, 0.0, 0.0, -0.5, 0.5, -0.5, 0.5]),
            ..Default::default()
        };
        let e = both.validate().unwrap_err().to_string();
        assert!(e.contains("ros.camera_from_body") && e.contains("ros.body_from_camera"), "{e}");
        let bad = RosConfig { body_from_camera: Some([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0]), ..Default::default() };
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("ros.body_from_camera") && e.contains("norm"), "{e}");
        let bad = RosConfig { body_from_lidar: Some([0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0, 1.0]), ..Default::default() };
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("ros.body_from_lidar") && e.contains("non-finite"), "{e}");
        let mut bad = RosConfig::default();
        bad.frames.aliases.insert("camera_init".into(), "".into());
        assert!(bad.validate().unwrap_err().to_string().contains("ros.frames.aliases"));
        let bad = RosConfig {
            tf: crate::tf::TfConfig { topic: "/tf two".into(), ..Default::default() },
            ..Default::default()
        };
        assert_eq!(bad.validate().unwrap_err().to_string(), "ros.tf.topic = \"/tf two\": not a valid ROS name");
    }

    /// A configuration with one key changed by `edit`, refused: the message.
    fn refused(edit: impl FnOnce(&mut RosConfig)) -> String {
        let mut config = RosConfig::default();
        edit(&mut config);
        config.validate().map(|()| "accepted".to_string()).unwrap_or_else(|e| e.to_string())
    }

    /// Each error names the key and its value (the same texts as the strings before).
    #[test]
    fn errors_name_the_key_and_the_value() {
        assert_eq!(refused(|_| ()), "accepted");
        assert_eq!(refused(|c| c.map_voxel_m = 0.0), "ros.map_voxel_m = 0: finite and > 0 expected");
        assert_eq!(
            refused(|c| c.sync.max_label_skew_s = 0.01),
            "ros.sync.max_label_skew_s = 0.01 is below ros.sync.image_tolerance_s = 0.05: at least that expected"
        );
        assert_eq!(refused(|c| c.health.window_frames = 0), "ros.health.window_frames = 0: at least 1 expected");
        assert_eq!(
            refused(|c| c.tf.max_mount_disagreement_m = -1.0),
            "ros.tf.max_mount_disagreement_m = -1: finite and > 0 expected"
        );
        assert_eq!(refused(|c| c.peers.queue = 0), "ros.peers.queue = 0: ≥ 1 expected");
        assert_eq!(
            refused(|c| c.peers.backoff_max_s = 0.5),
            "ros.peers.backoff_max_s = 0.5: ≥ backoff_initial_s (1) expected"
        );
        assert_eq!(refused(|c| c.max_message_bytes = 10), "ros.max_message_bytes = 10: ≥ 1024 expected");
        assert_eq!(refused(|c| c.topics.points = "".into()), "ros.topics.points = \"\": not a valid ROS name");
        assert_eq!(
            refused(|c| c.topics.deliver = "/sgm/deliver".into()),
            "ros.topics.deliver must contain {id}: one service per robot"
        );
    }
}
