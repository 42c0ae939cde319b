//! The IMU's samples between scans: checked as they arrive, and turned into the piecewise-constant
//! motion that propagation integrates (`propagation`).
//!
//! A sample (ω̃_k, f̃_k) holds from its stamp t_k to the next one's (the simulator's convention
//! and a driver's: the rate measured at t_k is the rate until the next measurement). The motion
//! from t₀ to t₁ is then a list of segments [s, e) each with the sample holding over it:
//!
//! ```text
//! [t₀, t_{j+1}) with sample j (the last with t_j ≤ t₀), [t_{j+1}, t_{j+2}) with j+1, …, [t_i, t₁)
//! ```
//!
//! A segment whose sample is older than `max_gap_s` at the segment's end is a *gap* (samples
//! lost, or not yet arrived). A stale sample is no evidence of the motion since — held through
//! a second of a legged gait, one instant's turn rate tilts the estimate by a tenth of a radian
//! and gravity leaks into the velocity — so across a gap, as before any sample, the robot
//! coasts at constant velocity: a sample that reads the state's own biases plus a turn rate
//! ω_c, f = Rᵀ g + b_a; the caller propagates it with the larger noise of a coasting robot.
//!
//! A *saturated* sample — at or beyond the gyro's or the accelerometer's full scale on some
//! axis — is what a real IMU reports when a jolt (a kerb, a stumble) exceeds its range: the
//! reading is clipped, and the true value lies beyond it by an amount nothing measured. It is
//! kept, clipped to the range (the nearest value the truth can have), and its segment says
//! which sensor saturated: the caller grows the uncertainty of what that sensor integrates by
//! the full scale over the jolt (`estimator`). Dropping it instead, and holding the sample
//! before over the jolt, left a 40 g kerb strike unintegrated: the velocity 1.4 m/s wrong with
//! the filter sure of it, and the robot sinking through the ground on `legged_campus` seed 3.
//!
//! Gravity at start (FAST-LIO2's static initialisation, §IV-B): the mean specific force f̄ over
//! the first samples points up in the body, so roll φ = atan2(f̄_y, f̄_z) and pitch
//! θ = atan2(−f̄_x, √(f̄_y² + f̄_z²)) level the odometry frame (yaw is free: it is set to 0).
//! When the body was still — the force's norm steady, the rate steady (its spread within the
//! gyro's noise) and small — the mean rate is the gyro's bias. A body that turned while the
//! samples were taken (a handheld rig sways even when its bearer stands) is levelled at the
//! window's end: each force is carried into the body's frame there by the rotation the gyro
//! measured since, f_k^end = Q_kᵀ f_k with Q_k = Exp(ω_k Δt_k) ⋯ Exp(ω_n Δt_n), and its rate
//! is not a bias. Taking a swaying rig's mean rate for the bias turned its estimate at 3°/s.

use super::propagation::{ImuNoise, NavState};
use crate::perception::imu::ImuSample;
use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// Samples kept waiting for their scan, at most (10 s at 1 kHz); beyond it the oldest go.
pub const MAX_PENDING: usize = 10_000;

/// What the IMU may read, and how long a sample may be held.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ImuLimits {
    /// A rate this large on any axis is the gyro's full scale: saturated, rad/s. Default 34.9
    /// (2000 °/s).
    pub gyro_range_rad_s: f64,
    /// A specific force this large on any axis is saturated, m/s². Default 156.9 (16 g).
    pub accel_range_mps2: f64,
    /// A sample held longer than this is a gap, s. Default 0.05 (a 200 Hz IMU missing 9).
    pub max_gap_s: f64,
}

impl Default for ImuLimits {
    fn default() -> Self {
        Self { gyro_range_rad_s: 34.9, accel_range_mps2: 156.9, max_gap_s: 0.05 }
    }
}

