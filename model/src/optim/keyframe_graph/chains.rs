//! Neighbours' own chains in our pose graph (`optimiser.share_factors`; the log they come from
//! is [`crate::optim::shared_factors`]).
//!
//! A slice of neighbour r's log adds its keyframes as variables X_(r,j) (placed at A_r · T_r(j),
//! A_r its anchor, T_r(j) its pose in r's world) and its factors between them; an inter-robot
//! factor r measured from its keyframe j to our keyframe i (z = T_j⁻¹ T_i, information Ω) is
//! held from our side, as ours are, inverted:
//!
//! ```text
//! z' = z⁻¹,   S' = S · Ad(z⁻¹)        (Sᵀ S = Ω; e' = Log(z · X_j⁻¹ · X_i) = −Ad(z) · e)
//! ```
//!
//! A neighbour keyframe the chain holds is no longer tied to the anchor by its marginal (the
//! tie's information becomes zero): the chain's factors carry that information already, and
//! counting both would count it twice. The chain's first keyframe takes the anchor's weak
//! prior, which holds the gauge while no inter-robot factor reaches the chain.
//!
//! Both robots then solve the same graph, each in its own gauge: ours holds our first
//! keyframe where our prior puts it, the neighbour's holds its first keyframe 0_r at T_r(0_r),
//! where its own prior does. So after each solve the anchor is that gauge — the transform that
//! carries the neighbour's solve into ours —
//!
//! ```text
//! A_r = X_(r,0_r) · T_r(0_r)⁻¹
//! ```
//!
//! (levelled in gravity-aligned worlds), taken once the chain holds every neighbour keyframe
//! still tied to the anchor (before, the chain is not yet joined to the keyframes our factors
//! reach, and the solve's anchor stands). A fit of the neighbour's poses to our solve of them
//! would average over poses it told us at different times, the older ones since moved by its
//! later solves. A neighbour's chain holds at most the configured number
//! of keyframes and factors ([`KeyframeGraph::set_chain_bound`]); a slice beyond it is refused
//! and the status says so.

use super::{KeyframeGraph, ANCHOR_PRIOR_SIGMAS};
use crate::geometry::{levelled, Pose3};
use crate::optim::factors::{Between, Prior};
use crate::optim::gravity::{gravity_priors, unit_up};
use crate::optim::manifold::Manifold;
use crate::optim::shared_factors::{LogSlice, SharedKind};
use crate::scene_graph::{KeyframeId, KeyframeRef, RobotId};
use nalgebra::{Matrix6, Vector3};
use std::collections::BTreeMap;

/// Keyframes and factors one neighbour's chain holds at most, unless set otherwise: about
/// 25 000 keyframes with their odometry (hours of a mission at a keyframe a second), some
/// 10 MB of graph.
pub const DEFAULT_CHAIN_ITEMS: usize = 50_000;

/// What we hold of one neighbour's chain.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NeighbourChain {
    /// The position in the neighbour's log to ask from next.
    pub next: u32,
    /// Its keyframes' poses in its world, as it last told them.
    pub poses: BTreeMap<KeyframeId, Pose3>,
    /// Its keyframes' measured ups (gravity-aligned worlds).
    pub ups: BTreeMap<KeyframeId, Vector3<f64>>,
    /// Its factors held.
    pub factors: u64,
    /// Its factors not held: an end we do not hold, or an information that is not positive
    /// definite.
    pub dropped: u64,
    /// A slice was refused: it would have held more than the bound.
    pub full: bool,
}

/// What [`KeyframeGraph::add_chain`] did with a slice.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChainAdded {
    Added {
        keyframes: usize,
        factors: usize,
        dropped: usize,
    },
    /// No anchor for the neighbour (not aligned, or withdrawn since we asked): nothing held.
    NotAligned,
    /// The slice does not start where the chain ends (a reply to an older request): ignored.
    Stale,
    /// It would take the chain beyond its bound: refused.
    Full,
}

