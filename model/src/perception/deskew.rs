//! Motion compensation of a LiDAR sweep ("deskewing"). A spinning or Livox sensor measures its
//! points one after another while it moves; a driver reports each in the sensor frame *of its
//! own instant*, so a scan taken on the move is bent. With each point's time τᵢ (seconds after
//! the scan's stamp) and the body's motion over the sweep as a constant twist ξ (body frame,
//! per second: the body at stamp + τ is Exp(τ·ξ) in the body at the stamp), the point in the
//! frame of the stamp is
//!
//!   pᵢ' = Exp(τᵢ·ξ) · pᵢ
//!
//! (KISS-ICP's constant-velocity deskew, with the twist from consecutive odometry poses:
//! ξ = Log(odom(t₀)⁻¹ · odom(t₁)) / (t₁ − t₀), [`super::motion`]). With an IMU whose samples
//! cover the sweep, the rotation comes from the gyro instead ([`super::imu`]) and the
//! translation from the twist's velocity v (body frame):
//!
//!   pᵢ' = R(τᵢ) · pᵢ + v·τᵢ
//!
//! which follows a legged robot's gait (a few degrees of roll and pitch at 2 Hz) that odometry
//! poses far apart average away.

use crate::geometry::lie::{se3_exp, Tangent3};
use crate::geometry::Pose3;
use crate::perception::imu::GyroBuffer;
use nalgebra::{Point3, Translation3, UnitQuaternion, Vector3};

/// Why a scan was not deskewed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum DeskewRefusal {
    #[error("the scan carries no per-point time")]
    NoTimes,
    #[error("{times} point times for {points} points")]
    TimesMismatch { points: usize, times: usize },
    #[error("a point time is not finite or is farther than {MAX_SWEEP_S} s from the stamp")]
    TimeOutOfRange,
    #[error("no motion known yet (the first scan, or no earlier odometry pose)")]
    NoMotion,
}

/// Point times farther from the stamp than this are refused (a sweep is ~0.1 s), s.
pub const MAX_SWEEP_S: f64 = 1.0;

/// When a sweep ends: its latest point's time after the stamp, s, at most 1 s (0 without
/// times, or when none is positive).
pub fn sweep_end_s(times: Option<&[f32]>) -> f64 {
    times.map_or(0.0, |t| t.iter().fold(0.0f64, |m, &x| m.max(f64::from(x))).min(1.0))
}

/// `points` measured at `times` (s after the stamp), moved into the body frame at the stamp
/// under the constant twist `twist`.
pub fn deskew(points: &[Point3<f64>], times: &[f32], twist: &Tangent3) -> Result<Vec<Point3<f64>>, DeskewRefusal> {
    deskew_with(points, times, |t| se3_exp(&(twist * f64::from(t))))
}

/// `points` measured at `times`, moved into the body frame at the stamp by `motion(τ)`, the body
/// at stamp + τ in the body at the stamp.
pub fn deskew_with(
    points: &[Point3<f64>],
    times: &[f32],
    mut motion: impl FnMut(f32) -> Pose3,
) -> Result<Vec<Point3<f64>>, DeskewRefusal> {
    if times.len() != points.len() {
        return Err(DeskewRefusal::TimesMismatch { points: points.len(), times: times.len() });
    }
    if times.iter().any(|t| !t.is_finite() || f64::from(t.abs()) > MAX_SWEEP_S) {
        return Err(DeskewRefusal::TimeOutOfRange);
    }
    // Points come in time order within a sweep: one motion per distinct time.
    let mut cached: Option<(f32, Pose3)> = None;
    Ok(points
        .iter()
        .zip(times)
        .map(|(p, &t)| {
            let m = match cached {
                Some((at, m)) if at == t => m,
                _ => {
                    let m = motion(t);
                    cached = Some((t, m));
                    m
                }
            };
            m * p
        })
        .collect())
}

