//! The k-nearest-neighbour graph of a fixed cloud, built lazily, and a nearest-point search that
//! starts from a hint and gives exactly the kd-tree's answer.
//!
//! ICP asks for the nearest target point of every source point on every pass, and after the
//! first pass the pose moves by millimetres: the answer is the last pass's point or one of its
//! neighbours (the idea of Greenspan & Yurick 2003, "Approximate k-d tree search for efficient
//! ICP", 3DIM, made exact here). From the hint q, the search walks the graph — to the neighbour
//! of q nearest to p while it is nearer than q — and the walk's end q* is certified by the
//! triangle inequality: every point t at least as near p as q* is within 2‖p − q*‖ of q*,
//!
//! ```text
//! ‖t − q*‖ ≤ ‖t − p‖ + ‖p − q*‖ ≤ 2‖p − q*‖
//! ```
//!
//! so when 2‖p − q*‖ is below q*'s cover radius ρ (the distance of its k-th neighbour, or the
//! search radius when it has fewer than k: within ρ its list holds every point), every
//! contender is in q*'s list, which the walk has already compared. The answer must also be
//! unique (no other listed point at the same distance): the kd-tree breaks ties by its own
//! order. Otherwise, and with no hint, the kd-tree answers. Distances are the kd-tree's own
//! (single precision, summed x, y, z), so the two paths return the same bits.
//!
//! Each point's list is the kd-tree's `nearest_k_within`, in its order, computed on first use:
//! the same list serves the surface normal at that point (`perception::normals`).
//!
//! A caller that wants only answers within the radius ([`NeighbourGraph::nearest_within`], as
//! ICP does) is told `None` without a search when the query's cell is beyond the cloud's
//! [`Reach`].

use super::point_tree::{squared_distance, PointTree};
use super::reach::Reach;
use nalgebra::Point3;
use rustc_hash::FxHashMap;
use std::borrow::Cow;

/// Graph steps a search takes before it hands over to the kd-tree.
const MAX_STEPS: usize = 8;

/// A list not yet computed.
const UNKNOWN: u32 = u32::MAX;

/// The k-nearest graph of `points` within `radius`, built on demand, over a kd-tree. The lists
/// are flat, k slots a point, each neighbour's key beside its index, so a search reads one
/// contiguous run per step.
pub struct NeighbourGraph<'a> {
    points: Cow<'a, [Point3<f64>]>,
    keys: Vec<[f32; 3]>,
    tree: PointTree,
    k: usize,
    radius: f64,
    /// Per point: its list's length (`UNKNOWN` until computed) and squared cover radius ρ²
    /// (single precision, as the kd-tree measures: within ρ the list holds every point).
    len: Vec<u32>,
    cover2: Vec<f32>,
    items: Vec<u32>,
    item_keys: Vec<[f32; 3]>,
    /// Built on the first [`NeighbourGraph::nearest_within`].
    reach: Option<Reach>,
}

impl<'a> NeighbourGraph<'a> {
    /// The graph of up to `k` neighbours within `radius` m of each of `points` (fewer than 2³²),
    /// borrowed or owned (a graph kept for several searches' sake owns its cloud).
    pub fn new(points: impl Into<Cow<'a, [Point3<f64>]>>, k: usize, radius: f64) -> Self {
        let points = points.into();
        let k = k.max(1);
        Self {
            keys: points.iter().map(PointTree::key).collect(),
            tree: PointTree::new(&points),
            k,
            radius,
            len: vec![UNKNOWN; points.len()],
            cover2: vec![0.0; points.len()],
            items: vec![0; points.len() * k],
            item_keys: vec![[0.0; 3]; points.len() * k],
            reach: None,
            points,
        }
    }

    /// The cloud.
    pub fn points(&self) -> &[Point3<f64>] {
        &self.points
    }

    /// Up to k neighbours of point `i` within the radius (itself included), in the kd-tree's
    /// order.
    pub fn neighbours(&mut self, i: usize) -> &[u32] {
        self.neighbours_in(i).1
    }

    /// The cloud and point `i`'s neighbours, together (a normal is fitted from both).
    pub fn neighbours_in(&mut self, i: usize) -> (&[Point3<f64>], &[u32]) {
        let n = self.ensure(i);
        (&self.points, &self.items[i * self.k..i * self.k + n])
    }

    /// Computes point `i`'s list if it is not yet known; its length.
    fn ensure(&mut self, i: usize) -> usize {
        if self.len[i] != UNKNOWN {
            return self.len[i] as usize;
        }
        let (found, cover2) = self.computed(i);
        self.store(i, &found, cover2);
        found.len()
    }

