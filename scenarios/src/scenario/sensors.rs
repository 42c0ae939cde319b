//! `[lidar]`, `[camera]` and `[odometry]`: the simulated sensors (`sim::lidar`, `sim::camera`,
//! `sim::odometry`).

use serde::{Deserialize, Serialize};

/// The LiDAR's scan pattern.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LidarPattern {
    /// A spinning multi-beam LiDAR: `beams` rings evenly over the vertical field of view, one
    /// return per `azimuth_step_deg`.
    Spinning,
    /// A Livox-Mid-360-like non-repetitive pattern: `points_per_frame` directions from a
    /// low-discrepancy sequence continued from frame to frame.
    Livox,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LidarSpec {
    /// Default "spinning".
    pub pattern: LidarPattern,
    /// Spinning: rings. Default 32.
    pub beams: usize,
    /// Spinning: horizontal resolution, degrees. Default 0.4.
    pub azimuth_step_deg: f64,
    /// Lowest and highest beam elevation, degrees. Default [-15, 15] (spinning); a Livox
    /// Mid-360 covers [-7, 52].
    pub vertical_fov_deg: [f64; 2],
    /// Livox: returns per frame. Default 20000.
    pub points_per_frame: usize,
    /// Farthest return, m. Default 60.
    pub max_range_m: f64,
    /// Standard deviation of range noise, m. Default 0.02.
    pub range_noise_m: f64,
    /// Duration of one sweep, s: each return is measured from the moving sensor at its own
    /// time and carries it (0: every return at the frame's stamp, an undistorted scan). A real
    /// 10 Hz LiDAR sweeps for 0.1 s. Default 0.
    pub sweep_s: f64,
    /// Where the LiDAR sits on the body (the point the trajectory follows), m, x forward, z up.
    /// Default [0, 0, 0].
    pub mount_xyz_m: [f64; 3],
    /// The LiDAR's roll, pitch and yaw on the body, degrees. Default [0, 0, 0].
    pub mount_rpy_deg: [f64; 3],
    /// The mount the robot is told (with which its driver brings the returns into the body
    /// frame) is off from the true one by a rotation of this angle about a random axis, degrees.
    /// Default 0.
    pub mount_error_deg: f64,
    /// … and by a translation of this length, m. Default 0.
    pub mount_error_m: f64,
}

impl Default for LidarSpec {
    fn default() -> Self {
        Self {
            pattern: LidarPattern::Spinning,
            beams: 32,
            azimuth_step_deg: 0.4,
            vertical_fov_deg: [-15.0, 15.0],
            points_per_frame: 20_000,
            max_range_m: 60.0,
            range_noise_m: 0.02,
            sweep_s: 0.0,
            mount_xyz_m: [0.0; 3],
            mount_rpy_deg: [0.0; 3],
            mount_error_deg: 0.0,
            mount_error_m: 0.0,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraSpec {
    /// A forward camera with a segmentation network; false: per-point labels from the
    /// simulator (with the same mislabel rate). Default true.
    pub enabled: bool,
    /// Label image size, pixels. Default 320 × 240.
    pub width: u32,
    pub height: u32,
    /// Horizontal field of view, degrees. Default 100.
    pub horizontal_fov_deg: f64,
    /// Probability that an object is given a wrong (matchable) class in one frame. Default 0.05.
    pub mislabel_rate: f64,
    /// Standard deviation of the label boundary jitter, pixels. Default 1.
    pub boundary_noise_px: f64,
    /// Where the camera sits on the body (the body is the LiDAR's frame): its position, m, in
    /// the body frame. Default [0, 0, 0].
    pub mount_xyz_m: [f64; 3],
    /// Its orientation: roll, pitch, yaw, degrees (extrinsic x-y-z, as
    /// `geometry::pose_from_rpy_translation`) of the camera's forward frame (x along the view)
    /// in the body frame. Default [0, 0, 0]: looking along the body's x.
    pub mount_rpy_deg: [f64; 3],
    /// The mount the robot is told is off from the true one by a rotation of this angle about
    /// a seeded axis, degrees (a calibration error). Default 0.
    pub mount_error_deg: f64,
    /// … and by a displacement of this length in a seeded direction, m. Default 0.
    pub mount_error_m: f64,
    /// The image's mid-exposure time after the scan's stamp, s: the camera fires at its own
    /// time, which its stamp says (the pipeline compensates the motion in between). Default 0.
    pub exposure_offset_s: f64,
    /// The camera clock's error: the image's stamp is its true time plus this, s (a clock the
    /// pipeline cannot know of). Default 0.
    pub clock_offset_s: f64,
}

impl Default for CameraSpec {
    fn default() -> Self {
        Self {
            enabled: true,
            width: 320,
            height: 240,
            horizontal_fov_deg: 100.0,
            mislabel_rate: 0.05,
            boundary_noise_px: 1.0,
            mount_xyz_m: [0.0; 3],
            mount_rpy_deg: [0.0; 3],
            mount_error_deg: 0.0,
            mount_error_m: 0.0,
            exposure_offset_s: 0.0,
            clock_offset_s: 0.0,
        }
    }
}

/// Where each robot's odometry comes from in a scenario.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OdometrySourceSpec {
    /// The truth plus the random walks below (`sim::odometry`), handed to the robot with each
    /// frame: quick, and its drift is a model's.
    #[default]
    Synthetic,
    /// Each robot runs SGM's LiDAR-inertial odometry (its Odometry actor) on the simulated
    /// sweeps, one every `sweep_interval_s`, and the IMU (`imu.enabled` must be true), with
    /// the default `odometry.estimator` told the scenario's `[imu]` noise.
    Internal,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OdometrySpec {
    /// "synthetic" or "internal". Default "synthetic".
    pub source: OdometrySourceSpec,
    /// Internal: the LiDAR hands on a sweep this often, s; every `scenario.frame_interval_s`
    /// one of them is also labelled and goes on to the map. Default 0.1 (a 10 Hz LiDAR).
    pub sweep_interval_s: f64,
    /// Position random walk, m per √m travelled (each horizontal axis). Default 0.005.
    pub position_walk_m: f64,
    /// Yaw random walk, degrees per √m travelled. Default 0.03.
    pub yaw_walk_deg: f64,
    /// Height random walk, m per √m travelled. Default 0.002.
    pub height_walk_m: f64,
    /// Roll and pitch error: standard deviation of a slowly varying tilt, degrees. Default 0.1.
    pub roll_pitch_deg: f64,
    /// Roll and pitch random walk, degrees per √m travelled: an odometry without a gravity
    /// reference (no IMU), whose frame tilts over the mission. Default 0.
    pub tilt_walk_deg: f64,
}

impl Default for OdometrySpec {
    fn default() -> Self {
        Self {
            source: OdometrySourceSpec::Synthetic,
            sweep_interval_s: 0.1,
            position_walk_m: 0.005,
            yaw_walk_deg: 0.03,
            height_walk_m: 0.002,
            roll_pitch_deg: 0.1,
            tilt_walk_deg: 0.0,
        }
    }
}
