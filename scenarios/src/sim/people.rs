//! People walking through the world (`segmentation.people`): each a person-sized upright
//! cylinder (radius 0.25 m, 1.75 m tall, standing on the ground) walking at
//! `person_speed_mps` round a seeded closed path of [`WAYPOINTS`] points, each near a random
//! point of a random robot's route (within ±[`ROUTE_OFFSET_M`] of it), so that people cross the
//! robots' views. They are solids of the world at the frame's time: the LiDAR sees them and
//! the segmenter labels them `person`; nothing else knows them.

use crate::sim::shapes::{Primitive, Solid};
use crate::sim::terrain::Terrain;
use crate::sim::world::World;
use nalgebra::Point2;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

pub const WAYPOINTS: usize = 5;
pub const ROUTE_OFFSET_M: f64 = 4.0;
pub const PERSON_RADIUS_M: f64 = 0.25;
pub const PERSON_HEIGHT_M: f64 = 1.75;

/// One person's walk: a closed polyline, walked from `start_m` along it.
#[derive(Clone, Debug)]
struct Walk {
    points: Vec<Point2<f64>>,
    length: f64,
    start_m: f64,
}

impl Walk {
    fn at(&self, distance: f64) -> Point2<f64> {
        let mut left = (self.start_m + distance).rem_euclid(self.length.max(f64::MIN_POSITIVE));
        let n = self.points.len();
        for k in 0..n {
            let (a, b) = (self.points[k], self.points[(k + 1) % n]);
            let leg = (b - a).norm();
            if left <= leg && leg > 0.0 {
                return a + (b - a) * (left / leg);
            }
            left -= leg;
        }
        self.points.first().copied().unwrap_or_else(Point2::origin)
    }
}

/// The people of a run.
#[derive(Clone, Debug, Default)]
pub struct People {
    walks: Vec<Walk>,
    speed_mps: f64,
    label: u16,
    first_instance: u32,
    /// Solids of the static world (people come after them in `world.solids`).
    static_solids: usize,
}

impl People {
    /// `count` people labelled `label` in `world` (their instances follow the world's), walking
    /// near `routes` (or anywhere in the world's bounds when there are none).
    pub fn new(
        count: usize,
        speed_mps: f64,
        label: u16,
        world: &World,
        routes: &[Vec<Point2<f64>>],
        seed: u64,
    ) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5045_4f50_4c45);
        let [x0, y0, x1, y1] = world.bounds;
        let legs: Vec<(Point2<f64>, Point2<f64>)> =
            routes.iter().flat_map(|r| r.windows(2).map(|w| (w[0], w[1]))).collect();
        let walks = (0..count)
            .map(|_| {
                let points: Vec<Point2<f64>> = (0..WAYPOINTS)
                    .map(|_| {
                        let p = match legs.get(rng.random_range(0..legs.len().max(1))) {
                            Some((a, b)) => {
                                let on = a + (b - a) * rng.random_range(0.0..1.0);
                                on + nalgebra::Vector2::new(
                                    rng.random_range(-ROUTE_OFFSET_M..ROUTE_OFFSET_M),
                                    rng.random_range(-ROUTE_OFFSET_M..ROUTE_OFFSET_M),
                                )
                            }
                            None => Point2::new(rng.random_range(x0..x1), rng.random_range(y0..y1)),
                        };
                        Point2::new(p.x.clamp(x0, x1), p.y.clamp(y0, y1))
                    })
                    .collect();
                let length = (0..WAYPOINTS).map(|k| (points[(k + 1) % WAYPOINTS] - points[k]).norm()).sum::<f64>();
                Walk { points, length, start_m: rng.random_range(0.0..length.max(1.0)) }
            })
            .collect();
        let first_instance = world.solids.iter().map(|s| s.instance).max().map_or(0, |m| m.saturating_add(1));
        Self { walks, speed_mps, label, first_instance, static_solids: world.solids.len() }
    }

    /// The people of `scenario` (none when `segmentation.people` is 0), labelled with its
    /// `person` class.
    pub fn of_scenario(scenario: &crate::scenario::Scenario, world: &World, routes: &[Vec<Point2<f64>>]) -> Self {
        let g = &scenario.segmentation;
        let person = crate::scenario::segmentation::PERSON;
        let label =
            scenario.fusion.classes.iter().find(|c| c.name == person).map_or(crate::sim::world::NO_LABEL, |c| c.id);
        Self::new(g.people, g.person_speed_mps, label, world, routes, scenario.scenario.seed)
    }

    /// Where person `k` is at time `t`, world frame.
    pub fn position(&self, k: usize, t: f64) -> Option<Point2<f64>> {
        self.walks.get(k).map(|w| w.at(self.speed_mps * t))
    }

    /// Object instance of person `k`.
    pub fn instance(&self, k: usize) -> u32 {
        self.first_instance.saturating_add(k as u32)
    }

    /// Puts the people in `world` where they are at `t` (the static world's solids untouched).
    pub fn place(&self, world: &mut World, t: f64) {
        if self.walks.is_empty() {
            return;
        }
        world.solids.truncate(self.static_solids);
        let terrain: &Terrain = &world.terrain;
        let people: Vec<Solid> = (0..self.walks.len())
            .filter_map(|k| {
                let p = self.position(k, t)?;
                let z0 = terrain.height(p.x, p.y);
                let primitive =
                    Primitive::Cylinder { x: p.x, y: p.y, radius: PERSON_RADIUS_M, z0, z1: z0 + PERSON_HEIGHT_M };
                Some(Solid { primitive, label: self.label, instance: self.instance(k) })
            })
            .collect();
        world.solids.extend(people);
    }

    /// Takes the people out of `world` again.
    pub fn remove(&self, world: &mut World) {
        world.solids.truncate(self.static_solids);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn people_walk_at_their_speed_near_the_routes_and_leave_the_static_world_alone() {
        let world = World { bounds: [-40.0, -40.0, 40.0, 40.0], ..World::default() };
        let route = vec![Point2::new(-20.0, 0.0), Point2::new(20.0, 0.0)];
        let people = People::new(3, 1.2, 10, &world, std::slice::from_ref(&route), 7);
        for k in 0..3 {
            let (a, b) = (people.position(k, 10.0).unwrap(), people.position(k, 10.5).unwrap());
            // On a straight leg the step is the speed × time; at a corner it is shorter.
            assert!((b - a).norm() <= 0.6 + 1e-9, "{}", (b - a).norm());
            assert!(a.y.abs() <= ROUTE_OFFSET_M + 1e-9, "{a}");
        }
        let moved =
            (0..3).filter(|k| (people.position(*k, 10.5).unwrap() - people.position(*k, 10.0).unwrap()).norm() > 0.59);
        assert!(moved.count() >= 2, "most steps are on straight legs");
        let again = People::new(3, 1.2, 10, &world, &[route], 7);
        assert_eq!(again.position(1, 33.0), people.position(1, 33.0), "seeded");
        let mut world = world;
        people.place(&mut world, 1.0);
        people.place(&mut world, 2.0);
        assert_eq!(world.solids.len(), 3, "the previous positions are replaced");
        assert!(world.solids.iter().all(|s| s.label == 10));
        people.remove(&mut world);
        assert!(world.solids.is_empty());
    }
}
