//! IMU samples, and the body's rotation over part of a sweep from the gyroscope: a sample's rate
//! ω_k holds from its stamp t_k to the next's, so the body at t in the body at t₀ is
//!
//!   R(t₀ → t) = Exp(−ω_j (t₀ − t_j)) · Exp(ω_j Δt_j) ⋯ Exp(ω_i (t − t_i)),
//!
//! j the sample holding at t₀ and i the one holding at t: the cumulative products at the
//! samples' stamps are taken once, so each time costs one Exp. The gyro's bias is left in (a
//! MEMS gyro's few 1e-4 rad/s turn a 0.1 s sweep by 1e-5 rad). The rotation the deskew wants
//! between odometry poses a second apart, where a legged robot's gait rolls and pitches by a few
//! degrees at 2 Hz, comes from here; the translation from the odometry's velocity.

use nalgebra::{UnitQuaternion, Vector3};
use std::collections::VecDeque;

/// One IMU sample, body frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuSample {
    /// s, the scans' clock.
    pub stamp: f64,
    /// rad/s.
    pub angular_velocity: Vector3<f64>,
    /// Specific force (acceleration minus gravity), m/s².
    pub specific_force: Vector3<f64>,
}

/// Samples kept: this many seconds behind the newest.
pub const KEEP_S: f64 = 2.0;
/// Largest gap between two samples that the rotation bridges, s (a 100 Hz IMU missing a few).
pub const MAX_GAP_S: f64 = 0.05;
/// Largest rate a sample may carry, rad/s (a 2000 °/s gyro saturates at 35).
pub const MAX_RATE_RAD_S: f64 = 100.0;

/// What became of the samples handed in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct GyroCounts {
    pub kept: u64,
    /// Non-finite or beyond [`MAX_RATE_RAD_S`].
    pub invalid: u64,
    /// Not after the newest kept sample.
    pub out_of_order: u64,
}

/// The last [`KEEP_S`] of gyro samples, in stamp order.
#[derive(Clone, Debug, Default)]
pub struct GyroBuffer {
    samples: VecDeque<(f64, Vector3<f64>)>,
    counts: GyroCounts,
}

/// The body's rotations over an interval, from [`GyroBuffer::rotations_from`].
pub struct Rotations {
    t0: f64,
    /// (t_k, R(t₀ → t_k), ω_k) of the samples from the one holding at t₀ on.
    steps: Vec<(f64, UnitQuaternion<f64>, Vector3<f64>)>,
    until: f64,
}

impl Rotations {
    /// R(t₀ → t₀ + dt); none outside the interval the samples cover.
    pub fn at(&self, dt: f64) -> Option<UnitQuaternion<f64>> {
        let t = self.t0 + dt;
        if !(t.is_finite() && t >= self.t0 - 1e-9 && t <= self.until + 1e-9) {
            return None;
        }
        let k = self.steps.partition_point(|(tk, _, _)| *tk <= t).saturating_sub(1);
        let (tk, r, w) = self.steps.get(k)?;
        Some(r * UnitQuaternion::from_scaled_axis(w * (t - tk)))
    }
}

impl GyroBuffer {
    /// Keeps the valid samples of `samples` that come after the newest kept; forgets those
    /// older than [`KEEP_S`] behind the newest.
    pub fn extend(&mut self, samples: &[ImuSample]) {
        for s in samples {
            let w = s.angular_velocity;
            if !s.stamp.is_finite() || !w.iter().all(|c| c.is_finite()) || w.amax() > MAX_RATE_RAD_S {
                self.counts.invalid += 1;
            } else if self.samples.back().is_some_and(|(t, _)| s.stamp <= *t) {
                self.counts.out_of_order += 1;
            } else {
                self.samples.push_back((s.stamp, w));
                self.counts.kept += 1;
            }
        }
        if let Some(&(newest, _)) = self.samples.back() {
            while self.samples.front().is_some_and(|(t, _)| *t < newest - KEEP_S) {
                self.samples.pop_front();
            }
        }
    }

    pub fn counts(&self) -> GyroCounts {
        self.counts
    }