/// One neighbour's chain in the status.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct ChainCounts {
    pub robot: RobotId,
    pub keyframes: usize,
    pub factors: u64,
    pub dropped: u64,
    pub full: bool,
}

/// The factor from our keyframe to the neighbour's, given the neighbour's from its keyframe to
/// ours (see the module's documentation).
pub(super) fn inverted(measured: &Pose3, sqrt_information: &Matrix6<f64>) -> (Pose3, Matrix6<f64>) {
    let inverse = measured.inverse();
    (inverse, sqrt_information * inverse.adjoint())
}

impl KeyframeGraph {
    /// Keyframes and factors one neighbour's chain may hold.
    pub fn set_chain_bound(&mut self, max_items: usize) {
        self.chain_bound = Some(max_items);
    }

    /// Our log for `receiver` from `from` on, at most `max_items` keyframes and factors, with
    /// our keyframes' poses now and their measured ups.
    pub fn factor_slice(&self, receiver: RobotId, from: u32, max_items: usize) -> LogSlice {
        let (ups, _) = self.measured_ups();
        let pose_of = |k: KeyframeId| {
            let i = *self.index.get(&KeyframeRef::Local(k))?;
            Some((self.graph.values[i], ups.get(&k).copied()))
        };
        self.log.slice(receiver, from, max_items, pose_of)
    }

    /// The neighbours whose chains to ask for, and from where: every neighbour with an anchor
    /// whose chain is not full.
    pub fn chain_requests(&self) -> Vec<(RobotId, u32)> {
        self.anchors
            .keys()
            .filter_map(|r| match self.chains.get(r) {
                Some(c) if c.full => None,
                Some(c) => Some((*r, c.next)),
                None => Some((*r, 0)),
            })
            .collect()
    }

    /// Whether `robot`'s chain holds `keyframe`.
    pub(super) fn chain_covers(&self, robot: RobotId, keyframe: KeyframeId) -> bool {
        self.chains.get(&robot).is_some_and(|c| c.poses.contains_key(&keyframe))
    }

    /// Adds a slice of `robot`'s log (see the module's documentation).
    pub fn add_chain(&mut self, robot: RobotId, slice: &LogSlice) -> ChainAdded {
        let Some(&anchor) = self.anchors.get(&robot) else { return ChainAdded::NotAligned };
        let mut chain = self.chains.remove(&robot).unwrap_or_default();
        let outcome = self.add_to_chain(robot, anchor, &mut chain, slice);
        self.chains.insert(robot, chain);
        outcome
    }

    fn add_to_chain(
        &mut self,
        robot: RobotId,
        anchor: usize,
        chain: &mut NeighbourChain,
        slice: &LogSlice,
    ) -> ChainAdded {
        if slice.from != chain.next || slice.next < slice.from {
            return ChainAdded::Stale;
        }
        let held = chain.poses.len() as u64 + chain.factors;
        let bound = self.chain_bound.unwrap_or(DEFAULT_CHAIN_ITEMS) as u64;
        if held + slice.items() as u64 > bound {
            chain.full = true;
            return ChainAdded::Full;
        }
        let anchor_value = self.graph.values[anchor];
        for k in &slice.keyframes {
            let r = KeyframeRef::Remote { robot, keyframe: k.keyframe };
            let first = chain.poses.is_empty();
            chain.poses.insert(k.keyframe, k.pose);
            if let Some(up) = k.up.filter(unit_up) {
                chain.ups.insert(k.keyframe, up);
            }
            let i = self.variable(r, anchor_value * k.pose);
            // Its marginal's information is in the chain's factors now.
            if let Some(tie) = self.tie_mut(anchor, i) {
                tie.sqrt_information = Matrix6::zeros();
            }
            if first {
                self.graph.add_prior_at_current(i, ANCHOR_PRIOR_SIGMAS);
            }
        }
        let (mut factors, mut dropped) = (0, 0);
        for f in &slice.factors {
            let theirs = |k: KeyframeId| KeyframeRef::Remote { robot, keyframe: k };
            let (from, to) = match f.kind {
                SharedKind::InterRobot => (KeyframeRef::Local(f.to), theirs(f.from)),
                SharedKind::Odometry | SharedKind::Loop => (theirs(f.from), theirs(f.to)),
            };
            let ends = self.index.get(&from).copied().zip(self.index.get(&to).copied());
            let (Some((from, to)), Some(s)) = (ends, super::sqrt_information(&f.information)) else {
                dropped += 1;
                continue;
            };
            let (measured, sqrt_information) = match f.kind {
                SharedKind::InterRobot => inverted(&f.measured, &s),
                _ => (f.measured, s),
            };
            self.graph.betweens.push(Between { from, to, measured, sqrt_information });
            self.candidates.push(f.kind != SharedKind::Odometry);
            factors += 1;
        }
        chain.factors += factors as u64;
        chain.dropped += dropped as u64;
        chain.next = slice.next;
        ChainAdded::Added { keyframes: slice.keyframes.len(), factors, dropped }
    }

