//! The `[ros]` section: topic names, frames, queue sizes and synchronisation, shared by the
//! node (`sgm ros`), the bag replay (`sgm replay`) and the bag writer (`sgm run --bag-out`).
//! `{robot}` in a topic or frame is replaced by the robot's name and `{id}` by its id.
//! Relative topic names resolve in the node's namespace (`__ns`, `ROS_NAMESPACE`).

use crate::error::InputError;
use crate::health::HealthConfig;
use crate::tf::TfConfig;
use crate::timeline::TimelineConfig;
use crate::transport::peer::PeerConfig;
use serde::{Deserialize, Serialize};
use sgm_model::geometry::Pose3;
use std::collections::BTreeMap;

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

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RosTopics {
    /// sensor_msgs/PointCloud2 in. Default `points`.
    pub points: String,
    /// sensor_msgs/Image (mono8/mono16 class ids) in. Default `labels`.
    pub labels: String,
    /// sensor_msgs/CameraInfo in. Default `camera_info`.
    pub camera_info: String,
    /// nav_msgs/Odometry in. Default `odometry`.
    pub odometry: String,
    /// nav_msgs/Odometry of the true pose, in bags written from scenarios (replay's ATE).
    /// Default `ground_truth`.
    pub ground_truth: String,
    /// visualization_msgs/MarkerArray out. Default `sgm/markers`.
    pub markers: String,
    /// nav_msgs/Path out. Default `sgm/path`.
    pub path: String,
    /// sensor_msgs/PointCloud2 semantic map out. Default `sgm/map`.
    pub map: String,
    /// std_msgs/String (JSON) status out. Default `sgm/status`.
    pub status: String,
    /// tf2_msgs/TFMessage out. Default `/tf`.
    pub tf: String,
    /// sgm_msgs/Envelope broadcasts between robots (object data). Default `/sgm/team`.
    pub team: String,
    /// rosgraph_msgs/Clock in, followed only when the parameter `/use_sim_time` is true.
    /// Default `/clock`.
    pub clock: String,
    /// sgm_msgs/Deliver service of each robot (requests and replies addressed to it).
    /// Default `/sgm/robot_{id}/deliver`.
    pub deliver: String,
}

impl Default for RosTopics {
    fn default() -> Self {
        Self {
            points: "points".into(),
            labels: "labels".into(),
            camera_info: "camera_info".into(),
            odometry: "odometry".into(),
            ground_truth: "ground_truth".into(),
            markers: "sgm/markers".into(),
            path: "sgm/path".into(),
            map: "sgm/map".into(),
            status: "sgm/status".into(),
            tf: "/tf".into(),
            team: "/sgm/team".into(),
            clock: "/clock".into(),
            deliver: "/sgm/robot_{id}/deliver".into(),
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RosFrames {
    /// The robot's world (odometry) frame: odometry's `header.frame_id`, and the frame of
    /// everything published. Default `{robot}/odom`.
    pub world: String,
    /// The body frame: odometry's `child_frame_id`. Default `{robot}/base_link`.
    pub body: String,
    /// The clouds' frame (points are taken as in the body frame). Default `{robot}/base_link`.
    pub lidar: String,
    /// The label image's and camera info's frame. Default `{robot}/camera`.
    pub camera: String,
    /// Frame ids renamed as they come in (messages' headers and tf), before any check: input
    /// name → SGM's name (`{robot}` and `{id}` allowed). For odometry with hard-coded frames on a
    /// one-master fleet: `camera_init = "{robot}/odom"`, `body = "{robot}/base_link"`. The keys
    /// above name frames after renaming. Default none.
    pub aliases: BTreeMap<String, String>,
}

impl Default for RosFrames {
    fn default() -> Self {
        Self {
            world: "{robot}/odom".into(),
            body: "{robot}/base_link".into(),
            lidar: "{robot}/base_link".into(),
            camera: "{robot}/camera".into(),
            aliases: BTreeMap::new(),
        }
    }
}

/// How clouds meet their odometry and label image.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SyncConfig {
    /// A label image within this of the cloud's stamp labels it as it is, s. Default 0.05.
    pub image_tolerance_s: f64,
    /// A label image farther than `image_tolerance_s` but within this of the cloud labels it
    /// with the body's motion in between compensated (the odometry at both stamps), s: a
    /// segmenter slower than the LiDAR is normal. Default 0.5.
    pub max_label_skew_s: f64,
    /// What becomes of a cloud with no label image within `max_label_skew_s`: `keep` (default:
    /// assembled without labels, so it still feeds keyframes and the map's geometry) or `drop`.
    pub unlabelled: Unlabelled,
    /// The odometry poses bracketing a cloud may be at most this far apart to interpolate, s.
    /// Default 0.5.
    pub max_odometry_gap_s: f64,
    /// A cloud still missing its odometry or image when the streams are this far past it is
    /// dropped, s. Default 1.
    pub max_wait_s: f64,
}

impl Default for SyncConfig {
    fn default() -> Self {
        Self {
            image_tolerance_s: 0.05,
            max_label_skew_s: 0.5,
            unlabelled: Unlabelled::Keep,
            max_odometry_gap_s: 0.5,
            max_wait_s: 1.0,
        }
    }
}

/// `ros.sync.unlabelled`: a cloud no label image reaches.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Unlabelled {
    /// Assembled without labels (counted as `unlabelled`).
    Keep,
    /// Dropped (counted as `no_image`).
    Drop,
}

/// A pose key's [x, y, z, qx, qy, qz, qw], checked; errors name `ros.KEY`.
fn pose_key([x, y, z, qx, qy, qz, qw]: [f64; 7], key: &str) -> Result<Pose3, InputError> {
    let pose = crate::msg::geometry_msgs::Pose {
        position: crate::msg::geometry_msgs::Point { x, y, z },
        orientation: crate::msg::geometry_msgs::Quaternion { x: qx, y: qy, z: qz, w: qw },
    };
    crate::convert::geometry::pose_from_msg(&pose).map_err(|e| InputError::invalid(format!("ros.{key}: {e}")))
}

impl RosConfig {
    /// `template` with `{robot}` and `{id}` filled in.
    pub fn resolve(template: &str, robot: &str, id: u16) -> String {
        template.replace("{robot}", robot).replace("{id}", &id.to_string())
    }