/// Why a sample is not kept.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImuDrop {
    /// A NaN or infinite stamp or value.
    NonFinite,
    /// At or beyond the gyro's or the accelerometer's range on some axis (the odometry keeps it,
    /// clipped: module notes).
    Saturated,
    /// Not after `newest` (time going backwards, or a repeat).
    OutOfOrder,
}

impl ImuLimits {
    /// `sample` clipped to the ranges, and which of its sensors reached them.
    pub fn clip(&self, sample: &ImuSample) -> (ImuSample, Saturation) {
        let clip = |v: &Vector3<f64>, range: f64| v.map(|c| c.clamp(-range, range));
        let saturation = Saturation {
            gyro: sample.angular_velocity.amax() >= self.gyro_range_rad_s,
            accel: sample.specific_force.amax() >= self.accel_range_mps2,
        };
        let clipped = ImuSample {
            angular_velocity: clip(&sample.angular_velocity, self.gyro_range_rad_s),
            specific_force: clip(&sample.specific_force, self.accel_range_mps2),
            ..*sample
        };
        (clipped, saturation)
    }

    /// What the odometry makes of `sample` after a kept sample stamped `newest` (`sgm doctor`
    /// asks the same of a recording): `None` kept as it is, `Saturated` kept clipped, the
    /// others dropped.
    pub fn screen(&self, sample: &ImuSample, newest: Option<f64>) -> Option<ImuDrop> {
        let values = || sample.angular_velocity.iter().chain(sample.specific_force.iter());
        if !(sample.stamp.is_finite() && values().all(|v| v.is_finite())) {
            Some(ImuDrop::NonFinite)
        } else if newest.is_some_and(|t| sample.stamp <= t) {
            Some(ImuDrop::OutOfOrder)
        } else if sample.angular_velocity.amax() >= self.gyro_range_rad_s
            || sample.specific_force.amax() >= self.accel_range_mps2
        {
            Some(ImuDrop::Saturated)
        } else {
            None
        }
    }
}

/// What became of the samples handed in, and of the time between them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ImuCounts {
    pub kept: u64,
    /// A NaN or infinite value: dropped.
    pub non_finite: u64,
    /// At or beyond the range on some axis: kept clipped to it, its segment marked (module
    /// notes); not counted in `kept`.
    pub saturated: u64,
    /// Not after the newest kept sample (time going backwards, or a repeat): dropped.
    pub out_of_order: u64,
    /// Dropped because more than [`MAX_PENDING`] waited for a scan.
    pub overflow: u64,
    /// Segments integrated across a gap (see the module notes).
    pub gaps: u64,
}

/// One piece of the motion: the sample held over [start, end), `None` = constant velocity (no
/// sample yet, or across a gap).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    pub start: f64,
    pub end: f64,
    pub sample: Option<ImuSample>,
    /// The sample is older than `max_gap_s` at `end`.
    pub gap: bool,
    /// Which of the sample's sensors read at full scale (the sample is clipped).
    pub saturation: Saturation,
}

/// Which sensors of a sample read at or beyond their range.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Saturation {
    pub gyro: bool,
    pub accel: bool,
}

impl Saturation {
    pub fn any(&self) -> bool {
        self.gyro || self.accel
    }
}

/// A sample the queue holds: clipped, with what saturated.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Held {
    sample: ImuSample,
    saturation: Saturation,
}

/// The sample that leaves `state` moving as it is: turning at `rate`, no acceleration.
pub fn coasting_sample(state: &NavState, gravity_mps2: f64, stamp: f64, rate: &Vector3<f64>) -> ImuSample {
    ImuSample {
        stamp,
        angular_velocity: state.gyro_bias + rate,
        specific_force: state.rotation.inverse() * (state.up * gravity_mps2) + state.accel_bias,
    }
}

/// Gravity and the gyro's bias from the first samples (module notes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Level {
    /// world_from_body rotation with roll and pitch from gravity, yaw 0.
    pub rotation: UnitQuaternion<f64>,
    /// The body did not move while they were taken.
    pub still: bool,
    /// The mean rate, when still.
    pub gyro_bias: Option<Vector3<f64>>,
    pub samples: usize,
    /// RMS of the forces (in the body at the window's end) about their mean, m/s²: what the
    /// body's own accelerations could have added to the mean.
    pub force_spread_mps2: f64,
}

