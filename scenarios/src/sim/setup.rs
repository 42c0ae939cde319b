//! A scenario's simulated world as the runner and the odometry bench both build it: the terrain,
//! each robot's route with its platform's motion, the world generated along the routes and
//! settled on the terrain, and the people walking through it; and one LiDAR sweep in the body
//! frame through the true mount.

use crate::scenario::Scenario;
use crate::sim::lidar::{Lidar, LidarFrame};
use crate::sim::mount::LidarMount;
use crate::sim::people::People;
use crate::sim::platform::Motion;
use crate::sim::terrain::Terrain;
use crate::sim::trajectory::Route;
use crate::sim::world::{generate, World};
use nalgebra::Point2;
use rand::Rng;
use sgm_model::geometry::Pose3;
use std::sync::Arc;

pub struct SimulatedWorld {
    pub routes: Vec<Route>,
    pub world: World,
    pub people: People,
}

impl SimulatedWorld {
    pub fn of(scenario: &Scenario) -> Self {
        let seed = scenario.scenario.seed;
        let [sx, sy] = scenario.world.size_m;
        let terrain = Arc::new(Terrain::generate(&scenario.terrain, [-sx / 2.0, -sy / 2.0, sx / 2.0, sy / 2.0], seed));
        let routes: Vec<Route> = scenario
            .robots
            .iter()
            .enumerate()
            .map(|(k, r)| {
                let motion = Motion::new(terrain.clone(), r.platform, &scenario.platforms, r.sensor_height_m, k, seed);
                Route::of(r, k, seed, &scenario.platforms).with_motion(motion)
            })
            .collect();
        let paths: Vec<Vec<Point2<f64>>> = routes.iter().map(|r| r.points.clone()).collect();
        let mut world = generate(&scenario.world, &scenario.fusion.classes, &paths, seed);
        world.settle_on(terrain);
        let people = People::of_scenario(scenario, &world, &paths);
        Self { routes, world, people }
    }
}

/// One sweep of `lidar` from the robot on `route` at `t` (`truth` its pose then), its returns
/// in the body frame through the true `mount` (float32, as a driver's), each from the pose of
/// its own instant.
pub fn sweep_in_body(
    lidar: &mut Lidar,
    mount: &LidarMount,
    world: &World,
    route: &Route,
    t: f64,
    truth: &Pose3,
    rng: &mut impl Rng,
) -> LidarFrame {
    if mount.at_body() {
        return lidar.sweep(world, &|tau| route.pose_at(t + tau).unwrap_or(*truth), rng);
    }
    let body_from_lidar = mount.body_from_lidar;
    let world_from_lidar = |tau| route.pose_at(t + tau).unwrap_or(*truth) * body_from_lidar;
    let mut frame = lidar.sweep(world, &world_from_lidar, rng);
    frame.points.iter_mut().for_each(|p| *p = (body_from_lidar * *p).map(|v| f64::from(v as f32)));
    frame
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::ImuSpec;
    use crate::sim::imu::Imu;
    use nalgebra::Vector3;

    /// The largest body rate (rad/s) and the largest departure of the specific force from
    /// gravity (m/s²) that each library scenario's robots go through, from noise-free samples.
    fn envelope(name: &str) -> (f64, f64) {
        let scenario = Scenario::load(name).expect("library scenario");
        let sim = SimulatedWorld::of(&scenario);
        let imu = Imu::new(&ImuSpec { rate_hz: 100.0, ..ImuSpec::default() }, 0, 0);
        let (mut rate, mut force) = (0.0f64, 0.0f64);
        for route in &sim.routes {
            let truth = |t: f64| route.pose_at(t);
            let end = (route.arrival_s().min(scenario.scenario.duration_s) * 100.0) as i64;
            for k in 0..end {
                let Some(sample) = imu.true_sample(k, &truth) else { continue };
                let Some(pose) = truth(sample.stamp) else { continue };
                let gravity = pose.rotation.inverse() * Vector3::z() * 9.81;
                rate = rate.max(sample.angular_velocity.amax());
                force = force.max((sample.specific_force - gravity).amax());
            }
        }
        (rate, force)
    }

    /// On flat ground the turn rate keeps within `platforms.yaw_rate_dps` (60°/s) and the
    /// acceleration within `platforms.accel_mps2` (1 m/s²) along and across the path; gait,
    /// sway and kerbs add to it, within what a MEMS IMU measures (±2000°/s, ±16 g): nothing
    /// the simulator makes saturates the odometry's IMU.
    #[test]
    fn every_library_robot_moves_as_a_body_can() {
        for name in ["quickstart", "outdoor_two_robots", "indoor_three_robots"] {
            let (rate, force) = envelope(name);
            assert!(rate <= 60f64.to_radians() + 1e-6, "{name}: {rate} rad/s");
            assert!(force <= 2f64.sqrt() + 1e-6, "{name}: {force} m/s²");
        }
        for name in ["legged_campus", "handheld_indoor"] {
            let (rate, force) = envelope(name);
            assert!(rate <= 3.0, "{name}: {rate} rad/s");
            assert!(force <= 16.0 * 9.81, "{name}: {force} m/s²");
        }
    }
}
