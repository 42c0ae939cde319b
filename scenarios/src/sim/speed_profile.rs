//! When the robot is where along its path: a speed profile that starts and ends at rest, keeps
//! within the platform's speed, acceleration and turn-rate limits, and slows for tight arcs.
//!
//! Each piece has a speed cap: the robot's speed on a line; on an arc of radius r also
//! √(a·r) (lateral acceleration v²/r ≤ a) and ω_max·r (yaw rate v/r ≤ ω_max); a spin turns at
//! ω_max with angular acceleration α_max and starts and ends at rest. The speeds at the joins are
//! the largest that both pieces allow and that a forward and a backward pass can reach under the
//! acceleration limit (v_{i+1}² ≤ v_i² + 2·a·L_i), and each piece is then a trapezoid: accelerate
//! from v₀ to the peak v_p = min(cap, √(a·L + (v₀² + v₁²)/2)), cruise, decelerate to v₁. Every
//! phase has constant acceleration, so the local coordinate is x₀ + v₀τ + aτ²/2 in closed form.

use crate::sim::path::Piece;

/// The platform's limits of motion.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    pub speed_mps: f64,
    pub accel_mps2: f64,
    pub yaw_rate_rps: f64,
    pub yaw_accel_rps2: f64,
}

/// A stretch of constant acceleration on one piece.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Phase {
    piece: usize,
    start_s: f64,
    duration_s: f64,
    from: f64,
    rate: f64,
    accel: f64,
}

/// Where on which piece the robot is at each time since it set off.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Profile {
    phases: Vec<Phase>,
    extents: Vec<f64>,
}

/// Where the robot is on its path: the piece, the local coordinate on it and its rate
/// (m/s, or rad/s on a spin).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Progress {
    pub piece: usize,
    pub along: f64,
    pub rate: f64,
}

impl Profile {
    pub fn of(pieces: &[Piece], limits: &Limits) -> Self {
        let n = pieces.len();
        let is_spin = |p: &Piece| matches!(p, Piece::Spin { .. });
        let accel = |p: &Piece| if is_spin(p) { limits.yaw_accel_rps2 } else { limits.accel_mps2 };
        let cap = |p: &Piece| match p {
            Piece::Spin { .. } => limits.yaw_rate_rps,
            _ => {
                let r = p.radius();
                limits.speed_mps.min((limits.accel_mps2 * r).sqrt()).min(limits.yaw_rate_rps * r)
            }
        };
        // The speed at each join: what both neighbours allow (a spin starts and ends at rest).
        let mut join = vec![0.0f64; n + 1];
        for k in 1..n {
            let (a, b) = (&pieces[k - 1], &pieces[k]);
            join[k] = if is_spin(a) || is_spin(b) { 0.0 } else { cap(a).min(cap(b)) };
        }
        let reach = |v: f64, p: &Piece| (v * v + 2.0 * accel(p) * p.extent()).sqrt();
        for k in 0..n {
            if !is_spin(&pieces[k]) {
                join[k + 1] = join[k + 1].min(reach(join[k], &pieces[k]));
            }
        }
        for k in (0..n).rev() {
            if !is_spin(&pieces[k]) {
                join[k] = join[k].min(reach(join[k + 1], &pieces[k]));
            }
        }
        let mut phases = Vec::new();
        let mut clock = 0.0;
        for (k, piece) in pieces.iter().enumerate() {
            let (length, a, c) = (piece.extent(), accel(piece), cap(piece));
            let (v0, v1) = (join[k], join[k + 1]);
            let peak = c.min((a * length + (v0 * v0 + v1 * v1) / 2.0).sqrt()).max(v0.max(v1));
            let speeding = (peak * peak - v0 * v0) / (2.0 * a);
            let braking = (peak * peak - v1 * v1) / (2.0 * a);
            let cruising = (length - speeding - braking).max(0.0);
            let stretches = [
                ((peak - v0) / a, 0.0, v0, a),
                (if peak > 0.0 { cruising / peak } else { 0.0 }, speeding, peak, 0.0),
                ((peak - v1) / a, speeding + cruising, peak, -a),
            ];
            for (duration_s, from, rate, accel) in stretches {
                if duration_s > 0.0 {
                    phases.push(Phase { piece: k, start_s: clock, duration_s, from, rate, accel });
                    clock += duration_s;
                }
            }
        }
        Self { phases, extents: pieces.iter().map(Piece::extent).collect() }
    }

    /// How long the whole path takes, s.
    pub fn duration_s(&self) -> f64 {
        self.phases.last().map_or(0.0, |p| p.start_s + p.duration_s)
    }