/// Spread of the specific force's norm and largest mean rate below which the body was still.
const STILL_FORCE_SPREAD_MPS2: f64 = 0.2;
const STILL_RATE_RAD_S: f64 = 0.05;
/// The rate's spread about its mean (RMS over the axes) of a still body is the gyro's white
/// noise per sample, σ·√rate: a spread beyond this many of them is a turning body; and never
/// below `STILL_RATE_SPREAD_FLOOR_RAD_S` (0.06°/s: an ideal gyro's zero noise).
const STILL_RATE_SPREAD_SIGMAS: f64 = 4.0;
const STILL_RATE_SPREAD_FLOOR_RAD_S: f64 = 1e-3;

/// The samples between the state's time and the newest.
#[derive(Clone, Debug, Default)]
pub struct ImuQueue {
    limits: ImuLimits,
    /// The last sample at or before the state's time: it holds at that time.
    holding: Option<Held>,
    /// The samples after it, in stamp order.
    pending: VecDeque<Held>,
    newest: Option<f64>,
    counts: ImuCounts,
}

impl ImuQueue {
    pub fn new(limits: ImuLimits) -> Self {
        Self { limits, ..Self::default() }
    }

    pub fn counts(&self) -> ImuCounts {
        self.counts
    }

    /// Samples waiting after the state's time.
    pub fn waiting(&self) -> usize {
        self.pending.len()
    }

    /// Stamp of the newest sample kept.
    pub fn newest(&self) -> Option<f64> {
        self.newest
    }

    /// Keeps `sample` when it is finite and after the newest, clipped when saturated (else
    /// counts why not).
    pub fn push(&mut self, sample: &ImuSample) {
        match self.limits.screen(sample, self.newest) {
            Some(ImuDrop::NonFinite) => self.counts.non_finite += 1,
            Some(ImuDrop::OutOfOrder) => self.counts.out_of_order += 1,
            Some(ImuDrop::Saturated) => {
                self.counts.saturated += 1;
                let (sample, saturation) = self.limits.clip(sample);
                self.keep(Held { sample, saturation });
            }
            None => {
                self.counts.kept += 1;
                self.keep(Held { sample: *sample, saturation: Saturation::default() });
            }
        }
    }

    fn keep(&mut self, held: Held) {
        if self.pending.len() >= MAX_PENDING {
            self.pending.pop_front();
            self.counts.overflow += 1;
        }
        self.newest = Some(held.sample.stamp);
        self.pending.push_back(held);
    }

    /// The segments from `from` to `to` (module notes); empty unless `to > from`.
    pub fn segments(&self, from: f64, to: f64) -> Vec<Segment> {
        let mut out = Vec::new();
        if !(from.is_finite() && to.is_finite() && to > from) {
            return out;
        }
        let mut held = self.holding;
        let mut start = from;
        for s in self.pending.iter() {
            if s.sample.stamp <= start {
                held = Some(*s);
                continue;
            }
            let end = s.sample.stamp.min(to);
            // Before the first sample the robot coasts; after it, the sample held.
            out.push(self.segment(start, end, held));
            start = end;
            held = Some(*s);
            if start >= to {
                return out;
            }
        }
        out.push(self.segment(start, to, held));
        out
    }

    fn segment(&self, start: f64, end: f64, held: Option<Held>) -> Segment {
        let gap = held.is_none_or(|h| end - h.sample.stamp > self.limits.max_gap_s);
        let held = held.filter(|_| !gap);
        Segment {
            start,
            end,
            sample: held.map(|h| h.sample),
            gap,
            saturation: held.map_or_else(Saturation::default, |h| h.saturation),
        }
    }

