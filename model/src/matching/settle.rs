//! Settling a contradicted cycle of alignments by object evidence (beyond the paper). Around a
//! cycle of robots each alignment should be the product of the others; when one is not
//! ([`super::relay::contradicting`] flags it) one of them is wrong, and arrival order says
//! nothing about which. The object graphs do: each alignment is scored by the object pairs it
//! explains between the two graphs it joins — mutual nearest of similar label within a gate
//! ([`super::closure::pairs_through`]) — and so is the transform that the cycle's other
//! alignments imply in its place:
//!
//! ```text
//! support(T; A, B) = |pairs_through(A, B, T)|
//! loss(e)          = support(T_e) − support(T̂_e),    T̂_e = the product of the cycle's other edges
//! ```
//!
//! Replacing a right alignment by the product through a wrong one lands its objects on nothing
//! (7–20 pairs fall to 1–4 in the indoor runs that settle a cycle); replacing the wrong one
//! costs little or nothing (a half turn of a symmetric room explains about as many pairs as the
//! truth: 10–14 against 8–10).
//! The edge whose loss is below every other edge's by at least `margin` pairs is the wrong one;
//! otherwise the cycle stays unsettled (it is still flagged). On a cycle of two (two robots'
//! alignments of each other) the losses are opposite, ±(support difference), and the wrong one
//! is the one whose transform explains fewer pairs than the other's by the margin. A robot on a
//! cycle of three holds the object data of both its neighbours, so it scores all three edges,
//! and each robot on the cycle reaches the same verdict from (nearly) the same data: only the
//! robot that made the wrong alignment withdraws it (the other end withdraws its own alignment
//! back only where that is wrong too, on a cycle of its own); the others keep theirs.

use super::closure::pairs_through;
use super::{GraphObject, LabelSimilarity};
use crate::geometry::Pose3;
use crate::scene_graph::RobotId;
use std::collections::BTreeMap;

/// One alignment on a cycle: `placer` placed `placed`'s world in its own.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CycleEdge {
    pub placer: RobotId,
    pub placed: RobotId,
    pub placer_from_placed: Pose3,
}

/// What the object graphs say of each edge of a cycle, and which one is wrong.
#[derive(Clone, Debug, PartialEq)]
pub struct Settlement {
    /// Per edge: the pairs its transform explains, and those the product of the others does.
    pub support: Vec<(usize, usize)>,
    /// The edge whose loss is below every other's by the margin, if one is.
    pub wrong: Option<usize>,
}

impl Settlement {
    /// support − the alternative's, per edge.
    pub fn losses(&self) -> Vec<i64> {
        self.support.iter().map(|(own, alternative)| *own as i64 - *alternative as i64).collect()
    }
}

/// How an edge is scored: the labels, the gate (m) and the margin (pairs) the wrong edge's loss
/// must leave to every other's.
#[derive(Clone, Copy, Debug)]
pub struct SettleConfig<'a> {
    pub labels: &'a LabelSimilarity,
    pub gate_m: f64,
    pub margin_pairs: usize,
}

