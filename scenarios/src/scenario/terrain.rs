//! `[terrain]` and `[platforms]`: the ground the robots move over and how their bodies move on
//! it. Every effect defaults to off (flat ground, wheeled robots), which is the world of the
//! first milestone; `sim::terrain` and `sim::platform` make them.

use serde::{Deserialize, Serialize};

/// The ground as a height field: rolling hills, raised sidewalks with kerbs, ramps.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TerrainSpec {
    /// Steepest slope of the rolling ground, ° (0: flat). Default 0.
    pub max_slope_deg: f64,
    /// Longest wavelength of the rolling ground, m. Default 40.
    pub hill_wavelength_m: f64,
    /// Raised sidewalks (3 m wide, a kerb on each side) crossing the world. Default 0.
    pub kerbs: usize,
    /// Height of a kerb, m. Default 0.12.
    pub kerb_height_m: f64,
    /// Ramps (3 m wide: up, a 4 m landing, down). Default 0.
    pub ramps: usize,
    /// Slope of a ramp, °. Default 8.
    pub ramp_slope_deg: f64,
    /// Height of a ramp's landing, m. Default 0.5.
    pub ramp_height_m: f64,
}

impl Default for TerrainSpec {
    fn default() -> Self {
        Self {
            max_slope_deg: 0.0,
            hill_wavelength_m: 40.0,
            kerbs: 0,
            kerb_height_m: 0.12,
            ramps: 0,
            ramp_slope_deg: 8.0,
            ramp_height_m: 0.5,
        }
    }
}

impl TerrainSpec {
    /// No hills, no kerbs, no ramps: the plane z = 0.
    pub fn is_flat(&self) -> bool {
        self.max_slope_deg == 0.0 && self.kerbs == 0 && self.ramps == 0
    }
}

/// How a robot's body moves over the ground.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Platform {
    /// Four wheels on the ground: attitude follows the terrain under them.
    #[default]
    Wheeled,
    /// A quadruped: the terrain's attitude plus the gait's roll and pitch oscillation and
    /// vertical bounce while it walks.
    Legged,
    /// Carried by a person: the terrain's height plus a 6-DoF sway, also when standing.
    Handheld,
}

/// The motion of each platform kind (`[platforms]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlatformsSpec {
    /// Wheelbase (front to rear contact) of a wheeled or legged robot, m. Default 0.6.
    pub wheelbase_m: f64,
    /// Track (left to right contact), m. Default 0.5.
    pub track_m: f64,
    /// Gait frequency of a legged robot (its roll; pitch and bounce at twice it), Hz. Default 2.
    pub gait_hz: f64,
    /// Roll and pitch amplitude of the gait, °. Default 3.
    pub gait_amplitude_deg: f64,
    /// Vertical bounce amplitude of the gait, m. Default 0.02.
    pub gait_bounce_m: f64,
    /// Rotation sway amplitude of a handheld rig (each axis), °. Default 4.
    pub sway_deg: f64,
    /// Translation sway amplitude of a handheld rig (each axis), m. Default 0.05.
    pub sway_m: f64,
    /// Acceleration limit, along the path and across it in turns, m/s². Default 1.
    pub accel_mps2: f64,
    /// Radius of the arc that rounds each corner of a route (smaller where the legs are short;
    /// 0: turn on the spot), m. Default 1.
    pub turn_radius_m: f64,
    /// Yaw rate limit, °/s. Default 60.
    pub yaw_rate_dps: f64,
    /// Yaw acceleration limit of a turn on the spot, °/s². Default 120.
    pub yaw_accel_dps2: f64,
    /// How long a robot stands still after it is switched on before it sets off, s. Default 2.
    pub still_at_start_s: f64,
}

impl Default for PlatformsSpec {
    fn default() -> Self {
        Self {
            wheelbase_m: 0.6,
            track_m: 0.5,
            gait_hz: 2.0,
            gait_amplitude_deg: 3.0,
            gait_bounce_m: 0.02,
            sway_deg: 4.0,
            sway_m: 0.05,
            accel_mps2: 1.0,
            turn_radius_m: 1.0,
            yaw_rate_dps: 60.0,
            yaw_accel_dps2: 120.0,
            still_at_start_s: 2.0,
        }
    }
}
