//! Label clean-up after projection. A segmentation image fattens foreground objects at depth
//! discontinuities (networks do; so does any image painted from sparse returns), so LiDAR
//! returns on the wall *behind* a chair's silhouette take the chair's class. Clustered, those
//! returns become objects on walls, and walls repeat from room to room: exactly the spurious,
//! periodic objects that let two different rooms look alike to the matcher.
//!
//! In 3D the bled returns sit among returns of the wall, metres from the chair. A vote over
//! spatial neighbours (as RangeNet++'s nearest-neighbour post-processing, Milioto et al. 2019)
//! gives them back the wall's class. Neighbours are the returns in the 3 × 3 × 3 block of
//! voxels (side `voxel_m`) around a return's voxel — one histogram per voxel, shared by every
//! return in it, instead of a k-nearest query per return (`label_vote_20k`, below):
//!
//! ```text
//! ℓ'(p) = argmax_ℓ |{ q ∈ B(p) : ℓ(q) = ℓ }|,   B(p): the labelled returns of the 27 voxels
//!                                              around p's, p included
//! ```
//!
//! A label changes only when another has strictly more votes; among those, the most votes, then
//! the smaller id (deterministic). Returns without a label neither vote nor change.

use crate::scene_graph::LabelId;
use crate::spatial::voxel::voxel_of;
use nalgebra::Point3;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LabelVote {
    /// Side of the voting voxels, m; the neighbourhood is 3 voxels across. 0 turns the vote
    /// off. Default 0.2.
    pub voxel_m: f64,
}

impl Default for LabelVote {
    fn default() -> Self {
        Self { voxel_m: 0.2 }
    }
}

/// A voxel's label histogram: (label, returns), few entries.
type Histogram = Vec<(LabelId, u32)>;

fn add(histogram: &mut Histogram, label: LabelId, count: u32) {
    match histogram.iter_mut().find(|(l, _)| *l == label) {
        Some((_, c)) => *c += count,
        None => histogram.push((label, count)),
    }
}

