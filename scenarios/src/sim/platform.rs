//! How a robot's body moves over the terrain (`[platforms]`, `robots.platform`): the route gives
//! where it is and where it heads, (x, y, ψ); the platform gives the full 6-DoF pose of the
//! body (the LiDAR's frame).
//!
//! - **Wheeled**: the four contacts at (±L/2, ±W/2) in the body rest on the ground, heights
//!   h_f, h_r (front, rear: mean of their pair) and h_l, h_r′ (left, right). Then
//!   pitch θ = −atan((h_f − h_r)/L) (nose up is negative about y), roll φ = atan((h_l − h_r′)/W),
//!   and the sensor sits at the contacts' mean height plus R(φ, θ, ψ)·(0, 0, sensor height).
//! - **Legged**: as wheeled, and while it walks the gait adds A·sin(2πft + φ₀) to roll,
//!   A·sin(4πft + φ₁) to pitch and b·sin(4πft + φ₂) to the height (f = `gait_hz`), with A and b
//!   scaled by how far it is under way (speed over cruise speed, or turn rate over the limit on
//!   the spot), so the gait grows from standing without a jump.
//! - **Handheld**: the ground's height under it, and on each of the six axes a sway of two
//!   seeded sines (0.2–0.5 Hz and 0.7–1.3 Hz, weights 0.6 and 0.4), also when standing.