    /// Point `i`'s list as the kd-tree gives it (neighbour, squared distance), and ρ².
    fn computed(&self, i: usize) -> (Vec<(u32, f32)>, f32) {
        let found = self.tree.nearest_k_within_distances(&self.points[i], self.k, self.radius);
        let cover2 = match found.len() < self.k {
            true => (self.radius * self.radius) as f32,
            false => found.iter().map(|n| n.1).fold(0.0, f32::max),
        };
        (found, cover2)
    }

    fn store(&mut self, i: usize, found: &[(u32, f32)], cover2: f32) {
        for (slot, &(j, _)) in found.iter().enumerate() {
            self.items[i * self.k + slot] = j;
            self.item_keys[i * self.k + slot] = self.keys[j as usize];
        }
        (self.cover2[i], self.len[i]) = (cover2, found.len() as u32);
    }

    /// Squared distance to, and index of, the nearest point to `p`: the kd-tree's answer, found
    /// from `hint` (a point near the answer, e.g. the last pass's) when the graph can certify
    /// it (module notes). `None` for an empty cloud.
    pub fn nearest(&mut self, p: &Point3<f64>, hint: Option<usize>) -> Option<(f64, usize)> {
        walk_from(self, p, hint).or_else(|| self.tree.nearest(p))
    }

    /// [`NeighbourGraph::nearest`] when a point may be within the graph's radius of `p`;
    /// `None` when none is (the answer may still lie beyond the radius: callers check).
    pub fn nearest_within(&mut self, p: &Point3<f64>, hint: Option<usize>) -> Option<(f64, usize)> {
        if let Some(found) = walk_from(self, p, hint) {
            return Some(found);
        }
        let (points, radius) = (&self.points, self.radius);
        if !self.reach.get_or_insert_with(|| Reach::new(points, radius)).may_reach(p) {
            return None;
        }
        self.tree.nearest(p)
    }

    /// The graph made ready for searches from several threads at once (its reach built): each
    /// takes a [`SharedSearch`], whose answers are the graph's own, and the lists they computed
    /// are given back with [`NeighbourGraph::absorb`].
    pub fn shared(&mut self) -> &Self {
        let (points, radius) = (&self.points, self.radius);
        self.reach.get_or_insert_with(|| Reach::new(points, radius));
        self
    }

    /// A search of this graph that leaves it unchanged (see [`NeighbourGraph::shared`]).
    pub fn search(&self) -> SharedSearch<'_, 'a> {
        SharedSearch { graph: self, aside: Aside::default() }
    }

    /// Keeps the lists a [`SharedSearch`] computed aside. A list depends on the cloud alone, so
    /// whichever search computed it, it is the one [`NeighbourGraph::ensure`] would store.
    pub fn absorb(&mut self, aside: Aside) {
        for (&i, &(start, len, cover2)) in &aside.at {
            let i = i as usize;
            if self.len[i] == UNKNOWN {
                let (run, to) = (start as usize..(start + len) as usize, i * self.k..i * self.k + len as usize);
                self.items[to.clone()].copy_from_slice(&aside.items[run.clone()]);
                self.item_keys[to].copy_from_slice(&aside.item_keys[run]);
                (self.cover2[i], self.len[i]) = (cover2, len);
            }
        }
    }

    #[cfg(test)]
    fn walk(&mut self, p: &Point3<f64>, start: usize) -> Option<(f64, usize)> {
        walk(self, p, start)
    }
}

/// Where a walk reads the lists: a graph's own, computed into it, or a shared graph's with those
/// it lacks computed aside.
trait Lists {
    fn len(&self) -> usize;
    fn key(&self, i: usize) -> &[f32; 3];
    /// Point `i`'s neighbours, their keys, and its squared cover radius ρ².
    fn list(&mut self, i: usize) -> (&[u32], &[[f32; 3]], f32);
}

impl Lists for NeighbourGraph<'_> {
    fn len(&self) -> usize {
        self.points.len()
    }

    fn key(&self, i: usize) -> &[f32; 3] {
        &self.keys[i]
    }

    fn list(&mut self, i: usize) -> (&[u32], &[[f32; 3]], f32) {
        let n = self.ensure(i);
        let run = i * self.k..i * self.k + n;
        (&self.items[run.clone()], &self.item_keys[run], self.cover2[i])
    }
}

