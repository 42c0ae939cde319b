//! The odometry's one configuration (`[odometry]` in a robot's or a scenario's file): every
//! part's parameters with defaults, and the check that refuses impossible values by key.

use super::imu_queue::ImuLimits;
use super::local_map::LocalMapConfig;
use super::propagation::ImuNoise;
use super::registration::RegistrationConfig;
use super::threshold::ThresholdConfig;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OdometryConfig {
    pub local_map: LocalMapConfig,
    pub registration: RegistrationConfig,
    /// The adaptive threshold; its σ₀ defaults to 0.5 m here, not KISS-ICP's 2 m: the first
    /// predictions (an IMU's, or a robot starting from rest) are good to decimetres, and a 6 m
    /// first threshold let the first registration of the tests' room settle 0.1 rad off.
    pub threshold: ThresholdConfig,
    /// The IMU's noise densities and gravity.
    pub imu: ImuNoise,
    pub imu_limits: ImuLimits,
    /// Process noise while coasting (across an IMU gap): how far a robot's motion may stray from
    /// constant velocity. Defaults: gyro 0.1 rad/s/√Hz, accelerometer 1.0 m/s²/√Hz, biases as
    /// the IMU's.
    pub coast: ImuNoise,
    /// Noise of one point-to-plane residual, m: the scan's information is its Hessian / σ².
    /// Default 0.05.
    pub point_noise_m: f64,
    /// The scan's information (its Hessian / σ²) is scaled by this. Residuals are not
    /// independent — neighbours share map points, fitted planes and the deskew's error — so N
    /// of them carry far less than N measurements' worth; counted at face value, a scan claims
    /// rotations to 0.05 mrad when registration is good to ~0.5, and the filter pushes the
    /// difference into the gyro's bias. Default 0.1.
    pub scan_information_scale: f64,
    /// Returns nearer than this (the robot itself) or farther than `max_range_m` are not
    /// registered, m. Defaults 0.5 and 100.
    pub min_range_m: f64,
    pub max_range_m: f64,
    /// Voxel of the scan that is registered, m. Default 0.5.
    pub scan_voxel_m: f64,
    /// Voxel of the scan added to the local map, m. Default 0.25.
    pub map_voxel_m: f64,
    /// Gravity is read from the IMU samples of this many seconds before the first scan, at least
    /// `level_min_samples` of them. Defaults 1.0 s and 20.
    pub level_window_s: f64,
    pub level_min_samples: usize,
    /// Initial uncertainty: velocity when the body was not still at start and when it was
    /// (its IMU at noise level for the window: a platform under way shakes it far beyond),
    /// where up is in the levelled frame besides what the accelerometer's bias explains (the
    /// larger of this and the window's force spread over g when the body was moving), gyro and
    /// accelerometer biases. Defaults 1.0 m/s, 0.05 m/s, 0.002 rad, 0.005 rad/s, 0.1 m/s².
    pub initial_velocity_sigma_mps: f64,
    pub initial_still_velocity_sigma_mps: f64,
    pub initial_tilt_sigma_rad: f64,
    pub initial_gyro_bias_sigma_rad_s: f64,
    pub initial_accel_bias_sigma_mps2: f64,
    /// A state faster than this has diverged, m/s. Default 30.
    pub max_speed_mps: f64,
    /// A registration that moves the prediction by more than this is not believed (the scan
    /// matched the wrong structure), m and rad. Defaults 1.0 and 0.3.
    pub max_correction_m: f64,
    pub max_correction_rad: f64,
    /// A registered scan of whose points fewer than this fraction found a surface of the local
    /// map is counted `low_overlap` (the first is warned): it saw mostly what the map does not
    /// hold — new ground all around, or an estimate that has left its map (a registration that
    /// agrees with a wrong prediction, onto the points that prediction put in the map). In [0, 1];
    /// 0 counts none; scans before the body first moved are not counted. Default 0.2.
    pub min_overlap: f64,
}