/// The labels after one vote (`labels[k]` belongs to `points[k]`; a length mismatch leaves
/// them as they were, non-finite points neither vote nor change). Every labelled return votes;
/// only those whose label passes `revote` may change (Fusion re-votes object classes only: a
/// wall return turning into a chair return changes no object).
pub fn vote(
    points: &[Point3<f64>],
    labels: &[Option<LabelId>],
    config: &LabelVote,
    revote: impl Fn(LabelId) -> bool,
) -> Vec<Option<LabelId>> {
    let mut out = labels.to_vec();
    let size = config.voxel_m;
    if !(size > 0.0 && size.is_finite()) || points.len() != labels.len() {
        return out;
    }
    let mut keyed: Vec<([i64; 3], usize)> = (0..points.len())
        .filter(|&k| labels[k].is_some() && points[k].coords.iter().all(|v| v.is_finite()))
        .map(|k| (voxel_of(&points[k], size), k))
        .collect();
    keyed.sort_unstable();
    // Unique voxels (sorted), where their members start in `keyed`, and their histograms, one
    // after another in `counts` (from `first[i]` to `first[i + 1]`: one allocation in all).
    let mut voxels: Vec<[i64; 3]> = Vec::new();
    let mut counts: Histogram = Vec::new();
    let (mut first, mut starts): (Vec<usize>, Vec<usize>) = (Vec::new(), Vec::new());
    for (n, (v, k)) in keyed.iter().enumerate() {
        if voxels.last() != Some(v) {
            voxels.push(*v);
            first.push(counts.len());
            starts.push(n);
        }
        if let (Some(&from), Some(l)) = (first.last(), labels[*k]) {
            match counts[from..].iter_mut().find(|(known, _)| *known == l) {
                Some((_, c)) => *c += 1,
                None => counts.push((l, 1)),
            }
        }
    }
    starts.push(keyed.len());
    first.push(counts.len());
    let histogram = |i: usize| &counts[first[i]..first[i + 1]];
    let mut block = Histogram::new();
    for (i, voxel) in voxels.iter().enumerate() {
        let members = &keyed[starts[i]..starts[i + 1]];
        if !histogram(i).iter().any(|(l, _)| revote(*l)) {
            continue;
        }
        block.clear();
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let neighbour = [voxel[0] + dx, voxel[1] + dy, voxel[2] + dz];
                    if let Ok(j) = voxels.binary_search(&neighbour) {
                        for (l, c) in histogram(j) {
                            add(&mut block, *l, *c);
                        }
                    }
                }
            }
        }
        for (_, k) in members {
            let Some(own) = labels[*k].filter(|l| revote(*l)) else { continue };
            let own_votes = block.iter().find(|(l, _)| *l == own).map_or(0, |(_, c)| *c);
            let best =
                block.iter().filter(|(_, c)| *c > own_votes).max_by(|a, b| a.1.cmp(&b.1).then(b.0 .0.cmp(&a.0 .0)));
            if let Some((l, _)) = best {
                out[*k] = Some(*l);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    const WALL: LabelId = LabelId(1);
    const CHAIR: LabelId = LabelId(6);

    /// A wall (x = 4, a return every ~5 cm) whose returns in a 4 cm strip beside the chair's
    /// silhouette took the chair's class, and a chair (0.5 m box at x = 2) whose returns all say
    /// chair.
    fn scene() -> (Vec<Point3<f64>>, Vec<Option<LabelId>>, Vec<usize>) {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (mut points, mut labels, mut fringe) = (Vec::new(), Vec::new(), Vec::new());
        for k in 0..4000 {
            let p = Point3::new(4.0, rng.random_range(-2.0..2.0), rng.random_range(0.0..2.5));
            let bled = (0.5..0.54).contains(&p.y) && p.z < 1.0;
            if bled {
                fringe.push(k);
            }
            points.push(p);
            labels.push(Some(if bled { CHAIR } else { WALL }));
        }
        for _ in 0..300 {
            points.push(Point3::new(
                rng.random_range(1.75..2.25),
                rng.random_range(-0.25..0.25),
                rng.random_range(0.0..1.0),
            ));
            labels.push(Some(CHAIR));
        }
        // A return outside the image.
        points.push(Point3::new(4.0, 0.51, 0.5));
        labels.push(None);
        (points, labels, fringe)
    }

    #[test]
    fn bled_returns_on_a_wall_take_the_walls_class_and_the_chair_keeps_its_own() {
        let (points, labels, fringe) = scene();
        assert!(fringe.len() >= 5, "the scene has a fringe");
        let voted = vote(&points, &labels, &LabelVote::default(), |_| true);
        let fixed = fringe.iter().filter(|&&k| voted[k] == Some(WALL)).count();
        assert_eq!(fixed, fringe.len(), "bled returns left");
        assert!((4000..points.len() - 1).all(|k| voted[k] == Some(CHAIR)), "the chair lost returns");
        assert_eq!(voted[points.len() - 1], None, "an unlabelled return got a label");
        assert!((0..4000).filter(|k| !fringe.contains(k)).all(|k| voted[k] == Some(WALL)), "the wall changed");
        // Only chairs re-voted: the same answer here, since no wall return changes.
        assert_eq!(vote(&points, &labels, &LabelVote::default(), |l| l == CHAIR), voted);
        // Only walls re-voted: the fringe stays.
        assert_eq!(vote(&points, &labels, &LabelVote::default(), |l| l == WALL), labels);
    }

    /// The module's equation evaluated directly: for each return, the labelled returns whose
    /// voxel is within one of its own on every axis.
    fn by_definition(points: &[Point3<f64>], labels: &[Option<LabelId>], size: f64) -> Vec<Option<LabelId>> {
        let voxel =
            |p: &Point3<f64>| [(p.x / size).floor() as i64, (p.y / size).floor() as i64, (p.z / size).floor() as i64];
        (0..points.len())
            .map(|k| {
                let own = labels[k]?;
                let mut votes = std::collections::BTreeMap::<u16, u32>::new();
                for (q, l) in points.iter().zip(labels) {
                    let (a, b) = (voxel(&points[k]), voxel(q));
                    if let (Some(l), true) = (l, (0..3).all(|d| (a[d] - b[d]).abs() <= 1)) {
                        *votes.entry(l.0).or_default() += 1;
                    }
                }
                let own_votes = votes.get(&own.0).copied().unwrap_or(0);
                // Most votes, then the smaller id; only strictly more than the return's own.
                let best = votes.iter().filter(|(_, c)| **c > own_votes).max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)));
                Some(best.map_or(own, |(l, _)| LabelId(*l)))
            })
            .collect()
    }

    proptest::proptest! {
        #[test]
        fn the_vote_is_its_equation(
            returns in proptest::collection::vec((0.0f64..1.5, 0.0f64..1.5, 0.0f64..0.6, proptest::option::of(0u16..4)), 0..120),
        ) {
            let points: Vec<Point3<f64>> = returns.iter().map(|r| Point3::new(r.0, r.1, r.2)).collect();
            let labels: Vec<Option<LabelId>> = returns.iter().map(|r| r.3.map(LabelId)).collect();
            let config = LabelVote::default();
            proptest::prop_assert_eq!(vote(&points, &labels, &config, |_| true), by_definition(&points, &labels, config.voxel_m));
        }
    }

    #[test]
    fn an_isolated_return_and_a_tie_keep_their_labels() {
        let points = vec![Point3::new(0.0, 0.0, 0.0), Point3::new(10.0, 0.0, 0.0), Point3::new(10.1, 0.0, 0.0)];
        let labels = vec![Some(CHAIR), Some(CHAIR), Some(WALL)];
        let voted = vote(&points, &labels, &LabelVote::default(), |_| true);
        assert_eq!(voted, labels);
    }

    #[test]
    fn off_or_mismatched_input_changes_nothing() {
        let (points, labels, _) = scene();
        let off = LabelVote { voxel_m: 0.0 };
        assert_eq!(vote(&points, &labels, &off, |_| true), labels);
        assert_eq!(vote(&points[1..], &labels, &LabelVote::default(), |_| true), labels);
        let mut bad = points.clone();
        bad[0] = Point3::new(f64::NAN, 0.0, 0.0);
        assert_eq!(vote(&bad, &labels, &LabelVote::default(), |_| true)[0], labels[0]);
    }
}