use crate::scenario::{Platform, PlatformsSpec};
use crate::sim::terrain::Terrain;
use nalgebra::{Point2, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sgm_model::geometry::Pose3;
use std::f64::consts::TAU;
use std::sync::Arc;

/// One sway axis: two sines.
#[derive(Clone, Copy, Debug)]
struct Sway {
    slow_hz: f64,
    fast_hz: f64,
    slow_phase: f64,
    fast_phase: f64,
}

impl Sway {
    fn at(&self, t: f64) -> f64 {
        0.6 * (TAU * self.slow_hz * t + self.slow_phase).sin() + 0.4 * (TAU * self.fast_hz * t + self.fast_phase).sin()
    }
}

/// A robot's body on the terrain.
#[derive(Clone, Debug)]
pub struct Motion {
    terrain: Arc<Terrain>,
    platform: Platform,
    spec: PlatformsSpec,
    sensor_height_m: f64,
    gait_phases: [f64; 3],
    /// roll, pitch, yaw, x, y, z.
    sway: [Sway; 6],
}

impl Motion {
    /// Robot `robot`'s motion (its gait and sway phases seeded by `seed` and its index).
    pub fn new(
        terrain: Arc<Terrain>,
        platform: Platform,
        spec: &PlatformsSpec,
        sensor_height_m: f64,
        robot: usize,
        seed: u64,
    ) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ (0x504c_4154_464f_524d + robot as u64));
        let gait_phases = [rng.random_range(0.0..TAU), rng.random_range(0.0..TAU), rng.random_range(0.0..TAU)];
        let sway = [(); 6].map(|()| Sway {
            slow_hz: rng.random_range(0.2..0.5),
            fast_hz: rng.random_range(0.7..1.3),
            slow_phase: rng.random_range(0.0..TAU),
            fast_phase: rng.random_range(0.0..TAU),
        });
        Self { terrain, platform, spec: spec.clone(), sensor_height_m, gait_phases, sway }
    }

    /// Whether the body is the planar route at the sensor's height: flat ground, on wheels.
    pub fn is_planar(&self) -> bool {
        self.terrain.is_flat() && self.platform == Platform::Wheeled
    }

    /// The body's pose at `position` heading `yaw` at time `t`; `gait`: how far the robot is
    /// under way, 0 (standing: a legged robot does not sway) to 1 (at its speed or turn rate:
    /// the gait's full amplitude).
    pub fn pose(&self, position: Point2<f64>, yaw: f64, t: f64, gait: f64) -> Pose3 {
        let ground = |forward: f64, left: f64| {
            let (s, c) = yaw.sin_cos();
            self.terrain.height(position.x + c * forward - s * left, position.y + s * forward + c * left)
        };
        let (mut roll, mut pitch, mut yaw) = (0.0, 0.0, yaw);
        let mut offset = Vector3::zeros();
        let height;
        match self.platform {
            Platform::Wheeled | Platform::Legged => {
                let (l, w) = (self.spec.wheelbase_m / 2.0, self.spec.track_m / 2.0);
                let (fl, fr, rl, rr) = (ground(l, w), ground(l, -w), ground(-l, w), ground(-l, -w));
                pitch = -((fl + fr - rl - rr) / 2.0).atan2(self.spec.wheelbase_m);
                roll = ((fl + rl - fr - rr) / 2.0).atan2(self.spec.track_m);
                height = (fl + fr + rl + rr) / 4.0;
                if self.platform == Platform::Legged && gait > 0.0 {
                    let (a, phase) = (gait * self.spec.gait_amplitude_deg.to_radians(), TAU * self.spec.gait_hz * t);
                    roll += a * (phase + self.gait_phases[0]).sin();
                    pitch += a * (2.0 * phase + self.gait_phases[1]).sin();
                    offset.z += gait * self.spec.gait_bounce_m * (2.0 * phase + self.gait_phases[2]).sin();
                }
            }
            Platform::Handheld => {
                height = ground(0.0, 0.0);
                let (a, m) = (self.spec.sway_deg.to_radians(), self.spec.sway_m);
                roll += a * self.sway[0].at(t);
                pitch += a * self.sway[1].at(t);
                yaw += a * self.sway[2].at(t);
                offset += Vector3::new(self.sway[3].at(t), self.sway[4].at(t), self.sway[5].at(t)) * m;
            }
        }
        let rotation = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
        let sensor = Vector3::new(position.x, position.y, height) + rotation * Vector3::z() * self.sensor_height_m;
        Pose3::from_parts((sensor + offset).into(), rotation)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn on(terrain: Terrain, platform: Platform) -> Motion {
        Motion::new(Arc::new(terrain), platform, &PlatformsSpec::default(), 0.8, 0, 7)
    }

    /// A plane rising at `slope` along x.
    fn incline(slope: f64) -> Terrain {
        Terrain::sampled([-20.0, -20.0, 20.0, 20.0], |p| p.x * slope.tan())
    }

    #[test]
    fn on_flat_ground_a_wheeled_body_is_level_at_its_sensor_height() {
        let m = on(Terrain::flat(), Platform::Wheeled);
        assert!(m.is_planar());
        let p = m.pose(Point2::new(3.0, -1.0), 0.7, 12.0, 1.0);
        assert!((p.translation.vector - Vector3::new(3.0, -1.0, 0.8)).norm() < 1e-12);
        assert!(p.rotation.angle_to(&UnitQuaternion::from_euler_angles(0.0, 0.0, 0.7)) < 1e-12);
    }

    #[test]
    fn on_an_incline_the_body_takes_its_slope_in_closed_form() {
        let slope = 10f64.to_radians();
        let m = on(incline(slope), Platform::Wheeled);
        assert!(!m.is_planar());
        // Heading up the slope: pitched nose up by the slope (negative about y), no roll.
        let up = m.pose(Point2::new(2.0, 0.0), 0.0, 0.0, 1.0);
        let (roll, pitch, yaw) = up.rotation.euler_angles();
        assert!(roll.abs() < 1e-9 && (pitch + slope).abs() < 1e-9 && yaw.abs() < 1e-9, "{roll} {pitch} {yaw}");
        // The sensor is 0.8 m from the ground along the body's z.
        let ground = Vector3::new(2.0, 0.0, 2.0 * slope.tan());
        assert!((up.translation.vector - ground - up.rotation * Vector3::z() * 0.8).norm() < 1e-9);
        // Heading across it (slope rising to the right): rolled right side up, no pitch.
        let across = m.pose(Point2::new(2.0, 0.0), std::f64::consts::FRAC_PI_2, 0.0, 1.0);
        let (roll, pitch, _) = across.rotation.euler_angles();
        assert!((roll + slope).abs() < 1e-9 && pitch.abs() < 1e-9, "{roll} {pitch}");
    }

    #[test]
    fn a_legged_gait_oscillates_while_walking_only() {
        let m = on(Terrain::flat(), Platform::Legged);
        let amplitude = PlatformsSpec::default().gait_amplitude_deg.to_radians();
        let rolls: Vec<f64> = (0..200)
            .map(|k| m.pose(Point2::origin(), 0.0, f64::from(k) * 0.01, 1.0).rotation.euler_angles().0)
            .collect();
        let peak = rolls.iter().fold(0.0f64, |a, r| a.max(r.abs()));
        assert!(peak <= amplitude + 1e-9 && peak > 0.95 * amplitude, "{peak}");
        // Roll at 2 Hz: a period of 0.5 s.
        let period = m.pose(Point2::origin(), 0.0, 0.5, 1.0).rotation.euler_angles().0;
        assert!((period - rolls[0]).abs() < 1e-9);
        let standing = m.pose(Point2::origin(), 0.0, 0.3, 0.0);
        assert!((standing.translation.vector - Vector3::new(0.0, 0.0, 0.8)).norm() < 1e-12);
    }

    #[test]
    fn a_handheld_rig_sways_within_its_amplitudes_also_standing() {
        let m = on(Terrain::flat(), Platform::Handheld);
        let spec = PlatformsSpec::default();
        let (mut moved, mut turned) = (0.0f64, 0.0f64);
        for k in 0..2000 {
            let p = m.pose(Point2::origin(), 0.0, f64::from(k) * 0.05, 0.0);
            let (r, pi, y) = p.rotation.euler_angles();
            for a in [r, pi, y] {
                assert!(a.abs() <= spec.sway_deg.to_radians() + 1e-9);
                turned = turned.max(a.abs());
            }
            let d = p.translation.vector - Vector3::new(0.0, 0.0, 0.8);
            moved = moved.max(d.amax());
        }
        assert!(turned > 0.5 * spec.sway_deg.to_radians() && moved > 0.02, "{turned} {moved}");
        // The sway itself, and the 0.8 m lever of the tilt (at most √2·a of roll and pitch).
        let lever = 0.8 * std::f64::consts::SQRT_2 * spec.sway_deg.to_radians();
        assert!(moved <= spec.sway_m + lever + 1e-9, "{moved}");
    }
}