impl Default for OdometryConfig {
    fn default() -> Self {
        let imu = ImuNoise::default();
        Self {
            local_map: LocalMapConfig::default(),
            registration: RegistrationConfig::default(),
            threshold: ThresholdConfig { initial_sigma_m: 0.5, ..ThresholdConfig::default() },
            imu,
            imu_limits: ImuLimits::default(),
            coast: ImuNoise { gyro_noise: 0.1, accel_noise: 1.0, ..imu },
            point_noise_m: 0.05,
            scan_information_scale: 0.1,
            min_range_m: 0.5,
            max_range_m: 100.0,
            scan_voxel_m: 0.5,
            map_voxel_m: 0.25,
            level_window_s: 1.0,
            level_min_samples: 20,
            initial_velocity_sigma_mps: 1.0,
            initial_still_velocity_sigma_mps: 0.05,
            initial_tilt_sigma_rad: 0.002,
            initial_gyro_bias_sigma_rad_s: 0.005,
            initial_accel_bias_sigma_mps2: 0.1,
            max_speed_mps: 30.0,
            max_correction_m: 1.0,
            max_correction_rad: 0.3,
            min_overlap: 0.2,
        }
    }
}

/// A parameter out of range: its key under `odometry.`, its value, what is allowed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("odometry.{key} = {value}: must be {allowed}")]
pub struct OdometryConfigError {
    pub key: String,
    pub value: f64,
    pub allowed: &'static str,
}