    /// Forgets the samples before `time`, keeping the one that holds at it, and counts the gaps
    /// of the motion up to it.
    pub fn advance(&mut self, from: f64, time: f64) {
        if self.newest.is_some() {
            self.counts.gaps += self.segments(from, time).iter().filter(|s| s.gap).count() as u64;
        }
        while self.pending.front().is_some_and(|s| s.sample.stamp <= time) {
            self.holding = self.pending.pop_front();
        }
    }

    /// Gravity from the samples of the last `window_s` up to `until`, in the body at `until`;
    /// none with fewer than `min_samples`, or before the samples span (nine tenths of) the
    /// window. `gyro_noise`: the gyro's white-noise density, rad/s/√Hz (module notes: still).
    pub fn level(&self, until: f64, window_s: f64, min_samples: usize, gyro_noise: f64) -> Option<Level> {
        // A clipped sample says nothing exact about gravity: left out.
        let taken: Vec<&ImuSample> = self
            .pending
            .iter()
            .filter(|h| !h.saturation.any())
            .map(|h| &h.sample)
            .filter(|s| s.stamp <= until && s.stamp >= until - window_s)
            .collect();
        // The whole window: a gait's or a vehicle's accelerations average out over seconds, not
        // over a fraction of a stride (a legged robot's trunk swings by ±1 g at 4 Hz).
        let span = taken.last().zip(taken.first()).map_or(0.0, |(b, a)| b.stamp - a.stamp);
        if taken.len() < min_samples.max(1) || span < 0.9 * window_s {
            return None;
        }
        let n = taken.len() as f64;
        let rate = taken.iter().map(|s| s.angular_velocity).sum::<Vector3<f64>>() / n;
        let rate_spread = (taken.iter().map(|s| (s.angular_velocity - rate).norm_squared()).sum::<f64>() / n).sqrt();
        let per_sample = gyro_noise * (n / span.max(1e-9)).sqrt() * 3f64.sqrt();
        let mean_norm = taken.iter().map(|s| s.specific_force.norm()).sum::<f64>() / n;
        let spread = (taken.iter().map(|s| (s.specific_force.norm() - mean_norm).powi(2)).sum::<f64>() / n).sqrt();
        let still = spread < STILL_FORCE_SPREAD_MPS2
            && rate.amax() < STILL_RATE_RAD_S
            && rate_spread < (STILL_RATE_SPREAD_SIGMAS * per_sample).max(STILL_RATE_SPREAD_FLOOR_RAD_S);
        let forces: Vec<Vector3<f64>> = if still {
            taken.iter().map(|s| s.specific_force).collect()
        } else {
            forces_at_end(&taken, until).collect()
        };
        let force = forces.iter().sum::<Vector3<f64>>() / n;
        if !force.iter().all(|x| x.is_finite()) || force.norm() < 1e-6 {
            return None;
        }
        let force_spread_mps2 = (forces.iter().map(|f| (f - force).norm_squared()).sum::<f64>() / n).sqrt();
        let roll = force.y.atan2(force.z);
        let pitch = (-force.x).atan2(force.y.hypot(force.z));
        Some(Level {
            rotation: UnitQuaternion::from_euler_angles(roll, pitch, 0.0),
            still,
            gyro_bias: still.then_some(rate),
            samples: taken.len(),
            force_spread_mps2,
        })
    }
}

/// Each sample's specific force in the body at `until` (stamp order in, reverse order out):
/// f_k^end = Q_kᵀ f_k, Q_k the rotation the gyro measured from t_k to `until` (module notes),
/// each sample holding until the next.
fn forces_at_end<'a>(taken: &'a [&ImuSample], until: f64) -> impl Iterator<Item = Vector3<f64>> + 'a {
    let mut k_from_end = UnitQuaternion::identity();
    let mut next = until;
    taken.iter().rev().map(move |s| {
        let k_from_next = UnitQuaternion::from_scaled_axis(s.angular_velocity * (next - s.stamp).max(0.0));
        // Q_k = Exp(ω_k Δt_k) Q_{k+1}; the force is carried by Q_kᵀ.
        k_from_end = k_from_next * k_from_end;
        next = s.stamp;
        k_from_end.inverse() * s.specific_force
    })
}

