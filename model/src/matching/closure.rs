//! Closure rounds of an aligned pair (beyond the paper's single alignment, §IV-D): once the
//! neighbour's world is placed in ours, its objects are associated with ours *through* that
//! transform — no graph matching — and a round is planned over ground no earlier round covered.
//!
//! ```text
//! pairs  = { (l, r) : l, r mutual nearest among objects of similar label,
//!            ‖c_l − T·c_r‖ ≤ gate_m }                          (T = local_from_remote)
//! seed   = argmax over pairs p with min_s ‖p − s‖ ≥ spacing_m (s: earlier seeds)
//!          of #{ q ∈ pairs : ‖q − p‖ ≤ radius_m }              (ties: lowest local id)
//! round  = { q ∈ pairs : ‖q − seed‖ ≤ radius_m },  needs ≥ min_pairs
//! ```
//!
//! Spreading rounds over the overlap is what pins the transform's yaw and tilt: a single
//! encounter constrains them only over its own few metres.

use super::{GraphObject, LabelSimilarity};
use crate::geometry::Pose3;
use crate::scene_graph::ObjectId;
use nalgebra::Point3;

/// Where closure rounds look and how far apart they are.
#[derive(Clone, Debug, PartialEq)]
pub struct ClosurePlan {
    /// A local and a neighbour object (through the current transform) this close are the same
    /// object, m. Default 1.0.
    pub gate_m: f64,
    /// A round takes the pairs within this distance of its seed, m. Default 15.
    pub radius_m: f64,
    /// A round's seed is at least this far from every earlier round's, m. Default 10.
    pub spacing_m: f64,
    /// Pairs a round needs. Default 3.
    pub min_pairs: usize,
}

impl Default for ClosurePlan {
    fn default() -> Self {
        Self { gate_m: 1.0, radius_m: 15.0, spacing_m: 10.0, min_pairs: 3 }
    }
}

/// A local object and a neighbour object taken for the same one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClosurePair {
    pub local: ObjectId,
    pub remote: ObjectId,
    /// The local object's centroid (local world).
    pub at: Point3<f64>,
}

/// The least label similarity for two objects to be paired.
const MIN_SIMILARITY: f64 = 0.5;

/// Mutual nearest pairs of similar label within `gate_m`, the neighbour's objects placed by
/// `local_from_remote`; in local id order.
pub fn pairs_through(
    local: &[GraphObject],
    remote: &[GraphObject],
    local_from_remote: &Pose3,
    labels: &LabelSimilarity,
    gate_m: f64,
) -> Vec<ClosurePair> {
    let placed: Vec<Point3<f64>> = remote.iter().map(|r| local_from_remote * r.centroid).collect();
    let nearest = |from: &Point3<f64>, label, among: &mut dyn Iterator<Item = (usize, Point3<f64>, _)>| {
        among
            .filter(|(_, _, l)| labels.get(label, *l) >= MIN_SIMILARITY)
            .map(|(i, p, _)| (i, (p - from).norm()))
            .filter(|(_, d)| *d <= gate_m)
            .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)))
            .map(|(i, _)| i)
    };
    let mut out = Vec::new();
    for (li, l) in local.iter().enumerate() {
        let Some(ri) =
            nearest(&l.centroid, l.label, &mut remote.iter().enumerate().map(|(i, r)| (i, placed[i], r.label)))
        else {
            continue;
        };
        let back = nearest(
            &placed[ri],
            remote[ri].label,
            &mut local.iter().enumerate().map(|(i, o)| (i, o.centroid, o.label)),
        );
        if back == Some(li) {
            out.push(ClosurePair { local: l.id, remote: remote[ri].id, at: l.centroid });
        }
    }
    out.sort_by_key(|p| p.local);
    out
}