impl OdometryConfig {
    pub fn validate(&self) -> Result<(), OdometryConfigError> {
        self.local_map.validate().map_err(|e| OdometryConfigError {
            key: format!("local_map.{}", e.key),
            value: e.value,
            allowed: e.allowed,
        })?;
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let non_negative = |v: f64| v.is_finite() && v >= 0.0;
        let r = &self.registration;
        let t = &self.threshold;
        let l = &self.imu_limits;
        let noise = |prefix: &'static str, n: &ImuNoise| {
            [
                (format!("{prefix}.gyro_noise"), n.gyro_noise, non_negative(n.gyro_noise), "finite and ≥ 0"),
                (format!("{prefix}.accel_noise"), n.accel_noise, non_negative(n.accel_noise), "finite and ≥ 0"),
                (
                    format!("{prefix}.gyro_bias_walk"),
                    n.gyro_bias_walk,
                    non_negative(n.gyro_bias_walk),
                    "finite and ≥ 0",
                ),
                (
                    format!("{prefix}.accel_bias_walk"),
                    n.accel_bias_walk,
                    non_negative(n.accel_bias_walk),
                    "finite and ≥ 0",
                ),
                (format!("{prefix}.gravity_mps2"), n.gravity_mps2, positive(n.gravity_mps2), "finite and > 0"),
            ]
        };
        let checks: Vec<(String, f64, bool, &'static str)> = [
            ("point_noise_m", self.point_noise_m, positive(self.point_noise_m), "finite and > 0"),
            (
                "scan_information_scale",
                self.scan_information_scale,
                positive(self.scan_information_scale) && self.scan_information_scale <= 1.0,
                "in (0, 1]",
            ),
            ("min_range_m", self.min_range_m, non_negative(self.min_range_m), "finite and ≥ 0"),
            (
                "max_range_m",
                self.max_range_m,
                positive(self.max_range_m) && self.max_range_m > self.min_range_m,
                "finite and > min_range_m",
            ),
            ("scan_voxel_m", self.scan_voxel_m, positive(self.scan_voxel_m), "finite and > 0"),
            ("map_voxel_m", self.map_voxel_m, positive(self.map_voxel_m), "finite and > 0"),
            ("level_window_s", self.level_window_s, positive(self.level_window_s), "finite and > 0"),
            ("level_min_samples", self.level_min_samples as f64, self.level_min_samples >= 1, "≥ 1"),
            (
                "initial_velocity_sigma_mps",
                self.initial_velocity_sigma_mps,
                positive(self.initial_velocity_sigma_mps),
                "finite and > 0",
            ),
            (
                "initial_still_velocity_sigma_mps",
                self.initial_still_velocity_sigma_mps,
                positive(self.initial_still_velocity_sigma_mps),
                "finite and > 0",
            ),
            (
                "initial_tilt_sigma_rad",
                self.initial_tilt_sigma_rad,
                positive(self.initial_tilt_sigma_rad),
                "finite and > 0",
            ),
            (
                "initial_gyro_bias_sigma_rad_s",
                self.initial_gyro_bias_sigma_rad_s,
                positive(self.initial_gyro_bias_sigma_rad_s),
                "finite and > 0",
            ),
            (
                "initial_accel_bias_sigma_mps2",
                self.initial_accel_bias_sigma_mps2,
                positive(self.initial_accel_bias_sigma_mps2),
                "finite and > 0",
            ),
            ("max_speed_mps", self.max_speed_mps, positive(self.max_speed_mps), "finite and > 0"),
            ("max_correction_m", self.max_correction_m, positive(self.max_correction_m), "finite and > 0"),
            ("max_correction_rad", self.max_correction_rad, positive(self.max_correction_rad), "finite and > 0"),
            ("min_overlap", self.min_overlap, (0.0..=1.0).contains(&self.min_overlap), "between 0 and 1"),
            ("registration.max_iterations", r.max_iterations as f64, r.max_iterations >= 1, "≥ 1"),
            ("registration.convergence_rad", r.convergence_rad, positive(r.convergence_rad), "finite and > 0"),
            ("registration.convergence_m", r.convergence_m, positive(r.convergence_m), "finite and > 0"),
            ("registration.min_correspondences", r.min_correspondences as f64, r.min_correspondences >= 6, "≥ 6"),
            ("registration.plane_neighbours", r.plane_neighbours as f64, r.plane_neighbours >= 3, "≥ 3"),
            ("registration.plane_tolerance_m", r.plane_tolerance_m, positive(r.plane_tolerance_m), "finite and > 0"),
            ("registration.planarity", r.planarity, positive(r.planarity) && r.planarity < 1.0, "in (0, 1)"),
            (
                "registration.weak_translation_ratio",
                r.weak_translation_ratio,
                positive(r.weak_translation_ratio) && r.weak_translation_ratio < 1.0,
                "in (0, 1)",
            ),
            (
                "registration.weak_rotation_ratio",
                r.weak_rotation_ratio,
                positive(r.weak_rotation_ratio) && r.weak_rotation_ratio < 1.0,
                "in (0, 1)",
            ),
            ("threshold.initial_sigma_m", t.initial_sigma_m, positive(t.initial_sigma_m), "finite and > 0"),
            ("threshold.min_motion_m", t.min_motion_m, non_negative(t.min_motion_m), "finite and ≥ 0"),
            ("threshold.max_range_m", t.max_range_m, positive(t.max_range_m), "finite and > 0"),
            ("imu_limits.gyro_range_rad_s", l.gyro_range_rad_s, positive(l.gyro_range_rad_s), "finite and > 0"),
            (
                "imu_limits.accel_range_mps2",
                l.accel_range_mps2,
                positive(l.accel_range_mps2) && l.accel_range_mps2 > self.imu.gravity_mps2,
                "finite and > gravity",
            ),
            ("imu_limits.max_gap_s", l.max_gap_s, positive(l.max_gap_s), "finite and > 0"),
        ]
        .into_iter()
        .map(|(k, v, ok, allowed)| (k.to_string(), v, ok, allowed))
        .chain(noise("imu", &self.imu))
        .chain(noise("coast", &self.coast))
        .collect();
        match checks.into_iter().find(|(_, _, ok, _)| !ok) {
            Some((key, value, _, allowed)) => Err(OdometryConfigError { key, value, allowed }),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_defaults_are_valid_and_bad_values_are_refused_by_key() {
        assert_eq!(OdometryConfig::default().validate(), Ok(()));
        let bad = |c: OdometryConfig| c.validate().expect_err("refused").to_string();
        assert_eq!(
            bad(OdometryConfig { point_noise_m: -1.0, ..OdometryConfig::default() }),
            "odometry.point_noise_m = -1: must be finite and > 0"
        );
        let mut c = OdometryConfig::default();
        c.local_map.voxel_m = f64::NAN;
        assert_eq!(bad(c), "odometry.local_map.voxel_m = NaN: must be finite and > 0");
        let mut c = OdometryConfig::default();
        c.imu.gyro_noise = -0.1;
        assert_eq!(bad(c), "odometry.imu.gyro_noise = -0.1: must be finite and ≥ 0");
        let mut c = OdometryConfig::default();
        c.registration.planarity = 1.5;
        assert_eq!(bad(c), "odometry.registration.planarity = 1.5: must be in (0, 1)");
        assert!(bad(OdometryConfig { max_range_m: 0.2, ..OdometryConfig::default() }).contains("max_range_m"));
        assert_eq!(
            bad(OdometryConfig { min_overlap: 1.5, ..OdometryConfig::default() }),
            "odometry.min_overlap = 1.5: must be between 0 and 1"
        );
        assert!(bad(OdometryConfig { min_overlap: f64::NAN, ..OdometryConfig::default() }).contains("min_overlap"));
    }
}