    /// The rotations from `t0` over the next `span_s`: none unless samples cover it (one at or
    /// before t₀, one at or after t₀ + span − [`MAX_GAP_S`], no gap wider than that).
    pub fn rotations_from(&self, t0: f64, span_s: f64) -> Option<Rotations> {
        let until = t0 + span_s;
        let first = self.samples.partition_point(|(t, _)| *t <= t0).checked_sub(1)?;
        let mut steps = Vec::new();
        let mut rotation = UnitQuaternion::identity();
        let (mut t_prev, mut w_prev) = self.samples[first];
        // R(t₀ → t_j) for the sample holding at t₀: backwards over (t₀ − t_j).
        rotation *= UnitQuaternion::from_scaled_axis(w_prev * (t_prev - t0));
        steps.push((t_prev, rotation, w_prev));
        for &(t, w) in self.samples.iter().skip(first + 1) {
            if t - t_prev > MAX_GAP_S {
                return None;
            }
            if t > until {
                break;
            }
            rotation *= UnitQuaternion::from_scaled_axis(w_prev * (t - t_prev));
            steps.push((t, rotation, w));
            (t_prev, w_prev) = (t, w);
        }
        (until - t_prev <= MAX_GAP_S).then_some(Rotations { t0, steps, until })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn sample(stamp: f64, w: Vector3<f64>) -> ImuSample {
        ImuSample { stamp, angular_velocity: w, specific_force: Vector3::z() * 9.81 }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// A constant rate: the rotation over any part of the covered interval is Exp(ω·dt),
        /// whatever the phase of t₀ against the samples (closed form).
        #[test]
        fn a_constant_rate_turns_the_body_by_its_exponential(
            w in prop::array::uniform3(-3.0f64..3.0),
            phase in 0.0f64..0.005,
            dt in 0.0f64..0.1,
        ) {
            let w = Vector3::from(w);
            let mut buffer = GyroBuffer::default();
            let samples: Vec<ImuSample> = (0..100).map(|k| sample(10.0 + f64::from(k) * 0.005, w)).collect();
            buffer.extend(&samples);
            let rotations = buffer.rotations_from(10.1 + phase, 0.1).expect("covered");
            let got = rotations.at(dt).expect("inside");
            let expected = UnitQuaternion::from_scaled_axis(w * dt);
            prop_assert!(got.angle_to(&expected) < 1e-9, "{} rad off", got.angle_to(&expected));
        }
    }

    /// A rate that changes from sample to sample (a roll oscillation): the piecewise product
    /// against the exact integral of a rate held constant per interval.
    #[test]
    fn a_varying_rate_is_integrated_piece_by_piece() {
        let rate = |k: i32| Vector3::new((f64::from(k) * 0.3).sin(), 0.0, 0.2);
        let mut buffer = GyroBuffer::default();
        let samples: Vec<ImuSample> = (0..40).map(|k| sample(f64::from(k) * 0.01, rate(k))).collect();
        buffer.extend(&samples);
        let rotations = buffer.rotations_from(0.105, 0.2).expect("covered");
        // 0.105 → 0.11 at rate(10), then 0.11 … 0.25 one interval each, then 0.25 → 0.255.
        let mut expected = UnitQuaternion::from_scaled_axis(rate(10) * 0.005);
        for k in 11..25 {
            expected *= UnitQuaternion::from_scaled_axis(rate(k) * 0.01);
        }
        expected *= UnitQuaternion::from_scaled_axis(rate(25) * 0.005);
        assert!(rotations.at(0.15).unwrap().angle_to(&expected) < 1e-12);
        assert!(rotations.at(0.25).is_none(), "beyond the span");
    }

    #[test]
    fn gaps_bad_samples_and_uncovered_intervals_give_no_rotation() {
        let mut buffer = GyroBuffer::default();
        let w = Vector3::new(0.0, 0.0, 1.0);
        buffer.extend(&[sample(0.0, w), sample(0.01, w), sample(0.2, w), sample(0.21, w)]);
        assert!(buffer.rotations_from(0.0, 0.1).is_none(), "a 0.19 s gap");
        assert!(buffer.rotations_from(-0.1, 0.05).is_none(), "before the first sample");
        assert!(buffer.rotations_from(0.2, 0.1).is_none(), "after the last");
        buffer.extend(&[sample(0.22, Vector3::new(f64::NAN, 0.0, 0.0)), sample(0.1, w), sample(0.23, w * 500.0)]);
        assert_eq!(buffer.counts(), GyroCounts { kept: 4, invalid: 2, out_of_order: 1 });
        buffer.extend(&[sample(5.0, w)]);
        assert!(buffer.rotations_from(0.0, 0.01).is_none(), "forgotten after KEEP_S");
    }
}