/// The motion over a sweep with the gyro's rotation (`gyro` covering stamp + min τ … stamp +
/// max τ) and the translation at `velocity`; none when the gyro does not cover it.
fn gyro_motion(
    gyro: &GyroBuffer,
    stamp: f64,
    times: &[f32],
    velocity: Vector3<f64>,
) -> Option<impl FnMut(f32) -> Pose3> {
    let (lo, hi) = times.iter().fold((0.0f64, 0.0f64), |(lo, hi), t| (lo.min(f64::from(*t)), hi.max(f64::from(*t))));
    if !(lo.is_finite() && hi.is_finite()) || hi - lo > MAX_SWEEP_S {
        return None;
    }
    let rotations = gyro.rotations_from(stamp + lo, hi - lo)?;
    // R(stamp → stamp + τ) = R(t₀ → stamp)⁻¹ · R(t₀ → stamp + τ).
    let at_stamp = rotations.at(-lo)?.inverse();
    Some(move |t: f32| {
        let rotation = rotations.at(f64::from(t) - lo).map_or(UnitQuaternion::identity(), |r| at_stamp * r);
        Pose3::from_parts(Translation3::from(velocity * f64::from(t)), rotation)
    })
}

/// How many scans were deskewed, and why the others were not.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct DeskewCounts {
    pub deskewed: u64,
    /// Scans without per-point time, used as they came.
    pub no_times: u64,
    /// Scans with times but no motion known yet (the first one), used as they came.
    pub no_motion: u64,
    /// Scans whose times did not fit their points (count or range), used as they came.
    pub refused: u64,
    /// Of the deskewed, those whose rotation came from the gyro.
    pub with_imu: u64,
    /// Of the deskewed, those whose IMU samples did not cover the sweep (a gap, or samples not
    /// yet arrived): deskewed with the odometry's twist instead.
    pub imu_not_covering: u64,
    /// Scans deskewed before they came (by the internal odometry, from the IMU's propagation),
    /// not counted above.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub upstream: u64,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

/// The constant-velocity deskew of a stream of scans, counted: the twist over a scan's sweep is
/// the one from the odometry pose of the scan before it to this scan's (KISS-ICP's model,
/// [`super::motion::ConstantVelocity`]).
#[derive(Clone, Debug, Default)]
pub struct Deskewer {
    counts: DeskewCounts,
}

impl Deskewer {
    /// A scan deskewed under `twist` when its `times` and the motion allow; else as it came
    /// (counted, with the reason). With `gyro` (the IMU's samples and the scan's stamp) covering
    /// the sweep, the rotation is the gyro's and the translation the twist's velocity (none
    /// before the first twist).
    pub fn apply(
        &mut self,
        twist: Option<&Tangent3>,
        gyro: Option<(&GyroBuffer, f64)>,
        points: Vec<Point3<f64>>,
        times: Option<&[f32]>,
    ) -> (Vec<Point3<f64>>, Result<(), DeskewRefusal>) {
        let velocity = twist.map_or(Vector3::zeros(), |t| Vector3::new(t[3], t[4], t[5]));
        let from_gyro = match (gyro, times) {
            (Some((buffer, stamp)), Some(times)) => gyro_motion(buffer, stamp, times, velocity),
            _ => None,
        };
        let outcome = match (times, twist, from_gyro) {
            (None, _, _) => Err(DeskewRefusal::NoTimes),
            (Some(times), _, Some(motion)) => {
                let straight = deskew_with(&points, times, motion);
                if straight.is_ok() {
                    self.counts.with_imu += 1;
                }
                straight
            }
            (Some(_), None, None) => Err(DeskewRefusal::NoMotion),
            (Some(times), Some(twist), None) => {
                let straight = deskew(&points, times, twist);
                if straight.is_ok() && gyro.is_some() {
                    self.counts.imu_not_covering += 1;
                }
                straight
            }
        };
        match outcome {
            Ok(straight) => {
                self.counts.deskewed += 1;
                (straight, Ok(()))
            }
            Err(refusal) => {
                match refusal {
                    DeskewRefusal::NoTimes => self.counts.no_times += 1,
                    DeskewRefusal::NoMotion => self.counts.no_motion += 1,
                    DeskewRefusal::TimesMismatch { .. } | DeskewRefusal::TimeOutOfRange => self.counts.refused += 1,
                }
                (points, Err(refusal))
            }
        }
    }