    /// Neighbour keyframe variables with their robot and their pose in its world as it last
    /// told it: the chains' keyframes.
    pub(super) fn chain_remote_poses(&self) -> Vec<(usize, RobotId, Pose3)> {
        let mut out = Vec::new();
        for (robot, chain) in &self.chains {
            for (k, pose) in &chain.poses {
                if let Some(&i) = self.index.get(&KeyframeRef::Remote { robot: *robot, keyframe: *k }) {
                    out.push((i, *robot, *pose));
                }
            }
        }
        out
    }

    /// Gravity priors on the chains' keyframes whose up their robot measured, at `sigma_rad`.
    pub(super) fn chain_gravity_priors(&self, sigma_rad: f64) -> Vec<Prior<Pose3, 6>> {
        let mut out = Vec::new();
        for (robot, chain) in &self.chains {
            let variable_of = |k| self.index.get(&KeyframeRef::Remote { robot: *robot, keyframe: k }).copied();
            out.extend(gravity_priors(&chain.ups, &BTreeMap::new(), variable_of, &self.graph.values, sigma_rad));
        }
        out
    }

    /// Each chained neighbour's anchor becomes the gauge between its graph and our solve of it
    /// (see the module's documentation), once its chain holds every neighbour keyframe tied to
    /// the anchor; until then the solve's anchor stands.
    pub(super) fn gauge_chained_anchors(&mut self) {
        for (robot, chain) in &self.chains {
            let Some(&anchor) = self.anchors.get(robot) else { continue };
            // Its first keyframe: the one its own prior holds.
            let Some((first, pose_in_remote)) = chain.poses.first_key_value() else { continue };
            let Some(&i) = self.index.get(&KeyframeRef::Remote { robot: *robot, keyframe: *first }) else { continue };
            let keyframe_of = |v: usize| self.index.iter().find(|(_, i)| **i == v).map(|(r, _)| *r);
            let uncovered = self.graph.betweens.iter().zip(&self.candidates).any(|(b, candidate)| {
                !candidate
                    && b.from == anchor
                    && b.sqrt_information != Matrix6::zeros()
                    && matches!(keyframe_of(b.to), Some(KeyframeRef::Remote { keyframe, .. }) if !chain.poses.contains_key(&keyframe))
            });
            if uncovered {
                continue;
            }
            let gauge = self.graph.values[i] * pose_in_remote.inverse();
            self.graph.values[anchor] = if self.level { levelled(&gauge) } else { gauge };
        }
    }