/// The walk's certified answer from a valid hint.
fn walk_from(lists: &mut impl Lists, p: &Point3<f64>, hint: Option<usize>) -> Option<(f64, usize)> {
    hint.filter(|&h| h < lists.len()).and_then(|h| walk(lists, p, h))
}

fn walk(lists: &mut impl Lists, p: &Point3<f64>, start: usize) -> Option<(f64, usize)> {
    let key = PointTree::key(p);
    let (mut at, mut best) = (start, squared_distance(&key, lists.key(start)));
    for _ in 0..MAX_STEPS {
        let (items, keys, cover2) = lists.list(at);
        let (mut next, mut next_d2, mut tied) = (at, best, false);
        for (&j, other) in items.iter().zip(keys) {
            let d2 = squared_distance(&key, other);
            if d2 < next_d2 {
                (next, next_d2, tied) = (j as usize, d2, false);
            } else if d2 == next_d2 && j as usize != at {
                tied = true;
            }
        }
        if next != at {
            (at, best) = (next, next_d2);
            continue;
        }
        // No neighbour is nearer: certify (2‖p − q‖ < ρ, with room for rounding).
        let certified = !tied && 4.0 * f64::from(best) * (1.0 + 1e-5) + 1e-12 < f64::from(cover2);
        return certified.then_some((f64::from(best), at));
    }
    None
}

/// Lists a [`SharedSearch`] computed that its graph did not hold: per point, (start, length,
/// ρ²) in the flat runs.
#[derive(Default)]
pub struct Aside {
    at: FxHashMap<u32, (u32, u32, f32)>,
    items: Vec<u32>,
    item_keys: Vec<[f32; 3]>,
}

/// One thread's searches of a shared graph: the graph's lists where it holds them, the rest
/// computed into its own [`Aside`]. Its answers are bit for bit those of the graph's own
/// searches.
pub struct SharedSearch<'g, 'a> {
    graph: &'g NeighbourGraph<'a>,
    aside: Aside,
}

impl SharedSearch<'_, '_> {
    /// The cloud.
    pub fn points(&self) -> &[Point3<f64>] {
        &self.graph.points
    }

    /// As [`NeighbourGraph::nearest_within`].
    pub fn nearest_within(&mut self, p: &Point3<f64>, hint: Option<usize>) -> Option<(f64, usize)> {
        if let Some(found) = walk_from(self, p, hint) {
            return Some(found);
        }
        // `NeighbourGraph::shared` built the reach.
        if self.graph.reach.as_ref().is_some_and(|reach| !reach.may_reach(p)) {
            return None;
        }
        self.graph.tree.nearest(p)
    }

    /// As [`NeighbourGraph::neighbours_in`].
    pub fn neighbours_in(&mut self, i: usize) -> (&[Point3<f64>], &[u32]) {
        let graph = self.graph;
        (&graph.points, self.list(i).0)
    }

    /// What this search computed that the graph lacks.
    pub fn into_aside(self) -> Aside {
        self.aside
    }
}

impl Lists for SharedSearch<'_, '_> {
    fn len(&self) -> usize {
        self.graph.points.len()
    }

    fn key(&self, i: usize) -> &[f32; 3] {
        &self.graph.keys[i]
    }