    pub fn counts(&self) -> DeskewCounts {
        self.counts
    }

    /// Counts a scan deskewed before it came ([`DeskewCounts::upstream`]).
    pub fn count_upstream(&mut self) {
        self.counts.upstream += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_rpy_translation;
    use crate::perception::motion::ConstantVelocity;
    use nalgebra::Vector3;
    use proptest::prelude::*;

    /// The world's points seen by a sensor moving at `twist`: each measured at its time from
    /// the sensor's pose then (as a driver reports them).
    fn skewed(world: &[Point3<f64>], start: &Pose3, twist: &Tangent3, times: &[f32]) -> Vec<Point3<f64>> {
        world.iter().zip(times).map(|(p, t)| (start * se3_exp(&(twist * f64::from(*t)))).inverse() * p).collect()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Deskewing a sweep taken on the move gives the scan from the pose at the stamp.
        #[test]
        fn a_skewed_sweep_straightens_to_the_stamps_frame(
            w in prop::array::uniform3(-1.0f64..1.0),
            v in prop::array::uniform3(-3.0f64..3.0),
            x in -10.0f64..10.0,
            yaw in -3.0f64..3.0,
        ) {
            let twist = Tangent3::new(w[0], w[1], w[2], v[0], v[1], v[2]);
            let start = pose_from_rpy_translation(0.05, -0.03, yaw, Vector3::new(x, 2.0, 0.5));
            let world: Vec<Point3<f64>> =
                (0..200).map(|k| { let a = f64::from(k) * 0.0314; Point3::new(8.0 * a.cos(), 8.0 * a.sin(), f64::from(k % 7) - 3.0) }).collect();
            let times: Vec<f32> = (0..200).map(|k| k as f32 * 0.0005).collect();
            let measured = skewed(&world, &start, &twist, &times);
            let deskewed = deskew(&measured, &times, &twist).expect("times fit");
            for (d, p) in deskewed.iter().zip(&world) {
                let expected = start.inverse() * p;
                prop_assert!((d - expected).norm() < 1e-9, "{d} vs {expected}");
            }
        }
    }

    #[test]
    fn a_stream_is_deskewed_from_its_second_scan_at_the_odometry_velocity() {
        let twist = Tangent3::new(0.0, 0.0, 0.4, 2.0, 0.0, 0.0);
        let odom = |t: f64| se3_exp(&(twist * t));
        let world: Vec<Point3<f64>> = (0..50).map(|k| Point3::new(6.0, f64::from(k) * 0.2 - 5.0, 0.3)).collect();
        let times: Vec<f32> = (0..50).map(|k| k as f32 * 0.002).collect();
        let mut deskewer = Deskewer::default();
        let mut velocity = ConstantVelocity::default();
        for (k, stamp) in [1.0, 1.5, 2.0].into_iter().enumerate() {
            let measured = skewed(&world, &odom(stamp), &twist, &times);
            let v = velocity.update(stamp, &odom(stamp));
            let (points, outcome) = deskewer.apply(v.as_ref(), None, measured, Some(&times));
            if k == 0 {
                assert_eq!(outcome, Err(DeskewRefusal::NoMotion), "no earlier pose");
            } else {
                assert_eq!(outcome, Ok(()));
                for (p, w) in points.iter().zip(&world) {
                    assert!((p - odom(stamp).inverse() * w).norm() < 1e-9);
                }
            }
        }
        let v = velocity.update(2.5, &odom(2.5));
        let (_, outcome) = deskewer.apply(v.as_ref(), None, world.clone(), None);
        assert_eq!(outcome, Err(DeskewRefusal::NoTimes));
        let v = velocity.update(3.0, &odom(3.0));
        let (_, outcome) = deskewer.apply(v.as_ref(), None, world.clone(), Some(&times[..3]));
        assert!(matches!(outcome, Err(DeskewRefusal::TimesMismatch { .. })));
        assert_eq!(
            deskewer.counts(),
            DeskewCounts {
                deskewed: 2,
                no_times: 1,
                no_motion: 1,
                refused: 1,
                with_imu: 0,
                imu_not_covering: 0,
                upstream: 0
            }
        );
    }

    #[test]
    fn bad_times_are_refused() {
        let twist = Tangent3::new(0.0, 0.0, 0.2, 1.0, 0.0, 0.0);
        let points = [Point3::new(1.0, 0.0, 0.0)];
        assert_eq!(deskew(&points, &[], &twist), Err(DeskewRefusal::TimesMismatch { points: 1, times: 0 }));
        assert_eq!(deskew(&points, &[f32::NAN], &twist), Err(DeskewRefusal::TimeOutOfRange));
        assert_eq!(deskew(&points, &[5.0], &twist), Err(DeskewRefusal::TimeOutOfRange));
        // Time zero: the point stays.
        assert_eq!(deskew(&points, &[0.0], &twist).expect("fits"), points.to_vec());
    }

    /// A legged robot's sweep: walking at 1 m/s while its gait rolls it by 3° at 2 Hz. The gyro
    /// (sampled at 200 Hz from the true attitude) straightens it to the millimetre; the twist of
    /// odometry poses a second apart, which the gait averages away, leaves it bent by decimetres.
    #[test]
    fn the_gyro_follows_a_gait_that_odometry_a_second_apart_misses() {
        use crate::perception::imu::{GyroBuffer, ImuSample};
        let roll = |t: f64| 3f64.to_radians() * (std::f64::consts::TAU * 2.0 * t).sin();
        let body = |t: f64| {
            Pose3::from_parts(Translation3::new(t, 0.0, 0.0), UnitQuaternion::from_euler_angles(roll(t), 0.0, 0.0))
        };
        let stamp = 10.05;
        let world: Vec<Point3<f64>> = (0..400)
            .map(|k| {
                let a = f64::from(k) * std::f64::consts::TAU / 400.0;
                Point3::new(stamp + 15.0 * a.cos(), 15.0 * a.sin(), -0.5 + f64::from(k % 5) * 0.5)
            })
            .collect();
        let times: Vec<f32> = (0..400).map(|k| k as f32 * 0.00025).collect();
        let measured: Vec<Point3<f64>> =
            world.iter().zip(&times).map(|(p, t)| body(stamp + f64::from(*t)).inverse() * p).collect();
        let mut gyro = GyroBuffer::default();
        let dt = 0.005;
        let samples: Vec<ImuSample> = (1900..2200)
            .map(|k| {
                let t = f64::from(k) * dt;
                let turn = body(t).rotation.inverse() * body(t + dt).rotation;
                ImuSample { stamp: t, angular_velocity: turn.scaled_axis() / dt, specific_force: Vector3::zeros() }
            })
            .collect();
        gyro.extend(&samples);
        let twist =
            crate::perception::motion::twist_between(&body(stamp - 1.0), stamp - 1.0, &body(stamp), stamp).unwrap();
        let worst = |points: &[Point3<f64>]| {
            points.iter().zip(&world).map(|(p, w)| (p - body(stamp).inverse() * w).norm()).fold(0.0, f64::max)
        };
        let mut deskewer = Deskewer::default();
        let (with_gyro, outcome) = deskewer.apply(Some(&twist), Some((&gyro, stamp)), measured.clone(), Some(&times));
        assert_eq!(outcome, Ok(()));
        let (with_twist, _) = deskewer.apply(Some(&twist), None, measured.clone(), Some(&times));
        assert!(worst(&with_gyro) < 0.005, "gyro: {} m", worst(&with_gyro));
        assert!(worst(&with_twist) > 0.1, "twist: {} m", worst(&with_twist));
        assert_eq!((deskewer.counts().deskewed, deskewer.counts().with_imu), (2, 1));
        // A gyro that does not cover the sweep: the twist, counted as such.
        let (_, outcome) = deskewer.apply(Some(&twist), Some((&gyro, stamp + 5.0)), measured, Some(&times));
        assert_eq!((outcome, deskewer.counts().with_imu), (Ok(()), 1));
        assert_eq!(deskewer.counts().imu_not_covering, 1);
    }
}
