//! The geometry a robot drives through its waypoints: straight legs joined by circular arcs, so
//! that its heading and velocity are continuous and no corner needs an infinite turn rate.
//!
//! At an interior waypoint P with incoming direction u and outgoing w, turning by
//! θ = atan2(u × w, u · w), an arc of radius r is tangent to both legs at the distance
//! d = r·tan(|θ|/2) before and after P. Each corner may use half of an interior leg (the whole
//! of the first or last), so where d would not fit, r shrinks to fit it; a reversal (|θ| → π)
//! leaves no room for an arc, and the robot turns on the spot instead (a `Spin`).
//!
//! On an arc turning by k = sign θ, starting at p₀ with heading ψ₀, the centre is
//! c = p₀ + k·r·(−sin ψ₀, cos ψ₀), and after σ metres the heading is ψ = ψ₀ + k·σ/r and the
//! position c + k·r·(sin ψ, −cos ψ).

use nalgebra::{Point2, Vector2};
use std::f64::consts::PI;

/// An arc smaller than this is a turn on the spot, m.
const SMALLEST_ARC_M: f64 = 1e-3;

/// One piece of a path; its local coordinate is metres along it, or radians turned for a spin.
#[derive(Clone, Debug, PartialEq)]
pub enum Piece {
    Line { from: Point2<f64>, heading: f64, length: f64 },
    Arc { from: Point2<f64>, heading: f64, radius: f64, turn: f64 },
    Spin { at: Point2<f64>, heading: f64, turn: f64 },
}

impl Piece {
    /// The extent of the local coordinate: metres, or radians for a spin.
    pub fn extent(&self) -> f64 {
        match *self {
            Piece::Line { length, .. } => length,
            Piece::Arc { radius, turn, .. } => radius * turn.abs(),
            Piece::Spin { turn, .. } => turn.abs(),
        }
    }

    /// Where the robot is and where it heads at local coordinate `x` (clamped to the piece).
    pub fn at(&self, x: f64) -> (Point2<f64>, f64) {
        let x = x.clamp(0.0, self.extent());
        match *self {
            Piece::Line { from, heading, .. } => (from + Vector2::new(heading.cos(), heading.sin()) * x, heading),
            Piece::Arc { from, heading, radius, turn } => {
                let k = turn.signum();
                let centre = from + Vector2::new(-heading.sin(), heading.cos()) * (k * radius);
                let psi = heading + k * x / radius;
                (centre + Vector2::new(psi.sin(), -psi.cos()) * (k * radius), psi)
            }
            Piece::Spin { at, heading, turn } => (at, heading + turn.signum() * x),
        }
    }

    /// Radius of the arc (infinite on a line, zero on a spin).
    pub fn radius(&self) -> f64 {
        match *self {
            Piece::Line { .. } => f64::INFINITY,
            Piece::Arc { radius, .. } => radius,
            Piece::Spin { .. } => 0.0,
        }
    }
}