/// The predicted motion over a sweep, for deskewing: the state at the start of each segment.
#[derive(Clone, Debug)]
pub struct Track {
    /// (segment, the state at its start), in time order.
    knots: Vec<(Segment, NavState)>,
    gravity_mps2: f64,
    coast_rate: Vector3<f64>,
}

impl Track {
    /// The states of `state` (at the first segment's start) propagated over `segments`, without
    /// covariance; segments without a sample coast turning at `coast_rate`.
    pub fn new(state: &NavState, segments: &[Segment], noise: &ImuNoise, coast_rate: &Vector3<f64>) -> Self {
        let g = noise.gravity_mps2;
        let mut knots = Vec::with_capacity(segments.len());
        let mut now = *state;
        for segment in segments {
            knots.push((*segment, now));
            let sample = segment.sample.unwrap_or_else(|| coasting_sample(&now, g, segment.start, coast_rate));
            now = now.propagated(&sample, segment.end - segment.start, g);
        }
        Self { knots, gravity_mps2: g, coast_rate: *coast_rate }
    }

    /// The state at the track's end.
    pub fn last(&self) -> Option<NavState> {
        self.knots.last().and_then(|(s, _)| self.state_at(s.end))
    }

    /// Its time span.
    pub fn span(&self) -> Option<(f64, f64)> {
        Some((self.knots.first()?.0.start, self.knots.last()?.0.end))
    }

