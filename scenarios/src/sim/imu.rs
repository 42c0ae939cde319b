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
//! bias steps by N(0, σ_b²·Δt) per sample.

use crate::scenario::ImuSpec;
use nalgebra::Vector3;
use rand::Rng;
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

impl Imu {
    pub fn new(spec: &ImuSpec) -> Self {
        Self { spec: spec.clone(), gyro_bias: Vector3::zeros(), accel_bias: Vector3::zeros(), next_tick: 0 }
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
        let mut imu = Imu::new(&spec);
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
        let mut imu = Imu::new(&spec);
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
            let mut imu = Imu::new(&spec);
            imu.samples_until(50.0, &truth, &mut ChaCha8Rng::seed_from_u64(seed));
            spread += imu.biases().1.x.powi(2);
        }
        let expected = spec.accel_bias_walk.powi(2) * 50.0;
        assert!((spread / 400.0 / expected - 1.0).abs() < 0.2, "{} vs {expected}", spread / 400.0);
    }
}