    /// The camera mounting pinned by configuration, as `body_from_camera`: `body_from_camera`,
    /// or the inverse of `camera_from_body` (checked: finite, unit quaternion, not both set).
    /// `None`: read from tf.
    pub fn camera_pin(&self) -> Result<Option<Pose3>, InputError> {
        match (self.camera_from_body, self.body_from_camera) {
            (Some(_), Some(_)) => Err(InputError::invalid(
                "ros.camera_from_body and ros.body_from_camera are both set: they are one mounting \
                 (one the inverse of the other), set one",
            )),
            (Some(values), None) => pose_key(values, "camera_from_body").map(|c| Some(c.inverse())),
            (None, Some(values)) => pose_key(values, "body_from_camera").map(Some),
            (None, None) => Ok(None),
        }
    }

    /// The LiDAR mounting pinned by configuration (`body_from_lidar`); `None`: from tf.
    pub fn lidar_pin(&self) -> Result<Option<Pose3>, InputError> {
        self.body_from_lidar.map(|values| pose_key(values, "body_from_lidar")).transpose()
    }

    /// Checks every key; errors name the key.
    pub fn validate(&self) -> Result<(), InputError> {
        let positive = |v: f64, key: &str| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(InputError::invalid(format!("ros.{key} = {v}: finite and > 0 expected")))
            }
        };
        positive(self.sync.image_tolerance_s, "sync.image_tolerance_s")?;
        positive(self.sync.max_label_skew_s, "sync.max_label_skew_s")?;
        if self.sync.max_label_skew_s < self.sync.image_tolerance_s {
            return Err(InputError::invalid(format!(
                "ros.sync.max_label_skew_s = {} is below ros.sync.image_tolerance_s = {}: at least that expected",
                self.sync.max_label_skew_s, self.sync.image_tolerance_s
            )));
        }
        positive(self.sync.max_odometry_gap_s, "sync.max_odometry_gap_s")?;
        positive(self.sync.max_wait_s, "sync.max_wait_s")?;
        positive(self.publish_interval_s, "publish_interval_s")?;
        positive(self.map_voxel_m, "map_voxel_m")?;
        positive(self.peers.call_timeout_s, "peers.call_timeout_s")?;
        positive(self.peers.backoff_initial_s, "peers.backoff_initial_s")?;
        positive(self.peers.backoff_max_s, "peers.backoff_max_s")?;
        positive(self.timeline.max_jump_s, "timeline.max_jump_s")?;
        self.health.validate().map_err(InputError::invalid)?;
        self.tf.validate().map_err(InputError::invalid)?;
        if self.timeline.confirm_messages == 0 {
            return Err(InputError::invalid("ros.timeline.confirm_messages = 0: ≥ 1 expected"));
        }
        if self.peers.queue == 0 {
            return Err(InputError::invalid("ros.peers.queue = 0: ≥ 1 expected"));
        }
        if self.peers.backoff_max_s < self.peers.backoff_initial_s {
            return Err(InputError::invalid(format!(
                "ros.peers.backoff_max_s = {}: ≥ backoff_initial_s ({}) expected",
                self.peers.backoff_max_s, self.peers.backoff_initial_s
            )));
        }
        if self.queue_size == 0 || self.max_cloud_points == 0 || self.max_image_pixels == 0 {
            return Err(InputError::invalid("ros.queue_size, max_cloud_points and max_image_pixels must be ≥ 1"));
        }
        if self.max_message_bytes < 1024 {
            return Err(InputError::invalid(format!(
                "ros.max_message_bytes = {}: ≥ 1024 expected",
                self.max_message_bytes
            )));
        }
        let t = &self.topics;
        for (key, name) in [
            ("points", &t.points),
            ("labels", &t.labels),
            ("camera_info", &t.camera_info),
            ("odometry", &t.odometry),
            ("markers", &t.markers),
            ("path", &t.path),
            ("map", &t.map),
            ("status", &t.status),
            ("tf", &t.tf),
            ("team", &t.team),
            ("clock", &t.clock),
            ("deliver", &t.deliver),
            ("tf.topic", &self.tf.topic),
            ("tf.static_topic", &self.tf.static_topic),
        ] {
            let bad = name.is_empty()
                || !name.chars().all(|c| c.is_ascii_alphanumeric() || "_/{}~".contains(c))
                || name.contains("//");
            if bad {
                let key = if key.starts_with("tf.") { key.to_string() } else { format!("topics.{key}") };
                return Err(InputError::invalid(format!("ros.{key} = {name:?}: not a valid ROS name")));
            }
        }
        if !t.deliver.contains("{id}") {
            return Err(InputError::invalid("ros.topics.deliver must contain {id}: one service per robot"));
        }
        for (from, to) in &self.frames.aliases {
            if from.trim_start_matches('/').is_empty() || to.trim_start_matches('/').is_empty() {
                return Err(InputError::invalid(format!(
                    "ros.frames.aliases: {from:?} = {to:?}: both frame names must be non-empty"
                )));
            }
        }
        self.camera_pin()?;
        self.lidar_pin().map(|_| ())
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
}
