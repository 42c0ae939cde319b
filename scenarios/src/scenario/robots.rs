//! `[[robots]]`: each robot's route, speed, sensor height, platform, start and faults.

use super::Platform;
use serde::{Deserialize, Serialize};

/// A generated route: random waypoints in a rectangle.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RouteSpec {
    /// [x_min, y_min, x_max, y_max], m.
    pub region_m: [f64; 4],
    /// Waypoints after the start.
    pub legs: usize,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RobotSpec {
    /// Default "robot<k>".
    pub name: String,
    /// [x, y] waypoints in the world, m; the robot starts at the first facing the second, and
    /// stops at the last. Either `waypoints` or `route`.
    pub waypoints: Vec<[f64; 2]>,
    /// A generated route (seeded): the robot starts at a random point of the region.
    pub route: Option<RouteSpec>,
    /// Cruise speed (from and to rest, slower on tight arcs: `[platforms]`). Default 1.5 m/s.
    pub speed_mps: f64,
    /// Height of the LiDAR above the ground, m. Default 0.8.
    pub sensor_height_m: f64,
    /// What carries the sensors: `wheeled`, `legged` or `handheld`. Default `wheeled`.
    pub platform: Platform,
    /// The robot is switched on at this time (it sets off `platforms.still_at_start_s` later), s.
    /// Default 0.
    pub start_s: f64,
    /// SGM on this robot crashes at this time, s: its actors and everything they held are
    /// gone (the vehicle and its odometry drive on). Default none.
    pub crash_s: Option<f64>,
    /// …and restarts at this time from its latest snapshot, s (needs `crash_s`). Default none:
    /// it stays down.
    pub restart_s: Option<f64>,
}

impl Default for RobotSpec {
    fn default() -> Self {
        Self {
            name: String::new(),
            waypoints: Vec::new(),
            route: None,
            speed_mps: 1.5,
            sensor_height_m: 0.8,
            platform: Platform::Wheeled,
            start_s: 0.0,
            crash_s: None,
            restart_s: None,
        }
    }
}