    fn list(&mut self, i: usize) -> (&[u32], &[[f32; 3]], f32) {
        let graph = self.graph;
        if graph.len[i] != UNKNOWN {
            let run = i * graph.k..i * graph.k + graph.len[i] as usize;
            return (&graph.items[run.clone()], &graph.item_keys[run], graph.cover2[i]);
        }
        let aside = &mut self.aside;
        let (start, len, cover2) = *aside.at.entry(i as u32).or_insert_with(|| {
            let (found, cover2) = graph.computed(i);
            let start = aside.items.len() as u32;
            aside.items.extend(found.iter().map(|n| n.0));
            aside.item_keys.extend(found.iter().map(|n| graph.keys[n.0 as usize]));
            (start, found.len() as u32, cover2)
        });
        let run = start as usize..(start + len) as usize;
        (&aside.items[run.clone()], &aside.item_keys[run], cover2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn cloud(seed: &[(f64, f64, f64)]) -> Vec<Point3<f64>> {
        seed.iter().map(|&(x, y, z)| Point3::new(x, y, z)).collect()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// Whatever the hint, the answer is the kd-tree's, bit for bit.
        #[test]
        fn the_answer_is_the_kd_trees(
            points in prop::collection::vec((-3.0f64..3.0, -3.0f64..3.0, -1.0f64..1.0), 1..300),
            queries in prop::collection::vec((-3.5f64..3.5, -3.5f64..3.5, -1.5f64..1.5, 0usize..1000), 1..60),
            k in 1usize..12,
            radius in 0.05f64..2.0,
        ) {
            let points = cloud(&points);
            let tree = PointTree::new(&points);
            let mut graph = NeighbourGraph::new(&points, k, radius);
            for (x, y, z, h) in queries {
                let q = Point3::new(x, y, z);
                let want = tree.nearest(&q).unwrap();
                // A hint anywhere, and the answer for a point 1 cm away (a pass later).
                let near = tree.nearest(&Point3::new(x + 0.01, y - 0.005, z)).unwrap().1;
                prop_assert_eq!(graph.nearest(&q, Some(near)).unwrap().0.to_bits(), want.0.to_bits());
                let got = graph.nearest(&q, Some(h % points.len())).unwrap();
                // Same distance always; the same point unless two are equally near.
                prop_assert_eq!(got.0.to_bits(), want.0.to_bits());
                prop_assert!(got.1 == want.1 || squared_distance(&PointTree::key(&q), &graph.keys[got.1]) as f64 == want.0);
                prop_assert_eq!(graph.nearest(&q, None), Some(want));
                // Bounded by the radius: the same answer, or none when the nearest is beyond it.
                match graph.nearest_within(&q, Some(near)) {
                    Some(got) => prop_assert_eq!(got.0.to_bits(), want.0.to_bits()),
                    None => prop_assert!(want.0 > radius * radius, "{} within {}", want.0, radius),
                }
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        /// Searches of a shared graph answer as the graph's own, whatever lists it already
        /// holds, and the lists they computed aside are the ones the graph computes itself.
        #[test]
        fn shared_searches_answer_as_the_graph(
            points in prop::collection::vec((-3.0f64..3.0, -3.0f64..3.0, -1.0f64..1.0), 1..200),
            queries in prop::collection::vec((-3.5f64..3.5, -3.5f64..3.5, -1.5f64..1.5, 0usize..1000), 1..40),
            k in 1usize..10,
            radius in 0.05f64..2.0,
        ) {
            let points = cloud(&points);
            let mut own = NeighbourGraph::new(&points, k, radius);
            let mut shared = NeighbourGraph::new(&points, k, radius);
            // The first half of the queries run on the shared graph's own lists first.
            for &(x, y, z, h) in &queries[..queries.len() / 2] {
                shared.nearest_within(&Point3::new(x, y, z), Some(h % points.len()));
            }
            let mut search = shared.shared().search();
            for &(x, y, z, h) in &queries {
                let (q, hint) = (Point3::new(x, y, z), Some(h % points.len()));
                prop_assert_eq!(search.nearest_within(&q, hint), own.nearest_within(&q, hint));
                let i = h % points.len();
                let (a, b) = (search.neighbours_in(i).1.to_vec(), own.neighbours(i).to_vec());
                prop_assert_eq!(a, b);
            }
            let aside = search.into_aside();
            shared.absorb(aside);
            for i in 0..points.len() {
                if shared.len[i] != UNKNOWN {
                    let (a, b) = (shared.neighbours(i).to_vec(), own.neighbours(i).to_vec());
                    prop_assert_eq!(a, b);
                    prop_assert_eq!(shared.cover2[i].to_bits(), own.cover2[i].to_bits());
                }
            }
        }
    }

    #[test]
    fn a_small_move_is_answered_by_the_graph() {
        // A plane sampled every 0.1 m: from the old answer, a query 2 cm away is certified.
        let points: Vec<Point3<f64>> =
            (0..400).map(|i| Point3::new((i % 20) as f64 * 0.1, (i / 20) as f64 * 0.1, 0.0)).collect();
        let mut graph = NeighbourGraph::new(&points, 10, 1.0);
        let q = Point3::new(1.02, 0.51, 0.01);
        let start = graph.tree.nearest(&q).unwrap().1;
        let nudged = Point3::new(1.04, 0.52, 0.012);
        assert_eq!(graph.walk(&nudged, start), graph.tree.nearest(&nudged));
        // Far from every point (beyond half the cover radius), the kd-tree answers.
        assert_eq!(graph.walk(&Point3::new(1.0, 0.5, 0.5), start), None);
        assert_eq!(
            graph.nearest(&Point3::new(1.0, 0.5, 0.5), Some(start)),
            graph.tree.nearest(&Point3::new(1.0, 0.5, 0.5))
        );
        assert_eq!(NeighbourGraph::new(&[], 3, 1.0).nearest(&q, None), None);
    }
}