    /// Each chain at a glance.
    pub(super) fn chain_counts(&self) -> Vec<ChainCounts> {
        self.chains
            .iter()
            .map(|(robot, c)| ChainCounts {
                robot: *robot,
                keyframes: c.poses.len(),
                factors: c.factors,
                dropped: c.dropped,
                full: c.full,
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{pose_from_rpy_translation, pose_from_yaw_translation};
    use crate::optim::graph::{Graph3, GTSAM_PRIOR_SIGMAS_3D};
    use crate::optim::solver::{least_squares, optimize_with, LmParams, Structure};
    use crate::scene_graph::{Keyframe, KeyframeEdge, KeyframeEdgeKind};
    use proptest::prelude::*;

    const A: RobotId = RobotId(0);
    const B: RobotId = RobotId(1);
    const N: u32 = 6;

    fn information() -> Matrix6<f64> {
        Matrix6::from_diagonal(&nalgebra::Vector6::new(1e4, 1e4, 1e4, 400.0, 400.0, 400.0))
    }

    /// Robot `seed`'s true path in its own world, and its odometry steps, wrong by a few cm and
    /// mrad each.
    fn truth(seed: u32) -> Vec<Pose3> {
        (0..N)
            .map(|k| {
                pose_from_yaw_translation(
                    0.3 * f64::from(k),
                    Vector3::new(f64::from(k) * 2.0, 0.5 * f64::from(seed), 0.0),
                )
            })
            .collect()
    }

    fn noisy_step(truth: &[Pose3], k: usize, seed: u32) -> Pose3 {
        let e = f64::from(seed + 1) * 0.01 * (k as f64 + 1.0).sin();
        truth[k - 1].inverse()
            * truth[k]
            * pose_from_rpy_translation(e * 0.1, -e * 0.2, e * 0.5, Vector3::new(e, -e, 0.5 * e))
    }

    /// A robot's graph of its own keyframes (each placed by its noisy odometry) and their
    /// odometry factors.
    fn own_graph(seed: u32) -> (KeyframeGraph, Vec<Pose3>) {
        let truth = truth(seed);
        let mut graph = KeyframeGraph::default();
        let mut pose = truth[0];
        for k in 0..N as usize {
            let mut edges = Vec::new();
            if k > 0 {
                let step = noisy_step(&truth, k, seed);
                pose *= step;
                edges.push(KeyframeEdge {
                    kind: KeyframeEdgeKind::Odometry,
                    from: KeyframeId(k as u32 - 1),
                    to: KeyframeRef::Local(KeyframeId(k as u32)),
                    from_from_to: step,
                    information: information(),
                });
            }
            graph.add_keyframe(
                &Keyframe { id: KeyframeId(k as u32), stamp: k as f64, world_from_body: pose },
                &edges,
                100,
            );
        }
        (graph, truth)
    }

    /// Two robots, each with an inter-robot factor of its own (A's keyframe 3 to B's 2; B's 4 to
    /// A's 1) and the other's keyframe served with a loose covariance. b_in_a: B's world in A's.
    fn pair() -> (KeyframeGraph, KeyframeGraph, Pose3) {
        let (mut a, truth_a) = own_graph(0);
        let (mut b, truth_b) = own_graph(1);
        let b_in_a = pose_from_yaw_translation(0.7, Vector3::new(3.0, -1.0, 0.0));
        let loose = Matrix6::identity() * 0.04;
        // Measured from the truth, a little off.
        let off = pose_from_yaw_translation(0.01, Vector3::new(0.05, -0.03, 0.0));
        let a3_from_b2 = truth_a[3].inverse() * b_in_a * truth_b[2] * off;
        a.add_neighbour(
            B,
            &b_in_a,
            &[(KeyframeId(2), truth_b[2], loose)],
            &[(KeyframeId(3), KeyframeId(2), a3_from_b2, information())],
        );
        let b4_from_a1 = truth_b[4].inverse() * b_in_a.inverse() * truth_a[1] * off.inverse();
        b.add_neighbour(
            A,
            &b_in_a.inverse(),
            &[(KeyframeId(1), truth_a[1], loose)],
            &[(KeyframeId(4), KeyframeId(1), b4_from_a1, information())],
        );
        (a, b, b_in_a)
    }

    /// `writer`'s log read whole by `reader`, in slices of `max_items`.
    fn read(
        reader: &mut KeyframeGraph,
        reader_robot: RobotId,
        writer: &KeyframeGraph,
        writer_robot: RobotId,
        max_items: usize,
    ) {
        loop {
            let from = reader.chain_requests().into_iter().find(|(r, _)| *r == writer_robot).map(|(_, f)| f).unwrap();
            let slice = writer.factor_slice(reader_robot, from, max_items);
            if slice.next == from {
                break;
            }
            assert!(matches!(reader.add_chain(writer_robot, &slice), ChainAdded::Added { dropped: 0, .. }));
        }
    }

    fn exchange(a: &mut KeyframeGraph, b: &mut KeyframeGraph, max_items: usize) {
        read(a, A, b, B, max_items);
        read(b, B, a, A, max_items);
    }

    /// The pair's graph written by hand: A's prior on its first keyframe, both robots'
    /// odometry, both inter-robot factors; variables A0..A5, B0..B5.
    fn joint(a: &KeyframeGraph, b: &KeyframeGraph) -> Vec<Pose3> {
        let mut g = Graph3::default();
        let b_in_a = a.graph.values[a.anchors[&B]];
        for k in 0..N {
            g.keys.push(u64::from(k));
            g.values.push(a.graph.values[a.index[&KeyframeRef::Local(KeyframeId(k))]]);
            g.fixed.push(false);
        }
        for k in 0..N {
            g.keys.push(u64::from(k + N));
            g.values.push(b_in_a * b.graph.values[b.index[&KeyframeRef::Local(KeyframeId(k))]]);
            g.fixed.push(false);
        }
        g.add_prior_at_current(0, GTSAM_PRIOR_SIGMAS_3D);
        let var = |robot: RobotId, k: u32| if robot == A { k as usize } else { (k + N) as usize };
        for (robot, graph) in [(A, a), (B, b)] {
            let other = if robot == A { B } else { A };
            for (bw, candidate) in graph.graph.betweens.iter().zip(&graph.candidates) {
                let key = |i: usize| graph.index.iter().find(|(_, v)| **v == i).map(|(r, _)| *r);
                match (key(bw.from), key(bw.to)) {
                    (Some(KeyframeRef::Local(f)), Some(KeyframeRef::Local(t))) => {
                        g.betweens.push(Between { from: var(robot, f.0), to: var(robot, t.0), ..bw.clone() })
                    }
                    (Some(KeyframeRef::Local(f)), Some(KeyframeRef::Remote { keyframe, .. })) if *candidate => {
                        g.betweens.push(Between { from: var(robot, f.0), to: var(other, keyframe.0), ..bw.clone() })
                    }
                    _ => {}
                }
            }
        }
        let structure = Structure::new(&g).unwrap();
        optimize_with(&mut g, &LmParams::default(), &structure, &least_squares).unwrap();
        g.values
    }

    fn close(x: &Pose3, y: &Pose3, tol: f64) -> bool {
        (x.translation.vector - y.translation.vector).norm() < tol && x.rotation.angle_to(&y.rotation) < tol
    }

    /// With each other's logs, each robot's solve is the pair's whole graph: A's own poses
    /// equal the hand-written joint graph's, and B's solve places A relative to B as the joint
    /// graph does (its gauge is B's own first keyframe, so relative poses are compared).
    #[test]
    fn each_robot_solves_the_pairs_whole_graph() {
        let (mut a, mut b, _) = pair();
        // Before the exchange: each graph's factors are its own.
        let expected = joint(&a, &b);
        exchange(&mut a, &mut b, 5);
        let solved_a = a.solve(false, 0).unwrap();
        for (k, pose) in &solved_a.poses {
            assert!(close(pose, &expected[k.0 as usize], 1e-5), "A{}: {pose:?} vs {:?}", k.0, expected[k.0 as usize]);
        }
        let solved_b = b.solve(false, 0).unwrap();
        let a_chain = |k: u32| b.graph.values[b.index[&KeyframeRef::Remote { robot: A, keyframe: KeyframeId(k) }]];
        for (j, pose_b) in &solved_b.poses {
            for i in 0..N {
                let in_b = a_chain(i).inverse() * pose_b;
                let in_joint = expected[i as usize].inverse() * expected[(j.0 + N) as usize];
                assert!(close(&in_b, &in_joint, 1e-5), "A{i} to B{}", j.0);
            }
        }
        // Without the chains, A's poses are another answer: the test can fail.
        let (mut lone, _, _) = pair();
        let alone = lone.solve(false, 0).unwrap();
        assert!(alone.poses.iter().any(|(k, p)| !close(p, &expected[k.0 as usize], 1e-3)));
        // The served keyframes' ties weigh nothing now.
        let tie =
            a.tie_mut(a.anchors[&B], a.index[&KeyframeRef::Remote { robot: B, keyframe: KeyframeId(2) }]).unwrap();
        assert_eq!(tie.sqrt_information, Matrix6::zeros());
    }

    /// A's anchor for B is the gauge between B's graph and A's solve of it: it carries B's
    /// first keyframe, where B's own prior holds it, onto A's solve of that keyframe, and then
    /// B's own solve of every keyframe onto A's (both solved the pair's whole graph), within the
    /// solver's tolerance; until the chain holds the keyframe B served A, the tie's anchor stands.
    #[test]
    fn the_anchor_is_the_gauge_between_the_neighbours_solve_and_ours() {
        let (mut a, mut b, b_in_a) = pair();
        // A first slice without keyframe 2, which A holds by its tie: not joined yet.
        let partial = b.factor_slice(A, 0, 3);
        assert!(!partial.keyframes.iter().any(|k| k.keyframe == KeyframeId(2)));
        a.add_chain(B, &partial);
        let tied = a.solve(false, 0).unwrap().anchors[0].1;
        let mut tie_only = pair().0;
        let before = tie_only.solve(false, 0).unwrap().anchors[0].1;
        assert!(close(&tied, &before, 1e-6), "the solve's anchor stands: {tied:?} vs {before:?}");
        // Afresh: the whole log.
        a = pair().0;
        exchange(&mut a, &mut b, 100);
        let solved_b = b.solve(false, 0).unwrap();
        let solved_a = a.solve(false, 0).unwrap();
        let anchor = solved_a.anchors.iter().find(|(r, _)| *r == B).unwrap().1;
        let chain = |k: u32| a.graph.values[a.index[&KeyframeRef::Remote { robot: B, keyframe: KeyframeId(k) }]];
        let told_first = a.chains[&B].poses[&KeyframeId(0)];
        assert!(close(&(anchor * told_first), &chain(0), 1e-9));
        for (k, own) in &solved_b.poses {
            assert!(close(&(anchor * own), &chain(k.0), 1e-4), "B{}: {:?} vs {:?}", k.0, anchor * own, chain(k.0));
        }
        assert!(close(&anchor, &b_in_a, 0.2), "{anchor:?}");
    }

    #[test]
    fn slices_out_of_turn_unaligned_or_beyond_the_bound_are_refused() {
        let (mut a, b, _) = pair();
        let slice = b.factor_slice(A, 0, 4);
        assert_eq!(a.add_chain(RobotId(7), &slice), ChainAdded::NotAligned);
        let later = b.factor_slice(A, 2, 4);
        assert_eq!(a.add_chain(B, &later), ChainAdded::Stale);
        assert!(matches!(a.add_chain(B, &slice), ChainAdded::Added { .. }));
        assert_eq!(a.add_chain(B, &slice), ChainAdded::Stale, "the same reply twice");
        a.set_chain_bound(6);
        let next = b.factor_slice(A, slice.next, 4);
        assert_eq!(a.add_chain(B, &next), ChainAdded::Full);
        assert!(a.chain_requests().is_empty(), "a full chain is not asked again");
        assert!(a.status().chains[0].full);
        // A factor to a keyframe we do not hold is dropped and counted.
        let mut c = pair().0;
        let mut bad = b.factor_slice(A, 0, 100);
        bad.factors[0].to = KeyframeId(999);
        assert!(matches!(c.add_chain(B, &bad), ChainAdded::Added { dropped: 1, .. }));
        assert_eq!(c.status().chains[0].dropped, 1);
    }

    /// In gravity-aligned worlds the ups a neighbour measured travel with its keyframes, and
    /// each of its chain's keyframes takes a gravity prior from them, as its own graph does;
    /// without gravity priors none.
    #[test]
    fn a_neighbours_measured_ups_hold_its_chain_to_gravity() {
        let (mut a, mut b, _) = pair();
        let tilted = nalgebra::UnitQuaternion::from_euler_angles(0.01, -0.02, 0.3);
        for k in 0..N {
            assert!(b.record_tilt(KeyframeId(k), &tilted));
        }
        exchange(&mut a, &mut b, 100);
        assert_eq!(a.chains[&B].ups.len(), N as usize);
        assert!((a.chains[&B].ups[&KeyframeId(3)] - tilted.inverse() * Vector3::z()).norm() < 1e-12);
        assert!(a.gravity_priors().is_empty(), "no gravity priors unless set");
        a.set_gravity_priors(Some(0.2_f64.to_radians()));
        let held: Vec<usize> = a.gravity_priors().iter().map(|p| p.variable).collect();
        let chain: Vec<usize> =
            (0..N).map(|k| a.index[&KeyframeRef::Remote { robot: B, keyframe: KeyframeId(k) }]).collect();
        assert_eq!(held, chain, "one prior on each of its keyframes, and none on ours (no tilt recorded)");
    }

    #[test]
    fn a_withdrawn_neighbours_chain_goes_and_a_frozen_graph_keeps_its_chains() {
        let (mut a, mut b, _) = pair();
        exchange(&mut a, &mut b, 100);
        let thawed = KeyframeGraph::thaw(a.freeze()).unwrap();
        assert_eq!(thawed.chains, a.chains);
        assert_eq!(thawed.log, a.log);
        let local = a.index.keys().filter(|r| matches!(r, KeyframeRef::Local(_))).count();
        a.withdraw_neighbour(B);
        assert!(a.chains.is_empty());
        assert_eq!(a.variables(), local);
        assert!(a.factor_slice(B, 0, 100).factors.iter().all(|f| f.kind != SharedKind::InterRobot));
    }

    proptest! {
        /// The inverted factor's whitened residual has the same norm as the original's at any
        /// values: the same measurement, seen from the other end.
        #[test]
        fn an_inverted_factor_weighs_the_same(
            z in prop::array::uniform6(-1.0f64..1.0),
            a in prop::array::uniform6(-2.0f64..2.0),
            b in prop::array::uniform6(-2.0f64..2.0),
            s in prop::array::uniform6(0.5f64..3.0),
        ) {
            let pose = |v: [f64; 6]| pose_from_rpy_translation(v[0], v[1], v[2], Vector3::new(v[3], v[4], v[5]) * 3.0);
            let (z, xi, xj) = (pose(z), pose(a), pose(b));
            let mut sqrt_information = Matrix6::from_diagonal(&nalgebra::Vector6::from_row_slice(&s));
            sqrt_information[(0, 4)] = 0.3;
            let original = Between { from: 0, to: 1, measured: z, sqrt_information };
            let (measured, sqrt_information) = inverted(&z, &sqrt_information);
            let flipped = Between { from: 1, to: 0, measured, sqrt_information };
            let r = original.whitened_error(&xi, &xj).norm();
            let r_flipped = flipped.whitened_error(&xj, &xi).norm();
            prop_assert!((r - r_flipped).abs() < 1e-9 * (1.0 + r), "{} vs {}", r, r_flipped);
        }
    }
}
