//! The IMU (`[imu]`): gyroscope and accelerometer samples at `rate_hz`, consistent with the
//! body's true motion, with white noise and bias random walks (the continuous-time densities of
//! a datasheet or a Kalibr calibration; the defaults are EuRoC's ADIS16448).
//!
//! The true motion is taken from the truth poses at the sample ticks t_k = k·Δt:
//!
//!   ω_k = Log(R_kᵀ R_{k+1}) / Δt                    (body rate over [t_k, t_{k+1}])
//!   a_k = (p_{k+1} − 2 p_k + p_{k−1}) / Δt²         (world acceleration)
//!   f_k = R_kᵀ (a_k + g ẑ)                           (specific force: at rest it reads +g up)
//!
//! so that strapdown integration — R_{k+1} = R_k Exp(ω_k Δt), v_k = v_{k−1} + (R_k f_k − g ẑ) Δt,
//! p_{k+1} = p_k + v_k Δt, the odometry's propagation (`sgm_model::odometry::propagation`) —
//! gives back the truth exactly when the noise is off (the test).
//! Measured: ω̃ = ω + b_g + n_g, f̃ = f + b_a + n_a, n ~ N(0, σ²·rate) per sample, and each
//! bias steps by N(0, σ_b²·Δt) per sample from its turn-on value, drawn per axis from
//! N(0, σ_on²) (`gyro_turn_on_bias`, `accel_turn_on_bias`) by the robot's own seeded stream.

use crate::scenario::ImuSpec;
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use sgm_model::geometry::Pose3;

pub use sgm_model::perception::imu::ImuSample;

/// A robot's IMU: its biases now, and the next tick it samples.
#[derive(Clone, Debug)]
pub struct Imu {
    spec: ImuSpec,
    gyro_bias: Vector3<f64>,
    accel_bias: Vector3<f64>,
    next_tick: i64,
}

/// Salts the turn-on biases' stream, apart from every other stream of the robot.
const TURN_ON_SALT: u64 = 0x1A0B_1A50;

