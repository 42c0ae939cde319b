//! Odometry with drift, as a LiDAR-inertial odometry would report it: each step's true motion
//! plus random walks in position (m per √m travelled), height and yaw about gravity (° per √m), and a slowly
//! varying roll/pitch error (a first-order Gauss–Markov tilt that does not accumulate). The
//! robot's world frame is where it started: its start position on the ground, its start
//! heading along x.

use crate::scenario::OdometrySpec;
use nalgebra::{Unit, UnitQuaternion, Vector3};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use sgm_model::geometry::{pose_from_yaw_translation, yaw_of, Pose3};

pub struct Odometry {
    spec: OdometrySpec,
    last_truth: Option<Pose3>,
    estimate: Pose3,
    tilt: [f64; 2],
    /// p_true = truth_from_world · p_world.
    pub truth_from_world: Pose3,
}

/// Correlation of the tilt error from one frame to the next.
const TILT_MEMORY: f64 = 0.95;

impl Odometry {
    pub fn new(spec: &OdometrySpec) -> Self {
        Self {
            spec: spec.clone(),
            last_truth: None,
            estimate: Pose3::identity(),
            tilt: [0.0; 2],
            truth_from_world: Pose3::identity(),
        }
    }

    /// The odometry's report for the body's true pose `truth` (world_from_body in the robot's
    /// world frame).
    pub fn step(&mut self, truth: &Pose3, rng: &mut impl Rng) -> Pose3 {
        let mut n = || -> f64 { StandardNormal.sample(rng) };
        match self.last_truth {
            None => {
                let t = truth.translation.vector;
                self.truth_from_world = pose_from_yaw_translation(yaw_of(truth), Vector3::new(t.x, t.y, 0.0));
                self.estimate = self.truth_from_world.inverse() * truth;
            }
            Some(last) => {
                let increment = last.inverse() * truth;
                let root = increment.translation.vector.norm().sqrt();
                let s = &self.spec;
                let mut noisy = increment;
                noisy.translation.vector += Vector3::new(
                    s.position_walk_m * root * n(),
                    s.position_walk_m * root * n(),
                    s.height_walk_m * root * n(),
                );
                // Heading drifts about gravity, as a gravity-aligned odometry's does: the axis is
                // the world's up seen from the previous body (its z only on level ground), so a
                // body on a slope gains no roll or pitch error from its heading noise.
                let yaw = s.yaw_walk_deg.to_radians() * root * n();
                let up_in_last = Unit::new_normalize(last.rotation.inverse() * Vector3::z());
                noisy.rotation = UnitQuaternion::from_axis_angle(&up_in_last, yaw) * noisy.rotation;
                if s.tilt_walk_deg > 0.0 {
                    // No gravity reference: roll and pitch errors accumulate, the frame tilts.
                    let sigma = s.tilt_walk_deg.to_radians() * root;
                    let (roll, pitch) = (sigma * n(), sigma * n());
                    noisy.rotation = UnitQuaternion::from_euler_angles(roll, pitch, 0.0) * noisy.rotation;
                }
                self.estimate *= noisy;
            }
        }
        self.last_truth = Some(*truth);
        let sigma = self.spec.roll_pitch_deg.to_radians() * (1.0 - TILT_MEMORY * TILT_MEMORY).sqrt();
        for k in 0..2 {
            self.tilt[k] = TILT_MEMORY * self.tilt[k] + sigma * n();
        }
        let mut reported = self.estimate;
        reported.rotation *= UnitQuaternion::from_euler_angles(self.tilt[0], self.tilt[1], 0.0);
        reported
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn noiseless_odometry_is_the_truth_in_the_start_frame() {
        let mut o = Odometry::new(&still());
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for k in 0..20 {
            let truth = pose_from_yaw_translation(0.3 + 0.1 * k as f64, Vector3::new(5.0 + k as f64, -2.0, 0.8));
            let reported = o.step(&truth, &mut rng);
            let e = sgm_model::geometry::pose_error(&(o.truth_from_world * reported), &truth);
            assert!(e.translation_m < 1e-9 && e.max_axis_rotation_deg() < 1e-9);
        }
        assert!((o.truth_from_world.translation.vector - Vector3::new(5.0, -2.0, 0.0)).norm() < 1e-12);
    }

    /// The pose each of 400 runs of 100 one-metre steps along x ends at, under `spec` (seeded).
    fn after_100_m(spec: &OdometrySpec, seed: u64) -> Vec<Pose3> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..400)
            .map(|_| {
                let mut o = Odometry::new(spec);
                let mut last = Pose3::identity();
                for k in 0..=100 {
                    last = o.step(&pose_from_yaw_translation(0.0, Vector3::new(k as f64, 0.0, 0.0)), &mut rng);
                }
                last
            })
            .collect()
    }

    /// No noise at all.
    fn still() -> OdometrySpec {
        OdometrySpec {
            position_walk_m: 0.0,
            yaw_walk_deg: 0.0,
            height_walk_m: 0.0,
            roll_pitch_deg: 0.0,
            tilt_walk_deg: 0.0,
            ..OdometrySpec::default()
        }
    }

    #[test]
    fn the_yaw_walk_grows_with_the_square_root_of_distance() {
        // At 0.1°/√m the yaw error's spread is σ·√100 = 1°.
        let ends = after_100_m(&OdometrySpec { yaw_walk_deg: 0.1, ..still() }, 2);
        let sd = (ends.iter().map(|p| yaw_of(p).to_degrees().powi(2)).sum::<f64>() / 400.0).sqrt();
        assert!((sd - 1.0).abs() < 0.1, "{sd}");
    }

    #[test]
    fn without_a_gravity_reference_the_frame_tilts_with_the_square_root_of_distance() {
        // At 0.1°/√m roll and pitch spread 1° each.
        let ends = after_100_m(&OdometrySpec { tilt_walk_deg: 0.1, ..still() }, 3);
        let sum_sq: f64 = ends
            .iter()
            .map(|p| {
                let (roll, pitch, _) = p.rotation.euler_angles();
                roll.to_degrees().powi(2) + pitch.to_degrees().powi(2)
            })
            .sum();
        let sd = (sum_sq / 800.0).sqrt();
        assert!((sd - 1.0).abs() < 0.1, "{sd}");
    }

    #[test]
    fn heading_drift_on_a_slope_leaves_gravity_where_it_is() {
        // Climbing a 10° slope sideways-tilted by 5°, with a large heading walk: the reported
        // attitude's up stays the true up (an IMU-aided odometry drifts in yaw, not in tilt).
        let spec = OdometrySpec { yaw_walk_deg: 0.5, ..still() };
        let mut o = Odometry::new(&spec);
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let attitude = UnitQuaternion::from_euler_angles(5f64.to_radians(), -10f64.to_radians(), 0.3);
        let mut worst: f64 = 0.0;
        for k in 0..=100 {
            let truth = Pose3::from_parts((attitude * Vector3::new(k as f64, 0.0, 0.0)).into(), attitude);
            let reported = o.truth_from_world * o.step(&truth, &mut rng);
            let up = |p: &Pose3| p.rotation.inverse() * Vector3::z();
            worst = worst.max(up(&reported).angle(&up(&truth)).to_degrees());
        }
        let heading = (o.truth_from_world * o.estimate).rotation.angle_to(&attitude).to_degrees();
        assert!(worst < 1e-6, "gravity moved by {worst}°");
        assert!(heading > 0.5, "the heading did drift: {heading}°");
    }
}
