//! Where each robot is: constant speed along its waypoints, heading along the current leg,
//! stationary before its start time... (it is off) and after its last waypoint. On terrain or
//! on legs, its `sim::platform::Motion` turns that planar track into the body's 6-DoF pose.

use crate::scenario::RobotSpec;
use crate::sim::platform::Motion;
use nalgebra::{Point2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sgm_model::geometry::{pose_from_yaw_translation, Pose3};

#[derive(Clone, Debug)]
pub struct Route {
    pub points: Vec<Point2<f64>>,
    pub speed_mps: f64,
    pub start_s: f64,
    pub height_m: f64,
    /// The body on the terrain; none: level at `height_m` above the plane z = 0.
    pub motion: Option<std::sync::Arc<Motion>>,
}

impl Route {
    /// The robot's route: its waypoints, or a generated one (seeded per robot).
    pub fn of(spec: &RobotSpec, robot: usize, seed: u64) -> Self {
        let points = match &spec.route {
            Some(route) => {
                let mut rng = ChaCha8Rng::seed_from_u64(seed ^ (0x0052_4f55_5445 + robot as u64));
                let [x0, y0, x1, y1] = route.region_m;
                (0..=route.legs).map(|_| Point2::new(rng.random_range(x0..x1), rng.random_range(y0..y1))).collect()
            }
            None => spec.waypoints.iter().map(|p| Point2::new(p[0], p[1])).collect(),
        };
        Self { points, speed_mps: spec.speed_mps, start_s: spec.start_s, height_m: spec.sensor_height_m, motion: None }
    }

    /// The route driven with `motion` (kept only when it is more than the planar track).
    pub fn with_motion(mut self, motion: Motion) -> Self {
        self.motion = (!motion.is_planar()).then(|| std::sync::Arc::new(motion));
        self
    }

    pub fn length_m(&self) -> f64 {
        self.points.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
    }

    /// True pose of the body (sensor) at time `t`; `None` before the robot starts.
    pub fn pose_at(&self, t: f64) -> Option<Pose3> {
        if t < self.start_s || self.points.len() < 2 {
            return None;
        }
        let mut s = (t - self.start_s) * self.speed_mps;
        let last = self.points.len() - 2;
        for (k, w) in self.points.windows(2).enumerate() {
            let d = w[1] - w[0];
            let len = d.norm();
            if len < 1e-9 && k < last {
                continue;
            }
            if s <= len || k == last {
                let p = w[0] + d * (s.min(len) / len.max(1e-9));
                let yaw = d.y.atan2(d.x);
                return Some(match &self.motion {
                    Some(motion) => motion.pose(p, yaw, t, s < len && self.speed_mps > 0.0),
                    None => pose_from_yaw_translation(yaw, Vector3::new(p.x, p.y, self.height_m)),
                });
            }
            s -= len;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_speed_along_the_legs_then_stopped() {
        let spec =
            RobotSpec { waypoints: vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]], start_s: 2.0, ..RobotSpec::default() };
        let r = Route::of(&spec, 0, 1);
        assert!(r.pose_at(1.0).is_none());
        let p = r.pose_at(2.0 + 10.0 / 1.5 + 2.0).unwrap();
        assert!((p.translation.vector - Vector3::new(10.0, 3.0, 0.8)).norm() < 1e-9);
        assert!((sgm_model::geometry::yaw_of(&p) - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        let end = r.pose_at(1e6).unwrap();
        assert!((end.translation.vector - Vector3::new(10.0, 10.0, 0.8)).norm() < 1e-9);
    }
}