impl Imu {
    /// Robot `robot`'s IMU in the scenario of `seed`, powered up: its biases at their turn-on
    /// values (zero when the spec has none; drawing them leaves every other stream as it was).
    pub fn new(spec: &ImuSpec, seed: u64, robot: usize) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ TURN_ON_SALT ^ ((robot as u64 + 1) << 32));
        let mut draw = |sigma: f64| {
            let unit: Vector3<f64> = Vector3::from_fn(|_, _| StandardNormal.sample(&mut rng));
            unit * sigma
        };
        let gyro_bias = draw(spec.gyro_turn_on_bias);
        let accel_bias = draw(spec.accel_turn_on_bias);
        Self { spec: spec.clone(), gyro_bias, accel_bias, next_tick: 0 }
    }

    pub fn interval_s(&self) -> f64 {
        1.0 / self.spec.rate_hz
    }

    /// The biases now (gyro rad/s, accelerometer m/s²).
    pub fn biases(&self) -> (Vector3<f64>, Vector3<f64>) {
        (self.gyro_bias, self.accel_bias)
    }

    /// The noise-free sample at tick `k` from the truth (`None` where the truth is unknown).
    pub fn true_sample(&self, k: i64, truth: &impl Fn(f64) -> Option<Pose3>) -> Option<ImuSample> {
        let dt = self.interval_s();
        let at = |k: i64| truth(k as f64 * dt);
        let (before, now, after) = (at(k - 1)?, at(k)?, at(k + 1)?);
        let turn = now.rotation.inverse() * after.rotation;
        let angular_velocity = turn.scaled_axis() / dt;
        let (p0, p1, p2) = (before.translation.vector, now.translation.vector, after.translation.vector);
        let acceleration = (p2 - 2.0 * p1 + p0) / (dt * dt);
        let specific_force = now.rotation.inverse() * (acceleration + Vector3::z() * self.spec.gravity_mps2);
        Some(ImuSample { stamp: k as f64 * dt, angular_velocity, specific_force })
    }

    /// Every sample with stamp ≤ `until` not given before, measured (noise and biases added).
    pub fn samples_until(
        &mut self,
        until: f64,
        truth: &impl Fn(f64) -> Option<Pose3>,
        rng: &mut impl Rng,
    ) -> Vec<ImuSample> {
        let dt = self.interval_s();
        let s = &self.spec;
        let white = |density: f64| density * s.rate_hz.sqrt();
        let walk = |density: f64| density * dt.sqrt();
        let mut out = Vec::new();
        while self.next_tick as f64 * dt <= until + 1e-9 * dt {
            let k = self.next_tick;
            self.next_tick += 1;
            let Some(sample) = self.true_sample(k, truth) else { continue };
            let mut normal = || Vector3::from_fn(|_, _| StandardNormal.sample(rng));
            let gyro_noise = normal() * white(s.gyro_noise);
            let accel_noise = normal() * white(s.accel_noise);
            out.push(ImuSample {
                angular_velocity: sample.angular_velocity + self.gyro_bias + gyro_noise,
                specific_force: sample.specific_force + self.accel_bias + accel_noise,
                ..sample
            });
            self.gyro_bias += normal() * walk(s.gyro_bias_walk);
            self.accel_bias += normal() * walk(s.accel_bias_walk);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::{Platform, PlatformsSpec, RobotSpec, TerrainSpec};
    use crate::sim::platform::Motion;
    use crate::sim::terrain::Terrain;
    use crate::sim::trajectory::Route;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use sgm_model::odometry::propagation::NavState;
    use std::sync::Arc;

    /// A legged robot walking a square on 10° hills: roll, pitch, bounce and turns.
    fn route() -> Route {
        let terrain = TerrainSpec { max_slope_deg: 10.0, ..TerrainSpec::default() };
        let terrain = Arc::new(Terrain::generate(&terrain, [-30.0, -30.0, 30.0, 30.0], 2));
        let spec = RobotSpec {
            waypoints: vec![[-10.0, -10.0], [10.0, -10.0], [10.0, 10.0], [-10.0, 10.0]],
            platform: Platform::Legged,
            ..RobotSpec::default()
        };
        let motion = Motion::new(terrain, Platform::Legged, &PlatformsSpec::default(), 0.5, 0, 2);
        Route::of(&spec, 0, 2, &PlatformsSpec::default()).with_motion(motion)
    }

    #[test]
    fn noise_free_samples_integrate_back_to_the_truth() {
        let spec = ImuSpec {
            gyro_noise: 0.0,
            gyro_bias_walk: 0.0,
            accel_noise: 0.0,
            accel_bias_walk: 0.0,
            ..ImuSpec::default()
        };
        let route = route();
        let truth = |t: f64| route.pose_at(t);
        let mut imu = Imu::new(&spec, 1, 0);
        let samples = imu.samples_until(30.0, &truth, &mut ChaCha8Rng::seed_from_u64(1));
        let dt = imu.interval_s();
        assert_eq!(samples.len(), 6000, "from t = Δt (tick 0 has no pose before it) to 30 s");
        let start = truth(samples[0].stamp).expect("truth");
        let before = truth(samples[0].stamp - dt).expect("truth");
        let velocity = (start.translation.vector - before.translation.vector) / dt;
        // Integrated by the odometry's own propagation (`sgm_model::odometry::propagation`).
        let mut state = NavState { velocity, ..NavState::at_rest(start.rotation, start.translation.vector) };
        let mut worst = (0.0f64, 0.0f64);
        for s in &samples {
            state = state.propagated(s, dt, spec.gravity_mps2);
            let expected = truth(s.stamp + dt).expect("truth");
            worst.0 = worst.0.max((state.position - expected.translation.vector).norm());
            worst.1 = worst.1.max(state.rotation.angle_to(&expected.rotation));
        }
        assert!(worst.0 < 1e-6 && worst.1 < 1e-9, "after 30 s: {worst:?}");
        // Standing still it reads gravity, up in the body.
        let end = imu.true_sample(100_000, &truth).expect("stopped");
        assert!(end.angular_velocity.norm() < 1e-12);
        let up = truth(500.0).expect("truth").rotation.inverse() * Vector3::z() * spec.gravity_mps2;
        assert!((end.specific_force - up).norm() < 1e-9, "{}", end.specific_force);
    }

    #[test]
    fn noise_and_bias_walks_have_their_datasheet_densities() {
        let spec = ImuSpec::default();
        let truth = |_: f64| Some(Pose3::identity());
        let mut imu = Imu::new(&spec, 1, 0);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let samples = imu.samples_until(200.0, &truth, &mut rng);
        let n = samples.len() as f64;
        // White noise: per-sample σ = density·√rate (the bias is small against it over 200 s).
        let variance = samples.iter().map(|s| s.angular_velocity.x.powi(2)).sum::<f64>() / n;
        let expected = spec.gyro_noise * spec.rate_hz.sqrt();
        assert!((variance.sqrt() / expected - 1.0).abs() < 0.05, "{} vs {expected}", variance.sqrt());
        // Bias walks: after T seconds each axis has variance σ_b²·T; over 400 robots of 50 s.
        let mut spread = 0.0;
        for seed in 0..400 {
            let mut imu = Imu::new(&spec, 1, 0);
            imu.samples_until(50.0, &truth, &mut ChaCha8Rng::seed_from_u64(seed));
            spread += imu.biases().1.x.powi(2);
        }
        let expected = spec.accel_bias_walk.powi(2) * 50.0;
        assert!((spread / 400.0 / expected - 1.0).abs() < 0.2, "{} vs {expected}", spread / 400.0);
    }

    #[test]
    fn turn_on_biases_are_each_robots_own_and_have_their_spread() {
        let truth = |_: f64| Some(Pose3::identity());
        // None by default: the biases start at zero.
        assert_eq!(Imu::new(&ImuSpec::default(), 3, 1).biases(), (Vector3::zeros(), Vector3::zeros()));
        let spec = ImuSpec { gyro_turn_on_bias: 0.002, accel_turn_on_bias: 0.05, ..ImuSpec::default() };
        // Drawn per axis from N(0, σ²): over 500 robots, each axis's spread is σ.
        let (mut gyro, mut accel) = (Vector3::zeros(), Vector3::zeros());
        for robot in 0..500 {
            let (g, a) = Imu::new(&spec, 7, robot).biases();
            gyro += g.component_mul(&g);
            accel += a.component_mul(&a);
        }
        for axis in 0..3 {
            assert!(((gyro[axis] / 500.0).sqrt() / 0.002 - 1.0).abs() < 0.1, "gyro {gyro}");
            assert!(((accel[axis] / 500.0).sqrt() / 0.05 - 1.0).abs() < 0.1, "accel {accel}");
        }
        // Each robot its own, the same at every run; the seed changes them.
        assert_ne!(Imu::new(&spec, 7, 0).biases(), Imu::new(&spec, 7, 1).biases());
        assert_eq!(Imu::new(&spec, 7, 0).biases(), Imu::new(&spec, 7, 0).biases());
        assert_ne!(Imu::new(&spec, 7, 0).biases(), Imu::new(&spec, 8, 0).biases());
        // The samples carry it: at rest the mean rate is the gyro's turn-on bias; the white
        // noise leaves the mean of 10 s at 200 Hz within 5.4e-5 rad/s per axis (1σ).
        let quiet = ImuSpec { gyro_bias_walk: 0.0, ..spec.clone() };
        let mut imu = Imu::new(&quiet, 7, 0);
        let (start, _) = imu.biases();
        let samples = imu.samples_until(10.0, &truth, &mut ChaCha8Rng::seed_from_u64(1));
        let mean = samples.iter().map(|s| s.angular_velocity).sum::<Vector3<f64>>() / samples.len() as f64;
        assert!(start.norm() > 1e-3 && (mean - start).norm() < 3e-4, "{mean} vs {start}");
        // The other streams are untouched: without the walk and noise the samples differ from
        // an unbiased IMU's by the turn-on biases exactly.
        let silent = ImuSpec { gyro_noise: 0.0, accel_noise: 0.0, accel_bias_walk: 0.0, ..quiet };
        let unbiased = ImuSpec { gyro_turn_on_bias: 0.0, accel_turn_on_bias: 0.0, ..silent.clone() };
        let mut biased = Imu::new(&silent, 7, 0);
        let (g, a) = biased.biases();
        let with = biased.samples_until(0.5, &truth, &mut ChaCha8Rng::seed_from_u64(2));
        let without = Imu::new(&unbiased, 7, 0).samples_until(0.5, &truth, &mut ChaCha8Rng::seed_from_u64(2));
        for (w, o) in with.iter().zip(&without) {
            assert!((w.angular_velocity - o.angular_velocity - g).norm() < 1e-15);
            assert!((w.specific_force - o.specific_force - a).norm() < 1e-15);
        }
    }
}
