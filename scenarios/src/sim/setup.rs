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
                Route::of(r, k, seed).with_motion(motion)
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