/// The next round: its seed and the pairs around it, or `None` when every pair is within
/// `spacing_m` of an earlier seed or no seed has `min_pairs` around it.
pub fn next_round(
    pairs: &[ClosurePair],
    seeds: &[Point3<f64>],
    plan: &ClosurePlan,
) -> Option<(Point3<f64>, Vec<ClosurePair>)> {
    let around = |p: &ClosurePair| pairs.iter().filter(|q| (q.at - p.at).norm() <= plan.radius_m).count();
    let seed = pairs
        .iter()
        .filter(|p| seeds.iter().all(|s| (p.at - s).norm() >= plan.spacing_m))
        .map(|p| (p, around(p)))
        .filter(|(_, n)| *n >= plan.min_pairs)
        // Most pairs around; among equals the first in local id order.
        .fold(None::<(&ClosurePair, usize)>, |best, c| match best {
            Some(b) if b.1 >= c.1 => Some(b),
            _ => Some(c),
        })?
        .0;
    let round = pairs.iter().filter(|q| (q.at - seed.at).norm() <= plan.radius_m).copied().collect();
    Some((seed.at, round))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_yaw_translation;
    use crate::scene_graph::LabelId;
    use nalgebra::Vector3;
    use proptest::prelude::*;

    fn object(id: u32, label: u16, x: f64, y: f64) -> GraphObject {
        GraphObject { id: ObjectId(id), label: LabelId(label), centroid: Point3::new(x, y, 0.5), size: None }
    }

    #[test]
    fn pairs_are_mutual_nearest_of_a_similar_label_within_the_gate() {
        let labels = LabelSimilarity::hard(4);
        let local_from_remote = pose_from_yaw_translation(std::f64::consts::FRAC_PI_2, Vector3::new(10.0, 0.0, 0.0));
        let local = vec![
            object(1, 0, 10.0, 2.0),  // remote 11 at (2, 0) lands here
            object(2, 1, 10.0, 5.0),  // remote 12 has another label
            object(3, 0, 10.0, 8.0),  // remote 13 lands 1.5 m off: beyond the gate
            object(4, 2, 20.0, 20.0), // a row of two: 5 is nearer to remote 15
            object(5, 2, 20.0, 20.6),
        ];
        let remote =
            vec![object(11, 0, 2.0, 0.0), object(12, 2, 5.0, 0.0), object(13, 0, 9.5, 0.0), object(15, 2, 20.7, -10.0)];
        let pairs = pairs_through(&local, &remote, &local_from_remote, &labels, 1.0);
        let ids: Vec<(u32, u32)> = pairs.iter().map(|p| (p.local.0, p.remote.0)).collect();
        assert_eq!(ids, vec![(1, 11), (5, 15)]);
    }

    #[test]
    fn rounds_spread_over_ground_not_yet_covered() {
        let plan = ClosurePlan { gate_m: 1.0, radius_m: 5.0, spacing_m: 10.0, min_pairs: 3 };
        let pair = |id: u32, x: f64| ClosurePair {
            local: ObjectId(id),
            remote: ObjectId(100 + id),
            at: Point3::new(x, 0.0, 0.0),
        };
        // A cluster of four at 0–3 m, three at 30–32 m, two at 60 m.
        let pairs = vec![
            pair(1, 0.0),
            pair(2, 1.0),
            pair(3, 2.0),
            pair(4, 3.0),
            pair(5, 30.0),
            pair(6, 31.0),
            pair(7, 32.0),
            pair(8, 60.0),
            pair(9, 61.0),
        ];
        let (seed, round) = next_round(&pairs, &[], &plan).expect("the biggest cluster");
        assert_eq!(round.iter().map(|p| p.local.0).collect::<Vec<_>>(), vec![1, 2, 3, 4]);
        let (seed2, round2) = next_round(&pairs, &[seed], &plan).expect("the next cluster");
        assert_eq!(round2.iter().map(|p| p.local.0).collect::<Vec<_>>(), vec![5, 6, 7]);
        // Two pairs are not enough.
        assert_eq!(next_round(&pairs, &[seed, seed2], &plan), None);
    }

    proptest! {
        /// Whatever the layout, the transform and the earlier seeds: every pair is of similar
        /// labels within the gate, no object is paired twice, and a round's seed keeps its
        /// spacing and has enough pairs around it.
        #[test]
        fn pairs_and_rounds_keep_their_promises(
            xs in prop::collection::vec((0.0f64..60.0, 0.0f64..60.0, 0u16..3), 1..40),
            yaw in -3.1f64..3.1, tx in -20.0f64..20.0, noise in 0.0f64..0.8,
            seeds in prop::collection::vec((0.0f64..60.0, 0.0f64..60.0), 0..4),
        ) {
            let labels = LabelSimilarity::hard(3);
            let local_from_remote = pose_from_yaw_translation(yaw, Vector3::new(tx, 0.0, 0.0));
            let local: Vec<GraphObject> = xs.iter().enumerate().map(|(i, (x, y, l))| object(i as u32, *l, *x, *y)).collect();
            let remote: Vec<GraphObject> = local.iter().enumerate().map(|(i, o)| {
                let jitter = Vector3::new(noise * ((i * 7 % 5) as f64 / 4.0 - 0.5), 0.0, 0.0);
                GraphObject { id: ObjectId(1000 + i as u32), centroid: local_from_remote.inverse() * (o.centroid + jitter), ..o.clone() }
            }).collect();
            let pairs = pairs_through(&local, &remote, &local_from_remote, &labels, 1.0);
            let mut seen_l = std::collections::BTreeSet::new();
            let mut seen_r = std::collections::BTreeSet::new();
            for p in &pairs {
                let l = local.iter().find(|o| o.id == p.local).unwrap();
                let r = remote.iter().find(|o| o.id == p.remote).unwrap();
                prop_assert_eq!(l.label, r.label);
                prop_assert!((l.centroid - local_from_remote * r.centroid).norm() <= 1.0 + 1e-9);
                prop_assert!(seen_l.insert(p.local) && seen_r.insert(p.remote));
            }
            let seeds: Vec<Point3<f64>> = seeds.iter().map(|(x, y)| Point3::new(*x, *y, 0.5)).collect();
            let plan = ClosurePlan::default();
            if let Some((seed, round)) = next_round(&pairs, &seeds, &plan) {
                prop_assert!(seeds.iter().all(|s| (seed - s).norm() >= plan.spacing_m));
                prop_assert!(round.len() >= plan.min_pairs);
                prop_assert!(round.iter().all(|q| (q.at - seed).norm() <= plan.radius_m));
            }
        }
    }
}
