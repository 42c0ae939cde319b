//! What a finding is about, and what the status says of it: the condition, its detail and its
//! likely cause.

use serde::Serialize;

/// What a finding is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Check {
    /// Most of an input topic's messages were refused.
    InputRefused,
    /// A sensor's mount is unknown: not pinned, and tf does not connect its frame to the body.
    NoMount,
    /// A mount pinned in configuration disagrees with tf.
    MountDisagrees,
    /// Most clouds found no odometry pose.
    NoOdometry,
    /// With the robot's own odometry: most clouds came before the IMU covered their sweep.
    ImuShort,
    /// The odometry topic and tf give different poses for the same world and body frames.
    OdometryDisagreesWithTf,
    /// Most clouds had no label image near them.
    NoLabels,
    /// Labelled frames, but (almost) none of their points lands in the label image.
    PointsOutsideImage,
    /// Frames flow, yet the map holds no confirmed object (none worth sharing).
    NoObjects,
}

impl Check {
    fn likely_cause(self) -> &'static str {
        match self {
            Check::InputRefused => {
                "the messages do not match [ros]: frame ids (ros.frames, or rename them with ros.frames.aliases), \
                 encodings or sizes; the reason above names what"
            }
            Check::NoMount => {
                "nothing publishes the mount on tf (robot_state_publisher, static_transform_publisher, the \
                 driver's tf_static), tf comes on another topic (ros.tf.topic, ros.tf.static_topic), or \
                 ros.frames names another frame than the messages carry; or pin it in [ros]"
            }
            Check::MountDisagrees => {
                "the configured mount is stale (the sensor was moved or recalibrated) or written the wrong way \
                 round (body_from_camera vs camera_from_body); tf or the key is wrong"
            }
            Check::NoOdometry => {
                "the odometry lags the clouds by more than ros.sync.max_wait_s, has gaps above \
                 ros.sync.max_odometry_gap_s, or is stamped by another clock"
            }
            Check::ImuShort => {
                "the IMU is silent on ros.topics.imu, lags the clouds by more than ros.sync.max_wait_s, or is \
                 stamped by another clock; the robot's own odometry coasts over what it lacks"
            }
            Check::OdometryDisagreesWithTf => {
                "two sources publish the same frames (another odometry or localisation on tf), or the odometry \
                 topic is not the one whose transform is on tf"
            }
            Check::NoLabels => {
                "the segmenter is not publishing on the labels topic, is slower than ros.sync.max_label_skew_s, \
                 or stamps its images by another clock than the LiDAR's (see sync.label_skew_max_ms)"
            }
            Check::PointsOutsideImage => {
                "the camera mount is wrong (inverted: tf gives ros.body_from_camera, not camera_from_body; or the \
                 camera's link instead of its optical frame), or camera_info is another camera's"
            }
            Check::NoObjects => {
                "the LiDAR points do not land on the label image's objects: ros.camera_from_body inverted \
                 (tf gives ros.body_from_camera) or the wrong camera_info; or the segmenter's ids are not \
                 fusion.classes' ids (map them in [classes]); or the objects are beyond fusion's range"
            }
        }
    }
}

/// One condition that holds, for the status.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Finding {
    pub check: Check,
    pub detail: String,
    pub likely_cause: &'static str,
}

impl Finding {
    pub(super) fn new(check: Check, detail: String) -> Self {
        Self { check, detail, likely_cause: check.likely_cause() }
    }
}