/// The pieces through `waypoints` with corners of radius `turn_radius_m` (smaller where the
/// legs are short). Repeated waypoints are skipped; fewer than two distinct ones make no path.
pub fn through(waypoints: &[Point2<f64>], turn_radius_m: f64) -> Vec<Piece> {
    let mut points: Vec<Point2<f64>> = Vec::with_capacity(waypoints.len());
    for p in waypoints {
        if points.last().is_none_or(|q| (p - q).norm() > 1e-9) {
            points.push(*p);
        }
    }
    if points.len() < 2 {
        return Vec::new();
    }
    let legs: Vec<Vector2<f64>> = points.windows(2).map(|w| w[1] - w[0]).collect();
    let heading = |leg: &Vector2<f64>| leg.y.atan2(leg.x);
    // How far before and after each interior waypoint its corner starts and ends, and its radius.
    let corners: Vec<(f64, f64)> = (1..points.len() - 1)
        .map(|i| {
            let (u, w) = (legs[i - 1], legs[i]);
            let turn = (u.perp(&w)).atan2(u.dot(&w));
            let share = |leg: usize| if leg == 0 || leg == legs.len() - 1 { 1.0 } else { 0.5 };
            let room = (legs[i - 1].norm() * share(i - 1)).min(legs[i].norm() * share(i));
            let half = (turn.abs() / 2.0).tan();
            let radius = if turn.abs() >= PI - 1e-9 { 0.0 } else { turn_radius_m.min(room / half.max(1e-300)) };
            (turn, if radius * turn.abs() < SMALLEST_ARC_M { 0.0 } else { radius })
        })
        .collect();
    let cut = |c: Option<&(f64, f64)>| c.map_or(0.0, |&(turn, radius)| radius * (turn.abs() / 2.0).tan());
    let mut pieces = Vec::new();
    for (k, leg) in legs.iter().enumerate() {
        let psi = heading(leg);
        let (before, after) = (k.checked_sub(1).and_then(|j| corners.get(j)), corners.get(k));
        let (start, end) = (cut(before), leg.norm() - cut(after));
        if end - start > 1e-12 {
            let from = points[k] + leg.normalize() * start;
            pieces.push(Piece::Line { from, heading: psi, length: end - start });
        }
        if let Some(&(turn, radius)) = after {
            if turn.abs() < 1e-12 {
                continue;
            }
            let from = points[k] + leg.normalize() * end;
            pieces.push(if radius == 0.0 {
                Piece::Spin { at: points[k + 1], heading: psi, turn }
            } else {
                Piece::Arc { from, heading: psi, radius, turn }
            });
        }
    }
    pieces
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::FRAC_PI_2;

    fn p(x: f64, y: f64) -> Point2<f64> {
        Point2::new(x, y)
    }

    #[test]
    fn a_right_angle_is_a_quarter_circle_tangent_to_both_legs() {
        let pieces = through(&[p(0.0, 0.0), p(10.0, 0.0), p(10.0, 10.0)], 2.0);
        assert_eq!(pieces.len(), 3);
        let Piece::Arc { radius, turn, .. } = pieces[1] else { panic!("{pieces:?}") };
        assert!((radius - 2.0).abs() < 1e-12 && (turn - FRAC_PI_2).abs() < 1e-12);
        // Closed form: it starts at (8, 0) heading east, its centre is (8, 2), it ends at
        // (10, 2) heading north, and half-way it is r·(sin 45°, 1 − cos 45°) from its start.
        let (start, psi0) = pieces[1].at(0.0);
        let (mid, _) = pieces[1].at(pieces[1].extent() / 2.0);
        let (end, psi1) = pieces[1].at(pieces[1].extent());
        assert!((start - p(8.0, 0.0)).norm() < 1e-12 && psi0.abs() < 1e-12);
        let h = std::f64::consts::FRAC_1_SQRT_2;
        assert!((mid - p(8.0 + 2.0 * h, 2.0 - 2.0 * h)).norm() < 1e-12);
        assert!((end - p(10.0, 2.0)).norm() < 1e-12 && (psi1 - FRAC_PI_2).abs() < 1e-12);
        assert!((pieces[0].extent() - 8.0).abs() < 1e-12 && (pieces[2].extent() - 8.0).abs() < 1e-12);
    }

    #[test]
    fn short_legs_shrink_the_radius_and_a_reversal_spins_on_the_spot() {
        // Legs of 1 m: the 90° corner may use all of each (first and last legs), so r = 1.
        let pieces = through(&[p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0)], 5.0);
        assert!((pieces.iter().map(Piece::radius).fold(f64::INFINITY, f64::min) - 1.0).abs() < 1e-12, "{pieces:?}");
        let back = through(&[p(0.0, 0.0), p(4.0, 0.0), p(0.0, 0.0)], 1.0);
        assert_eq!(back.len(), 3);
        assert!(matches!(back[1], Piece::Spin { turn, .. } if (turn.abs() - PI).abs() < 1e-12), "{back:?}");
        assert!(through(&[p(1.0, 1.0), p(1.0, 1.0)], 1.0).is_empty());
    }

    proptest! {
        /// Any waypoints: the pieces join end to start in position and heading, and turn by the
        /// corners' angles in all.
        #[test]
        fn pieces_are_continuous(
            xs in proptest::collection::vec((-50.0f64..50.0, -50.0f64..50.0), 2..8),
            radius in 0.1f64..5.0,
        ) {
            let waypoints: Vec<_> = xs.iter().map(|&(x, y)| p(x, y)).collect();
            let pieces = through(&waypoints, radius);
            for w in pieces.windows(2) {
                let (end, psi_end) = w[0].at(w[0].extent());
                let (start, psi_start) = w[1].at(0.0);
                prop_assert!((end - start).norm() < 1e-6, "{:?}", w);
                let jump = (psi_start - psi_end).sin().abs() + (1.0 - (psi_start - psi_end).cos());
                prop_assert!(jump < 1e-6, "{:?}", w);
            }
            if let (Some(first), Some(last)) = (pieces.first(), pieces.last()) {
                prop_assert!((first.at(0.0).0 - waypoints[0]).norm() < 1e-6);
                prop_assert!((last.at(last.extent()).0 - waypoints[waypoints.len() - 1]).norm() < 1e-6);
            }
            for piece in &pieces {
                let line = matches!(piece, Piece::Line { .. });
                prop_assert!(line || piece.radius() <= radius + 1e-12);
            }
        }
    }
}