    /// Where the robot is `tau` seconds after it set off (at its start before, at its end
    /// after); `None` for an empty path.
    pub fn at(&self, tau: f64) -> Option<Progress> {
        let last = self.extents.len().checked_sub(1)?;
        let k = self.phases.partition_point(|p| p.start_s <= tau);
        let Some(phase) = k.checked_sub(1).and_then(|k| self.phases.get(k)) else {
            let piece = self.phases.first().map_or(0, |p| p.piece);
            return Some(Progress { piece, along: 0.0, rate: 0.0 });
        };
        if tau >= phase.start_s + phase.duration_s && k == self.phases.len() {
            return Some(Progress { piece: last, along: self.extents[last], rate: 0.0 });
        }
        let t = (tau - phase.start_s).clamp(0.0, phase.duration_s);
        let along = (phase.from + phase.rate * t + 0.5 * phase.accel * t * t).clamp(0.0, self.extents[phase.piece]);
        Some(Progress { piece: phase.piece, along, rate: (phase.rate + phase.accel * t).max(0.0) })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::path::through;
    use nalgebra::Point2;
    use proptest::prelude::*;

    const LIMITS: Limits = Limits { speed_mps: 1.5, accel_mps2: 1.0, yaw_rate_rps: 1.0, yaw_accel_rps2: 2.0 };

    #[test]
    fn a_straight_leg_is_a_trapezoid_in_closed_form() {
        // 10 m at 1.5 m/s, 1 m/s²: 1.5 s and 1.125 m to speed up, the same to stop, and
        // 7.75 m at 1.5 m/s between: 1.5 + 5.1667 + 1.5 s.
        let pieces = through(&[Point2::new(0.0, 0.0), Point2::new(10.0, 0.0)], 1.0);
        let profile = Profile::of(&pieces, &LIMITS);
        assert!((profile.duration_s() - (3.0 + 7.75 / 1.5)).abs() < 1e-12);
        let at = |t| profile.at(t).unwrap();
        assert!((at(1.0).along - 0.5).abs() < 1e-12 && (at(1.0).rate - 1.0).abs() < 1e-12);
        assert!((at(4.0).along - (1.125 + 2.5 * 1.5)).abs() < 1e-12);
        assert_eq!(at(-1.0).along, 0.0);
        assert_eq!(at(100.0).along, 10.0);
        // Too short to reach speed: a triangle, peak √(a·L) = 1 m/s over 1 m.
        let short = Profile::of(&through(&[Point2::new(0.0, 0.0), Point2::new(1.0, 0.0)], 1.0), &LIMITS);
        assert!((short.duration_s() - 2.0).abs() < 1e-12);
        assert!((short.at(1.0).unwrap().rate - 1.0).abs() < 1e-12);
    }

    #[test]
    fn an_arc_is_driven_within_the_lateral_and_yaw_limits_and_a_reversal_spins() {
        // r = 0.5: √(a·r) = 0.707 m/s, ω·r = 0.5 m/s: the yaw rate binds.
        let corner = [Point2::new(0.0, 0.0), Point2::new(10.0, 0.0), Point2::new(10.0, 10.0)];
        let pieces = through(&corner, 0.5);
        let profile = Profile::of(&pieces, &LIMITS);
        let on_arc: Vec<_> =
            (0..4000).filter_map(|k| profile.at(f64::from(k) * 0.01)).filter(|p| p.piece == 1).collect();
        assert!(!on_arc.is_empty());
        assert!(on_arc.iter().all(|p| (p.rate - 0.5).abs() < 1e-9), "{:?}", on_arc[0]);
        let back = through(&[Point2::new(0.0, 0.0), Point2::new(4.0, 0.0), Point2::new(0.0, 0.0)], 1.0);
        let profile = Profile::of(&back, &LIMITS);
        let spinning: Vec<_> =
            (0..2000).filter_map(|k| profile.at(f64::from(k) * 0.01)).filter(|p| p.piece == 1).collect();
        // π rad at 1 rad/s with 2 rad/s²: 0.5 s to speed up, π − 0.5 rad at 1 rad/s, 0.5 s down.
        let expected = 1.0 + std::f64::consts::PI - 0.5;
        assert!((spinning.len() as f64 * 0.01 - expected).abs() < 0.02, "{}", spinning.len());
        assert!(spinning.iter().all(|p| p.rate <= 1.0 + 1e-12));
    }

    proptest! {
        /// Any route: the robot moves continuously, never faster than its caps, never
        /// accelerating harder than its limit, and gets to the end.
        #[test]
        fn motion_is_continuous_and_within_limits(
            xs in proptest::collection::vec((-30.0f64..30.0, -30.0f64..30.0), 2..6),
            radius in 0.0f64..3.0,
        ) {
            let waypoints: Vec<_> = xs.iter().map(|&(x, y)| Point2::new(x, y)).collect();
            let pieces = through(&waypoints, radius);
            let profile = Profile::of(&pieces, &LIMITS);
            let dt = 0.01;
            let steps = (profile.duration_s() / dt) as usize + 2;
            let position = |t: f64| profile.at(t).map(|p| pieces[p.piece].at(p.along));
            let mut before = position(0.0);
            let limit = |k: usize| match pieces[k] {
                Piece::Spin { .. } => (LIMITS.yaw_rate_rps, LIMITS.yaw_accel_rps2),
                _ => (LIMITS.speed_mps, LIMITS.accel_mps2),
            };
            let mut previous = profile.at(0.0).unwrap();
            for k in 1..=steps {
                let t = k as f64 * dt;
                let progress = profile.at(t).unwrap();
                let now = position(t);
                let (Some((p0, _)), Some((p1, _))) = (before, now) else { break };
                prop_assert!((p1 - p0).norm() <= LIMITS.speed_mps * dt + 1e-9);
                let (top, accel) = limit(progress.piece);
                let accel = accel.max(limit(previous.piece).1);
                prop_assert!((progress.rate - previous.rate).abs() <= accel * dt + 1e-9);
                prop_assert!(progress.rate <= top + 1e-9);
                before = now;
                previous = progress;
            }
            if let (Some(end), Some(last)) = (position(profile.duration_s() + 1.0), pieces.last()) {
                prop_assert!((end.0 - last.at(last.extent()).0).norm() < 1e-9);
            }
        }
    }
}
