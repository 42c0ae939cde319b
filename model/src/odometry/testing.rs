//! A closed-form world for the odometry's tests: a box room (or a featureless corridor) with
//! box pillars, a legged robot's motion through it (turning, 2 Hz roll and pitch), the IMU
//! samples the simulator would build from that motion, and spinning-LiDAR sweeps ray-cast
//! analytically from the moving sensor, each return reported in the sensor frame of its instant.

use crate::geometry::Pose3;
use crate::perception::imu::ImuSample;
use nalgebra::{Point3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::f64::consts::TAU;

/// An axis-aligned box, [lo, hi].
#[derive(Clone, Copy, Debug)]
pub struct Aabb {
    pub lo: Vector3<f64>,
    pub hi: Vector3<f64>,
}

pub struct Scene {
    /// The inside of the room.
    pub room: Aabb,
    pub pillars: Vec<Aabb>,
}

impl Scene {
    /// A 30 × 20 × 4 m room with pillars of different sizes.
    pub fn room() -> Self {
        let b = |x: f64, y: f64, w: f64, d: f64, h: f64| Aabb {
            lo: Vector3::new(x - w / 2.0, y - d / 2.0, 0.0),
            hi: Vector3::new(x + w / 2.0, y + d / 2.0, h),
        };
        Self {
            room: Aabb { lo: Vector3::new(-15.0, -10.0, 0.0), hi: Vector3::new(15.0, 10.0, 4.0) },
            pillars: vec![
                b(-11.0, 7.0, 1.0, 1.0, 4.0),
                b(11.0, -7.5, 1.5, 0.8, 4.0),
                b(0.0, 0.0, 0.6, 2.5, 1.2),
                b(-4.0, -8.0, 2.0, 1.0, 2.0),
                b(6.0, 8.5, 0.8, 0.8, 3.0),
            ],
        }
    }

    /// A corridor along x, 3 m wide, far longer than the sensor's range: nothing varies along it.
    pub fn corridor() -> Self {
        Self {
            room: Aabb { lo: Vector3::new(-1000.0, -1.5, 0.0), hi: Vector3::new(1000.0, 1.5, 3.0) },
            pillars: Vec::new(),
        }
    }

    /// Distance along the unit ray from `o` to the first surface.
    pub fn cast(&self, o: &Point3<f64>, d: &Vector3<f64>) -> f64 {
        let mut best = f64::INFINITY;
        for k in 0..3 {
            if d[k].abs() > 1e-12 {
                let bound = if d[k] > 0.0 { self.room.hi[k] } else { self.room.lo[k] };
                best = best.min((bound - o[k]) / d[k]);
            }
        }
        for b in &self.pillars {
            let (mut near, mut far) = (f64::NEG_INFINITY, f64::INFINITY);
            for k in 0..3 {
                if d[k].abs() < 1e-12 {
                    if o[k] < b.lo[k] || o[k] > b.hi[k] {
                        near = f64::INFINITY;
                    }
                    continue;
                }
                let (a, c) = ((b.lo[k] - o[k]) / d[k], (b.hi[k] - o[k]) / d[k]);
                near = near.max(a.min(c));
                far = far.min(a.max(c));
            }
            if near <= far && near > 0.0 {
                best = best.min(near);
            }
        }
        best
    }
}

/// The legged robot's true pose at `t`: standing still until t = 1 s (as a LiDAR-inertial
/// odometry starts, FAST-LIO2's static initialisation), then walking a loop through the room at
/// ~1.5 m/s, or straight down the corridor, with a 2 Hz gait and bounce that start with it
/// (or, without `gait`, as smoothly as a wheeled robot on a flat floor).
pub fn truth(t: f64, corridor: bool, gait: bool) -> Pose3 {
    // Time along the path, s(t) = u − 1 + e^(−u) for u = t − 1 > 0: starts at rest, and with a
    // finite acceleration.
    let u = (t - 1.0).max(0.0);
    let s = u - 1.0 + (-u).exp();
    let pace = if gait { 1.0 - (-u).exp() } else { 0.0 };
    let gait = UnitQuaternion::from_euler_angles(pace * 0.03 * (12.0 * t).sin(), pace * 0.025 * (12.0 * t).cos(), 0.0);
    let bounce = pace * 0.02 * (25.0 * t).sin();
    if corridor {
        let yaw = UnitQuaternion::from_euler_angles(0.0, 0.0, 0.05 * (0.7 * s).sin());
        return Pose3::from_parts(Translation3::new(1.5 * s, 0.2 * (0.5 * s).sin(), 0.6 + bounce), yaw * gait);
    }
    let (x, y) = (9.0 * (0.15 * s).sin(), 6.0 * (0.3 * s).sin());
    let (dx, dy) = (9.0 * 0.15 * (0.15 * s).cos(), 6.0 * 0.3 * (0.3 * s).cos());
    let yaw = UnitQuaternion::from_euler_angles(0.0, 0.0, dy.atan2(dx));
    Pose3::from_parts(Translation3::new(x, y, 0.6 + bounce), yaw * gait)
}

/// IMU noise and constant biases to add (zero: exact samples).
#[derive(Clone, Copy, Debug, Default)]
pub struct ImuErrors {
    pub gyro_white: f64,
    pub accel_white: f64,
    pub gyro_bias: Vector3<f64>,
    pub accel_bias: Vector3<f64>,
}

/// A kerb stepped up: the body rises `height_m` within `duration_s` from `at_s` (a smoothstep,
/// whose peak acceleration 6 h / d² is a jolt no IMU's range holds: 0.3 m in 40 ms is 1 100 m/s²).
#[derive(Clone, Copy, Debug)]
pub struct Kerb {
    pub at_s: f64,
    pub height_m: f64,
    pub duration_s: f64,
}

impl Kerb {
    /// The body's rise at `t`.
    pub fn rise(&self, t: f64) -> f64 {
        let u = ((t - self.at_s) / self.duration_s).clamp(0.0, 1.0);
        self.height_m * u * u * (3.0 - 2.0 * u)
    }
}

pub struct Sensors {
    pub scene: Scene,
    pub corridor: bool,
    pub gait: bool,
    pub kerb: Option<Kerb>,
    /// Carried in a hand: the body sways at all times, also while its bearer stands.
    pub sway: bool,
    pub imu_dt: f64,
    pub errors: ImuErrors,
    rng: ChaCha8Rng,
    next_tick: i64,
}

/// A scan: points (sensor frame of each instant), their times after the stamp.
pub struct Sweep {
    pub points: Vec<Point3<f64>>,
    pub times: Vec<f32>,
}

pub const SWEEP_S: f64 = 0.1;
pub const GRAVITY: f64 = 9.81;

impl Sensors {
    pub fn new(corridor: bool, errors: ImuErrors, seed: u64) -> Self {
        let scene = if corridor { Scene::corridor() } else { Scene::room() };
        Self {
            scene,
            corridor,
            gait: true,
            kerb: None,
            sway: false,
            imu_dt: 0.005,
            errors,
            rng: ChaCha8Rng::seed_from_u64(seed),
            next_tick: 0,
        }
    }

    pub fn truth(&self, t: f64) -> Pose3 {
        let rise = self.kerb.map_or(0.0, |k| k.rise(t));
        let body = Translation3::new(0.0, 0.0, rise) * truth(t, self.corridor, self.gait);
        if !self.sway {
            return body;
        }
        // A hand's sway: 3° and 3 cm on every axis, at 0.35 and 0.9 Hz (the simulator's
        // handheld platform), about the body's own point.
        let wave = |phase: f64| 0.6 * (TAU * 0.35 * t + phase).sin() + 0.4 * (TAU * 0.9 * t + 2.0 * phase).sin();
        let a = 3f64.to_radians();
        let turn = UnitQuaternion::from_euler_angles(a * wave(0.0), a * wave(1.0), a * wave(2.0));
        let shift = Vector3::new(wave(3.0), wave(4.0), wave(5.0)) * 0.03;
        Pose3::from_parts(Translation3::from(body.translation.vector + shift), body.rotation * turn)
    }

    /// The samples with stamps up to `until` not given before (the simulator's construction).
    pub fn imu_until(&mut self, until: f64) -> Vec<ImuSample> {
        let dt = self.imu_dt;
        let mut out = Vec::new();
        while self.next_tick as f64 * dt <= until + 1e-9 {
            let k = self.next_tick;
            self.next_tick += 1;
            let at = |k: i64| self.truth(k as f64 * dt);
            let (before, now, after) = (at(k - 1), at(k), at(k + 1));
            let w = (now.rotation.inverse() * after.rotation).scaled_axis() / dt;
            let a = (after.translation.vector - 2.0 * now.translation.vector + before.translation.vector) / (dt * dt);
            let f = now.rotation.inverse() * (a + Vector3::z() * GRAVITY);
            let e = self.errors;
            let mut white = |density: f64| Vector3::from_fn(|_, _| gaussian(&mut self.rng) * density / dt.sqrt());
            out.push(ImuSample {
                stamp: k as f64 * dt,
                angular_velocity: w + e.gyro_bias + white(e.gyro_white),
                specific_force: f + e.accel_bias + white(e.accel_white),
            });
        }
        out
    }

    /// A 16-beam spinning sweep (±15°, 1° columns) starting at `stamp`.
    pub fn sweep(&self, stamp: f64) -> Sweep {
        let columns = 360;
        let (mut points, mut times) = (Vec::new(), Vec::new());
        for c in 0..columns {
            let tau = c as f64 / columns as f64 * SWEEP_S;
            let pose = self.truth(stamp + tau);
            let origin = Point3::from(pose.translation.vector);
            let azimuth = (c as f64).to_radians();
            for r in 0..16 {
                let elevation = (-15.0 + 2.0 * r as f64).to_radians();
                let local =
                    Vector3::new(elevation.cos() * azimuth.cos(), elevation.cos() * azimuth.sin(), elevation.sin());
                let d = pose.rotation * local;
                let range = self.scene.cast(&origin, &d);
                if range.is_finite() && range < 40.0 {
                    points.push(Point3::from(local * range));
                    times.push(tau as f32);
                }
            }
        }
        Sweep { points, times }
    }
}

/// A standard normal draw (Box–Muller).
fn gaussian(rng: &mut impl Rng) -> f64 {
    let u: f64 = rng.random_range(f64::EPSILON..1.0);
    let v: f64 = rng.random_range(0.0..1.0);
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}