/// Scores the cycle through `robots` (edge k joins robots k and k + 1, the last back to the
/// first, in either direction: for two robots, both of their alignments of each other), each
/// robot's objects in its own world. `None` when the edges do not close the cycle or a
/// robot's objects are missing.
pub fn settle_cycle(
    robots: &[RobotId],
    edges: &[CycleEdge],
    objects: &BTreeMap<RobotId, &[GraphObject]>,
    config: &SettleConfig,
) -> Option<Settlement> {
    let n = robots.len();
    if n < 2 || edges.len() != n {
        return None;
    }
    // T_{c_k ← c_{k+1}}, each edge taken forward around the cycle.
    let mut forward = Vec::with_capacity(n);
    for (k, e) in edges.iter().enumerate() {
        let (a, b) = (robots[k], robots[(k + 1) % n]);
        forward.push(match (e.placer, e.placed) {
            (p, q) if (p, q) == (a, b) => e.placer_from_placed,
            (p, q) if (p, q) == (b, a) => e.placer_from_placed.inverse(),
            _ => return None,
        });
    }
    let mut support = Vec::with_capacity(n);
    for (k, e) in edges.iter().enumerate() {
        // The other way round: c_k ← c_{k−1} ← … ← c_{k+1}, each step an edge taken backward.
        let mut alternative = Pose3::identity();
        for step in 1..n {
            let m = (k + n - step) % n;
            alternative *= forward[m].inverse();
        }
        // In the edge's own direction.
        if e.placer != robots[k] {
            alternative = alternative.inverse();
        }
        let (into, from) = (objects.get(&e.placer)?, objects.get(&e.placed)?);
        let pairs = |t: &Pose3| pairs_through(into, from, t, config.labels, config.gate_m).len();
        support.push((pairs(&e.placer_from_placed), pairs(&alternative)));
    }
    let losses: Vec<i64> = support.iter().map(|(own, alt)| *own as i64 - *alt as i64).collect();
    // Two edges: the losses are ±d for a support difference d; the margin is on d.
    let margin = config.margin_pairs as i64 * if n == 2 { 2 } else { 1 };
    let wrong = (0..n).find(|&k| (0..n).all(|m| m == k || losses[k] + margin <= losses[m]));
    Some(Settlement { support, wrong })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_yaw_translation;
    use crate::scene_graph::{LabelId, ObjectId};
    use nalgebra::{Point3, Vector3};
    use proptest::prelude::*;

    fn pose(yaw: f64, x: f64, y: f64) -> Pose3 {
        pose_from_yaw_translation(yaw, Vector3::new(x, y, 0.0))
    }

    /// Where an object is: in a room symmetric under a half turn about (10, 5) (chairs at
    /// mirrored places, so the turn maps each onto one of its own label), or in one of two
    /// corridors that no half turn maps onto anything.
    #[derive(Clone, Copy, PartialEq)]
    enum Region {
        Room,
        CorridorA,
        CorridorB,
    }

    fn world() -> Vec<(Region, LabelId, Point3<f64>)> {
        let mut out = Vec::new();
        for (k, (x, y)) in [(2.0, 1.0), (6.0, 2.5), (9.0, 1.5), (4.0, 4.0), (7.5, 3.5)].into_iter().enumerate() {
            let label = LabelId(k as u16 % 2);
            out.push((Region::Room, label, Point3::new(x, y, 0.5)));
            out.push((Region::Room, label, Point3::new(20.0 - x, 10.0 - y, 0.5)));
        }
        for k in 0..8 {
            let (along, across) = (2.5 * f64::from(k), f64::from(k % 4));
            out.push((Region::CorridorA, LabelId(2 + k % 3), Point3::new(27.0 + along, 1.0 + across, 0.5)));
            out.push((Region::CorridorB, LabelId(2 + k % 3), Point3::new(across, 15.0 + along, 0.5)));
        }
        out
    }

    /// The objects of `regions`, in the world of a robot placed at `world_from_robot`.
    fn seen_by(world_from_robot: &Pose3, regions: &[Region]) -> Vec<GraphObject> {
        world()
            .into_iter()
            .filter(|(r, _, _)| regions.contains(r))
            .enumerate()
            .map(|(k, (_, label, p))| GraphObject {
                id: ObjectId(k as u32),
                label,
                centroid: world_from_robot.inverse() * p,
                size: None,
            })
            .collect()
    }

    const EVERYWHERE: [Region; 3] = [Region::Room, Region::CorridorA, Region::CorridorB];

    fn edge(placer: u16, placed: u16, t: Pose3) -> CycleEdge {
        CycleEdge { placer: RobotId(placer), placed: RobotId(placed), placer_from_placed: t }
    }

    /// Three robots: 1 and 2 share only the symmetric room; 2 and 3 also corridor A, 1 and 3
    /// corridor B. The alignment 1 ← 2 taken a half turn about the room's centre explains as
    /// many pairs as the truth, while the products through it cost the other two edges their
    /// corridor: it is the wrong one. In a cycle of right alignments nothing is.
    #[test]
    fn a_half_turn_of_a_symmetric_room_is_found_on_its_cycle() {
        let worlds = [pose(0.3, 1.0, -2.0), pose(-1.1, 4.0, 7.0), pose(2.0, -9.0, 1.0)];
        let o1 = seen_by(&worlds[0], &[Region::Room, Region::CorridorB]);
        let o2 = seen_by(&worlds[1], &[Region::Room, Region::CorridorA]);
        let o3 = seen_by(&worlds[2], &EVERYWHERE);
        let objects: BTreeMap<RobotId, &[GraphObject]> =
            [(RobotId(1), &o1[..]), (RobotId(2), &o2[..]), (RobotId(3), &o3[..])].into();
        let t = |a: usize, b: usize| worlds[a].inverse() * worlds[b];
        let wrong_12 = worlds[0].inverse() * pose(std::f64::consts::PI, 20.0, 10.0) * worlds[1];
        let labels = LabelSimilarity::hard(5);
        let config = SettleConfig { labels: &labels, gate_m: 0.5, margin_pairs: 3 };
        let robots = [RobotId(1), RobotId(2), RobotId(3)];
        let edges = [edge(1, 2, wrong_12), edge(3, 2, t(2, 1)), edge(1, 3, t(0, 2))];
        let s = settle_cycle(&robots, &edges, &objects, &config).expect("scored");
        assert_eq!(s.support, vec![(10, 10), (18, 10), (18, 10)]);
        assert_eq!(s.wrong, Some(0));
        // The same cycle started elsewhere, each edge in either direction: the same edge.
        let turned = [edge(3, 2, t(2, 1)), edge(2, 1, wrong_12.inverse()), edge(3, 1, t(2, 0))];
        let s = settle_cycle(&[RobotId(3), RobotId(2), RobotId(1)], &turned, &objects, &config).expect("scored");
        assert_eq!(s.wrong, Some(1));
        // Within a margin of 9 pairs the corridors do not decide.
        let strict = SettleConfig { margin_pairs: 9, ..config };
        assert_eq!(settle_cycle(&robots, &edges, &objects, &strict).expect("scored").wrong, None);
        let right = [edge(1, 2, t(0, 1)), edge(3, 2, t(2, 1)), edge(1, 3, t(0, 2))];
        let s = settle_cycle(&robots, &right, &objects, &config).expect("scored");
        assert_eq!(s.wrong, None);
        assert_eq!(s.losses(), vec![0, 0, 0]);
    }

    /// Two robots that placed each other differently: the one whose transform explains fewer
    /// pairs than the other's inverse by the margin is wrong; within it, neither.
    #[test]
    fn of_two_alignments_of_each_other_the_worse_supported_is_wrong() {
        let worlds = [pose(0.3, 1.0, -2.0), pose(-1.1, 4.0, 7.0)];
        let o1 = seen_by(&worlds[0], &EVERYWHERE);
        let o2 = seen_by(&worlds[1], &EVERYWHERE);
        let objects: BTreeMap<RobotId, &[GraphObject]> = [(RobotId(1), &o1[..]), (RobotId(2), &o2[..])].into();
        let truth = worlds[0].inverse() * worlds[1];
        let wrong = worlds[0].inverse() * pose(std::f64::consts::PI, 20.0, 10.0) * worlds[1];
        let labels = LabelSimilarity::hard(5);
        let robots = [RobotId(1), RobotId(2)];
        let config = SettleConfig { labels: &labels, gate_m: 0.5, margin_pairs: 3 };
        let s = settle_cycle(&robots, &[edge(1, 2, wrong), edge(2, 1, truth.inverse())], &objects, &config)
            .expect("scored");
        assert_eq!(s.support, vec![(10, 26), (26, 10)]);
        assert_eq!(s.wrong, Some(0));
        let s = settle_cycle(&robots, &[edge(1, 2, truth), edge(2, 1, wrong.inverse())], &objects, &config)
            .expect("scored");
        assert_eq!(s.wrong, Some(1));
        let exact = SettleConfig { margin_pairs: 16, ..config };
        let s =
            settle_cycle(&robots, &[edge(1, 2, truth), edge(2, 1, wrong.inverse())], &objects, &exact).expect("scored");
        assert_eq!(s.wrong, Some(1), "16 pairs fewer meets a margin of 16");
        let strict = SettleConfig { margin_pairs: 17, ..config };
        let s = settle_cycle(&robots, &[edge(1, 2, truth), edge(2, 1, wrong.inverse())], &objects, &strict)
            .expect("scored");
        assert_eq!(s.wrong, None, "16 pairs fewer is within a margin of 17");
    }

    #[test]
    fn edges_that_do_not_close_the_cycle_or_missing_objects_settle_nothing() {
        let o: Vec<GraphObject> = seen_by(&Pose3::identity(), &EVERYWHERE);
        let objects: BTreeMap<RobotId, &[GraphObject]> = [(RobotId(1), &o[..]), (RobotId(2), &o[..])].into();
        let labels = LabelSimilarity::hard(5);
        let config = SettleConfig { labels: &labels, gate_m: 0.5, margin_pairs: 3 };
        let i = Pose3::identity();
        let robots = [RobotId(1), RobotId(2), RobotId(3)];
        assert!(settle_cycle(&robots, &[edge(1, 2, i), edge(2, 3, i)], &objects, &config).is_none(), "too few");
        assert!(settle_cycle(&robots, &[edge(1, 2, i), edge(2, 1, i), edge(3, 1, i)], &objects, &config).is_none());
        assert!(settle_cycle(&robots, &[edge(1, 2, i), edge(2, 3, i), edge(3, 1, i)], &objects, &config).is_none());
    }

    proptest! {
        /// Whatever the worlds, a cycle of right alignments loses nothing at any edge (the
        /// product of the others is the edge itself, to rounding) and nothing is called wrong.
        #[test]
        fn right_alignments_are_never_called_wrong(
            yaws in proptest::array::uniform3(-3.1..3.1f64),
            xs in proptest::array::uniform3(-50.0..50.0f64),
            ys in proptest::array::uniform3(-50.0..50.0f64),
        ) {
            let worlds: Vec<Pose3> = (0..3).map(|k| pose(yaws[k], xs[k], ys[k])).collect();
            let seen: Vec<Vec<GraphObject>> = worlds.iter().map(|w| seen_by(w, &EVERYWHERE)).collect();
            let objects: BTreeMap<RobotId, &[GraphObject]> =
                (0..3).map(|k| (RobotId(k as u16 + 1), &seen[k][..])).collect();
            let t = |a: usize, b: usize| worlds[a].inverse() * worlds[b];
            let labels = LabelSimilarity::hard(5);
            let config = SettleConfig { labels: &labels, gate_m: 0.5, margin_pairs: 1 };
            let robots = [RobotId(1), RobotId(2), RobotId(3)];
            let edges = [edge(1, 2, t(0, 1)), edge(3, 2, t(2, 1)), edge(3, 1, t(2, 0))];
            let s = settle_cycle(&robots, &edges, &objects, &config).expect("scored");
            prop_assert_eq!(s.wrong, None);
            prop_assert!(s.support.iter().all(|(own, alt)| own == alt && *own == world().len()), "{:?}", s);
        }
    }
}