    /// The state at `t`; none outside the track (or before it starts).
    pub fn state_at(&self, t: f64) -> Option<NavState> {
        let k = self.knots.partition_point(|(s, _)| s.start <= t).checked_sub(1)?;
        let (segment, state) = self.knots.get(k)?;
        if t > segment.end + 1e-9 {
            return None;
        }
        let sample = segment
            .sample
            .unwrap_or_else(|| coasting_sample(state, self.gravity_mps2, segment.start, &self.coast_rate));
        let dt = t - segment.start;
        Some(if dt > 0.0 { state.propagated(&sample, dt, self.gravity_mps2) } else { *state })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    fn sample(stamp: f64, w: f64) -> ImuSample {
        ImuSample { stamp, angular_velocity: Vector3::new(0.0, 0.0, w), specific_force: Vector3::z() * 9.81 }
    }

    #[test]
    fn bad_samples_are_counted_and_dropped_and_saturated_ones_kept_clipped() {
        let mut q = ImuQueue::new(ImuLimits::default());
        q.push(&sample(0.0, 0.1));
        q.push(&sample(f64::NAN, 0.1));
        q.push(&ImuSample { specific_force: Vector3::new(0.0, f64::INFINITY, 0.0), ..sample(0.01, 0.0) });
        q.push(&sample(0.01, -40.0)); // beyond 2000 °/s
        q.push(&ImuSample { specific_force: Vector3::new(200.0, 0.0, 9.81), ..sample(0.02, 0.0) }); // beyond 16 g
        q.push(&ImuSample { specific_force: Vector3::new(200.0, 0.0, 9.81), ..sample(0.015, 0.0) }); // and late
        q.push(&sample(0.0, 0.1)); // repeated
        q.push(&sample(-1.0, 0.1)); // backwards
        q.push(&sample(0.03, 0.1));
        let c = q.counts();
        assert_eq!((c.kept, c.non_finite, c.saturated, c.out_of_order), (2, 2, 2, 3));
        assert_eq!(q.newest(), Some(0.03));
        // Each sample holds until the next; the saturated ones clipped to the range, and marked.
        let s = q.segments(0.0, 0.04);
        let (gyro, accel) = (Saturation { gyro: true, accel: false }, Saturation { gyro: false, accel: true });
        let marks: Vec<Saturation> = s.iter().map(|s| s.saturation).collect();
        assert_eq!(marks, vec![Saturation::default(), gyro, accel, Saturation::default()]);
        let held = |k: usize| s[k].sample.expect("a sample");
        let limits = ImuLimits::default();
        assert_eq!(held(1).angular_velocity, Vector3::new(0.0, 0.0, -limits.gyro_range_rad_s));
        assert_eq!(held(2).specific_force, Vector3::new(limits.accel_range_mps2, 0.0, 9.81));
        // A clipped sample says nothing exact about gravity: levelling leaves it out.
        let mut still = ImuQueue::new(limits);
        for k in 0..=200 {
            still.push(&sample(k as f64 * 0.005, 0.0));
        }
        let level = still.level(1.0, 1.0, 100, 0.0).expect("levelled");
        still.push(&ImuSample { specific_force: Vector3::new(0.0, 200.0, 9.81), ..sample(1.001, 0.0) });
        assert_eq!(still.level(1.001, 1.0, 100, 0.0).expect("levelled").rotation, level.rotation);
    }

    #[test]
    fn segments_hold_each_sample_until_the_next_and_mark_gaps() {
        let mut q = ImuQueue::new(ImuLimits::default());
        for t in [0.0, 0.005, 0.010, 0.100, 0.105] {
            q.push(&sample(t, t));
        }
        let s = q.segments(0.002, 0.103);
        let spans: Vec<(f64, f64, f64, bool)> =
            s.iter().map(|s| (s.start, s.end, s.sample.map_or(-1.0, |x| x.stamp), s.gap)).collect();
        assert_eq!(
            spans,
            vec![
                (0.002, 0.005, 0.0, false),
                (0.005, 0.010, 0.005, false),
                (0.010, 0.100, -1.0, true),
                (0.100, 0.103, 0.100, false)
            ]
        );
        // Beyond the newest sample, the last one is held until it is old: then a gap, coasted.
        let tail = q.segments(0.105, 0.2);
        assert_eq!(tail.len(), 1);
        assert!(tail[0].gap && tail[0].sample.is_none());
        assert!(q.segments(0.105, 0.12).iter().all(|s| !s.gap && s.sample.is_some()));
        // Before any sample: coasting.
        let early = q.segments(-0.1, 0.0);
        assert_eq!(early.len(), 1);
        assert!(early[0].sample.is_none() && early[0].gap);
        // Advancing keeps the sample holding at the new time, and counts the gap crossed.
        q.advance(0.002, 0.102);
        assert_eq!(q.counts().gaps, 1);
        let after = q.segments(0.102, 0.104);
        assert_eq!(after[0].sample.map(|x| x.stamp), Some(0.100));
        assert!(q.segments(0.2, 0.1).is_empty());
    }

    #[test]
    fn the_pending_queue_is_bounded() {
        let mut q = ImuQueue::new(ImuLimits::default());
        for k in 0..(MAX_PENDING + 5) {
            q.push(&sample(k as f64 * 1e-3, 0.0));
        }
        assert_eq!(q.counts().overflow, 5);
        assert_eq!(q.pending.len(), MAX_PENDING);
    }

    #[test]
    fn levelling_finds_roll_pitch_and_a_still_gyros_bias() {
        let truth = UnitQuaternion::from_euler_angles(0.2, -0.15, 0.0);
        let bias = Vector3::new(0.003, -0.002, 0.001);
        let mut q = ImuQueue::new(ImuLimits::default());
        for k in 0..100 {
            q.push(&ImuSample {
                stamp: k as f64 * 0.005,
                angular_velocity: bias,
                specific_force: truth.inverse() * Vector3::z() * 9.81,
            });
        }
        let level = q.level(0.5, 0.5, 20, 0.0).expect("enough samples");
        assert!(level.rotation.angle_to(&truth) < 1e-9, "{:?}", level.rotation.euler_angles());
        assert!(level.still);
        assert!((level.gyro_bias.expect("still") - bias).norm() < 1e-12);
        assert!(q.level(0.05, 1.0, 5, 0.0).is_none(), "0.05 s of samples do not span the window");
        assert!(q.level(0.5, 0.5, 200, 0.0).is_none(), "101 samples are too few");
    }

    /// A body turning about its own point (a rig swaying in a hand, its bearer standing): no
    /// acceleration, so every force is gravity (its norm steady), but in a body that turns. Levelled at the
    /// window's end with the forces carried there by the gyro, roll and pitch are the end's
    /// to the samples' discretisation; their plain mean is the window's mean attitude, degrees
    /// off; and the mean rate is no bias.
    #[test]
    fn a_turning_body_is_levelled_at_the_windows_end_and_its_rate_is_not_a_bias() {
        // Its mean rate over the window is below 0.05 rad/s on every axis (0.035, −0.024, 0):
        // only the rate's spread tells it from a still gyro's bias.
        let attitude = |t: f64| {
            UnitQuaternion::from_euler_angles(0.06 * (TAU * 0.4 * t).sin(), 0.05 * (TAU * 0.9 * t + 1.0).sin(), 0.0)
        };
        let dt = 0.005;
        let mut q = ImuQueue::new(ImuLimits::default());
        for k in 0..=200 {
            let t = k as f64 * dt;
            let rate = (attitude(t).inverse() * attitude(t + dt)).scaled_axis() / dt;
            q.push(&ImuSample {
                stamp: t,
                angular_velocity: rate,
                specific_force: attitude(t).inverse() * Vector3::z() * 9.81,
            });
        }
        let level = q.level(1.0, 1.0, 20, 1.7e-4).expect("enough samples");
        let tilt = |r: &UnitQuaternion<f64>| r.inverse() * Vector3::z();
        let error = tilt(&level.rotation).angle(&tilt(&attitude(1.0)));
        assert!(error < 1e-3, "{error} rad");
        assert!(!level.still && level.gyro_bias.is_none());
        let mean_rate = q.pending.iter().map(|h| h.sample.angular_velocity).sum::<Vector3<f64>>() / 201.0;
        assert!(mean_rate.amax() < STILL_RATE_RAD_S, "the old test alone would call it still: {mean_rate}");
        let mean = q.pending.iter().map(|h| h.sample.specific_force).sum::<Vector3<f64>>();
        assert!(mean.angle(&tilt(&attitude(1.0))) > 0.5f64.to_radians(), "the plain mean is the mean attitude");
    }

    #[test]
    fn a_track_reproduces_propagation_at_any_time() {
        let noise = ImuNoise::default();
        let mut q = ImuQueue::new(ImuLimits::default());
        for k in 0..30 {
            let t = k as f64 * 0.005;
            q.push(&ImuSample {
                stamp: t,
                angular_velocity: Vector3::new(0.1, -0.2, 1.0 + t),
                specific_force: Vector3::new(0.5, 0.1, 9.9),
            });
        }
        let start = NavState {
            velocity: Vector3::new(1.0, 0.0, 0.0),
            ..NavState::at_rest(UnitQuaternion::identity(), Vector3::zeros())
        };
        let segments = q.segments(0.0, 0.1);
        let track = Track::new(&start, &segments, &noise, &Vector3::zeros());
        // Sample by sample to 0.0725 (half-way through a sample's interval).
        let mut direct = start;
        for k in 0..14 {
            direct = direct.propagated(&q.pending[k].sample, 0.005, noise.gravity_mps2);
        }
        direct = direct.propagated(&q.pending[14].sample, 0.0025, noise.gravity_mps2);
        let at = track.state_at(0.0725).expect("inside");
        assert!((at.position - direct.position).norm() < 1e-12);
        assert!(at.rotation.angle_to(&direct.rotation) < 1e-12);
        assert!(track.state_at(0.2).is_none() && track.state_at(-0.1).is_none());
    }
}
