//! Where each robot is: switched on at its start time (before it, it is off), standing still
//! for `platforms.still_at_start_s`, then along its waypoints on the path of `sim::path` (legs
//! joined by arcs) at the speed of `sim::speed_profile` (from rest to rest, within the
//! platform's limits), heading along the path, and stopped at its last waypoint. On terrain or
//! on legs, its `sim::platform::Motion` turns that planar track into the body's 6-DoF pose.

use crate::scenario::{PlatformsSpec, RobotSpec};
use crate::sim::path::{self, Piece};
use crate::sim::platform::Motion;
use crate::sim::speed_profile::{Limits, Profile};
use nalgebra::{Point2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sgm_model::geometry::{pose_from_yaw_translation, Pose3};

#[derive(Clone, Debug)]
pub struct Route {
    /// The waypoints (the world is generated along them).
    pub points: Vec<Point2<f64>>,
    pub start_s: f64,
    pub height_m: f64,
    /// The body on the terrain; none: level at `height_m` above the plane z = 0.
    pub motion: Option<std::sync::Arc<Motion>>,
    pieces: Vec<Piece>,
    profile: Profile,
    sets_off_s: f64,
    limits: Limits,
}

impl Route {
    /// The robot's route: its waypoints, or a generated one (seeded per robot), driven within
    /// the `platforms` limits.
    pub fn of(spec: &RobotSpec, robot: usize, seed: u64, platforms: &PlatformsSpec) -> Self {
        let points: Vec<Point2<f64>> = match &spec.route {
            Some(route) => {
                let mut rng = ChaCha8Rng::seed_from_u64(seed ^ (0x0052_4f55_5445 + robot as u64));
                let [x0, y0, x1, y1] = route.region_m;
                (0..=route.legs).map(|_| Point2::new(rng.random_range(x0..x1), rng.random_range(y0..y1))).collect()
            }
            None => spec.waypoints.iter().map(|p| Point2::new(p[0], p[1])).collect(),
        };
        let limits = Limits {
            speed_mps: spec.speed_mps,
            accel_mps2: platforms.accel_mps2,
            yaw_rate_rps: platforms.yaw_rate_dps.to_radians(),
            yaw_accel_rps2: platforms.yaw_accel_dps2.to_radians(),
        };
        let pieces = path::through(&points, platforms.turn_radius_m);
        let profile = Profile::of(&pieces, &limits);
        Self {
            points,
            start_s: spec.start_s,
            height_m: spec.sensor_height_m,
            motion: None,
            pieces,
            profile,
            sets_off_s: spec.start_s + platforms.still_at_start_s,
            limits,
        }
    }

    /// The route driven with `motion` (kept only when it is more than the planar track).
    pub fn with_motion(mut self, motion: Motion) -> Self {
        self.motion = (!motion.is_planar()).then(|| std::sync::Arc::new(motion));
        self
    }

    /// When the robot is at its last waypoint, s.
    pub fn arrival_s(&self) -> f64 {
        self.sets_off_s + self.profile.duration_s()
    }

    /// True pose of the body (sensor) at time `t`; `None` before the robot starts. Waypoints that
    /// are all one point make no path: the robot stands there, heading along x.
    pub fn pose_at(&self, t: f64) -> Option<Pose3> {
        if t < self.start_s {
            return None;
        }
        let (p, yaw, gait) = match self.profile.at(t - self.sets_off_s) {
            Some(progress) => {
                let piece = self.pieces.get(progress.piece)?;
                let (p, yaw) = piece.at(progress.along);
                let top =
                    if matches!(piece, Piece::Spin { .. }) { self.limits.yaw_rate_rps } else { self.limits.speed_mps };
                (p, yaw, (progress.rate / top).clamp(0.0, 1.0))
            }
            None => (*self.points.first()?, 0.0, 0.0),
        };
        Some(match &self.motion {
            Some(motion) => motion.pose(p, yaw, t, gait),
            None => pose_from_yaw_translation(yaw, Vector3::new(p.x, p.y, self.height_m)),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn still_then_along_the_legs_round_the_corner_then_stopped() {
        let spec =
            RobotSpec { waypoints: vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]], start_s: 2.0, ..RobotSpec::default() };
        let r = Route::of(&spec, 0, 1, &PlatformsSpec::default());
        assert!(r.pose_at(1.0).is_none());
        // Switched on at 2 s, still until 4 s.
        for t in [2.0, 3.0, 4.0] {
            let p = r.pose_at(t).unwrap();
            assert!((p.translation.vector - Vector3::new(0.0, 0.0, 0.8)).norm() < 1e-12, "{t}");
        }
        // Then 1 m/s² from rest: 0.5 m after 1 s.
        assert!((r.pose_at(5.0).unwrap().translation.x - 0.5).abs() < 1e-9);
        // Half-way round the corner (r = 1 about (9, 1)), heading 45°.
        let (mut t0, mut t1) = (4.0, r.arrival_s());
        for _ in 0..100 {
            let mid = (t0 + t1) / 2.0;
            let yaw = sgm_model::geometry::yaw_of(&r.pose_at(mid).unwrap());
            if yaw < std::f64::consts::FRAC_PI_4 {
                t0 = mid;
            } else {
                t1 = mid;
            }
        }
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let p = r.pose_at(t0).unwrap().translation.vector;
        assert!((p - Vector3::new(9.0 + h, 1.0 - h, 0.8)).norm() < 1e-6, "{p}");
        let end = r.pose_at(r.arrival_s() + 1.0).unwrap();
        assert!((end.translation.vector - Vector3::new(10.0, 10.0, 0.8)).norm() < 1e-9);
        assert!((sgm_model::geometry::yaw_of(&end) - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn waypoints_that_are_one_point_park_the_robot_there() {
        let spec = RobotSpec { waypoints: vec![[3.0, 4.0], [3.0, 4.0]], ..RobotSpec::default() };
        let r = Route::of(&spec, 0, 1, &PlatformsSpec::default());
        for t in [0.0, 10.0, 100.0] {
            let p = r.pose_at(t).expect("on from its start");
            assert!((p.translation.vector - Vector3::new(3.0, 4.0, 0.8)).norm() < 1e-12, "{t}");
        }
    }
}
