//! `[imu]`: the simulated IMU (`sim::imu`). Off by default.

use serde::{Deserialize, Serialize};

/// Rates and noise densities as a datasheet or a Kalibr `imu.yaml` gives them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ImuSpec {
    /// Simulate an IMU on every robot. Default false.
    pub enabled: bool,
    /// Samples per second, Hz. Default 200.
    pub rate_hz: f64,
    /// Gyroscope white noise density, rad/s/√Hz. Default 1.6968e-4 (EuRoC's ADIS16448).
    pub gyro_noise: f64,
    /// Gyroscope bias random walk, rad/s²/√Hz. Default 1.9393e-5.
    pub gyro_bias_walk: f64,
    /// Accelerometer white noise density, m/s²/√Hz. Default 2.0e-3.
    pub accel_noise: f64,
    /// Accelerometer bias random walk, m/s³/√Hz. Default 3.0e-3.
    pub accel_bias_walk: f64,
    /// Turn-on bias: each robot's IMU starts with biases drawn per axis from N(0, σ²), its own
    /// at every power-up (a datasheet's "bias repeatability" or "zero-rate offset"), then walks
    /// from there. Gyroscope rad/s, accelerometer m/s². Defaults 0 (the biases start at zero).
    pub gyro_turn_on_bias: f64,
    pub accel_turn_on_bias: f64,
    /// Gravity, m/s². Default 9.81.
    pub gravity_mps2: f64,
}

impl Default for ImuSpec {
    fn default() -> Self {
        Self {
            enabled: false,
            rate_hz: 200.0,
            gyro_noise: 1.6968e-4,
            gyro_bias_walk: 1.9393e-5,
            accel_noise: 2.0e-3,
            accel_bias_walk: 3.0e-3,
            gyro_turn_on_bias: 0.0,
            accel_turn_on_bias: 0.0,
            gravity_mps2: 9.81,
        }
    }
}
