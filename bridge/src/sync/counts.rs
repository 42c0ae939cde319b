//! What became of the clouds: the synchroniser's counters, in the status and the replay's report.

use serde::Serialize;
use std::collections::BTreeMap;

/// What became of the clouds.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct SyncCounts {
    pub frames: u64,
    pub no_odometry: u64,
    pub no_image: u64,
    pub no_camera_info: u64,
    pub no_label_field: u64,
    pub out_of_order: u64,
    pub overflow: u64,
    /// Clouds still waiting for partners when the timeline restarted (dropped).
    pub at_restart: u64,
    /// Frames labelled by an image farther than `image_tolerance_s`, motion-compensated.
    pub compensated: u64,
    /// Frames assembled without labels: no image within `max_label_skew_s`, or no odometry at
    /// the image's stamp to compensate with (`unlabelled = "keep"`).
    pub unlabelled: u64,
    /// The largest |image stamp − cloud stamp| of a labelled frame, ms (rounded up).
    pub label_skew_max_ms: u64,
    /// Sum of |image stamp − cloud stamp| over labelled frames, ms (mean = sum / labelled).
    pub label_skew_sum_ms: u64,
    /// Clouds dropped because the LiDAR's mount is unknown (not pinned, not in tf).
    pub no_lidar_mount: u64,
    /// Clouds that found their image but not the camera's mount (then kept unlabelled or
    /// dropped as `unlabelled` says; counted there too).
    pub no_camera_mount: u64,
    /// A sample of the points of labelled frames (every
    /// [`PROJECTION_SAMPLE`](super::PROJECTION_SAMPLE)-th), and those of them that project into
    /// the label image (`points_outside_image`).
    pub sampled_points: u64,
    pub sampled_in_image: u64,
    /// Pixels of colour label images whose colour the palette lacks (no class), and per
    /// colour (`#rrggbb`, the first 32 colours seen).
    pub unknown_colour_pixels: u64,
    pub unknown_colours: BTreeMap<String, u64>,
    /// With the robot's own odometry: clouds handed to it alone, without labels (no label
    /// field, no label image in time with `unlabelled = "drop"`, no camera info); registered,
    /// not mapped.
    #[serde(skip_serializing_if = "is_zero")]
    pub sweeps: u64,
    /// With the robot's own odometry: clouds handed on before the IMU reached their sweep's end
    /// (it lagged by more than `max_wait_s`, or stopped): the odometry coasted over the gap.
    #[serde(skip_serializing_if = "is_zero")]
    pub imu_short: u64,
    /// With the robot's own odometry: clouds dropped because the IMU's mount is unknown.
    #[serde(skip_serializing_if = "is_zero")]
    pub no_imu_mount: u64,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}
