//! A robot's pose graph over keyframes, as plain state (paper §III, §IV-E): local keyframes with
//! odometry and intra-robot loop factors, neighbour keyframes as variables with priors from
//! their marginal covariances (expressed in our world through `local_from_remote`), and
//! inter-robot factors — solved by Levenberg–Marquardt ([`super::solver`]). The Optimiser actor
//! owns one and publishes what [`KeyframeGraph::solve`] returns.
//!
//! Each neighbour's world is placed in ours by an *anchor* variable A_r = local_from_remote
//! (Kim et al., "Multiple relative pose graphs for robust cooperative mapping", ICRA 2010). A
//! neighbour keyframe j with pose T_r(j) in the neighbour's world and covariance Σ_j is a
//! variable X_j tied to the anchor by a between factor
//!
//! ```text
//! e_j = Log(T_r(j)⁻¹ · A_r⁻¹ · X_j),   Ω_j = Σ_j⁻¹
//! ```
//!
//! (with right perturbations X_j · Exp(δ) the covariance is unchanged by the left product A_r),
//! and to local keyframes by the inter-robot factors from ICP. The anchor is thus re-estimated
//! from every inter-robot factor at each solve: the more closures over the overlap, the better
//! it is known. A weak prior (σ = 1 km, 100 rad) at its first value keeps it determined while
//! no factor reaches it; against keyframe covariances of centimetres and milliradians it moves
//! the estimate by less than a micrometre.
//!
//! In gravity-aligned worlds (each robot's from an IMU: `matcher.max_tilt_deg = 0`) the anchor
//! is known to be level — yaw and translation only — to about the two worlds' tilt errors, so
//! its prior holds roll and pitch ([`KeyframeGraph::set_level_anchors`]): inter-robot factors from
//! registrations that leave the tilt weakly determined (walls without a shared floor, a sensor at
//! 1.5 m against one at 0.5 m) no longer tilt one map against the other.
//!
//! With outlier rejection, each neighbour's inter-robot factors first go through pairwise
//! consistency maximisation ([`super::consistency`]): those outside the largest mutually
//! consistent set are rejected before the solve (when at least two agree: otherwise there is no
//! evidence to choose by), and when that set — at least three, a strict majority — implies a
//! transform far from the anchor's (evidence against the first alignment) the anchor and the
//! neighbour's keyframes are moved to it. Then each solve is GNC-TLS over the loop and inter-robot factors
//! ([`super::robust::optimize_gnc_incremental_with`]): the previous decision is kept while it
//! still holds, and made again from scratch when it does not. Rejected factors stay in the
//! graph with weight 0 and add no information to the marginals.
//!
//! With `optimiser.share_factors`, every local keyframe and factor of our own measurements goes
//! into a log ([`super::shared_factors`]) that neighbours read, and each aligned neighbour's own
//! log comes into the graph as its chain ([`chains`]): its keyframes and factors in place of
//! the ties, so that the graph is the pair's whole graph.

mod chains;
pub use chains::{ChainAdded, ChainCounts, NeighbourChain, DEFAULT_CHAIN_ITEMS};

use super::consistency::{largest_consistent_set, Consistency, ImpliedClosure};
use super::factors::{Between, Prior};
use super::graph::{Graph3, GTSAM_PRIOR_SIGMAS_3D};
use super::gravity::{gravity_priors, unit_up, up_in_body, yaw_only, MeasuredUp};
use super::marginals::marginal_covariances_with;
use super::robust::{optimize_gnc_incremental_with, rejection_weights, weighted};
use super::shared_factors::FactorLog;
use super::solver::{least_squares, optimize_with, LmParams, SolveError, Structure};
use crate::geometry::{levelled, medoid, pose_error, Pose3};
use crate::scene_graph::{Keyframe, KeyframeEdge, KeyframeEdgeKind, KeyframeId, KeyframeRef, RobotId};
use nalgebra::{Matrix6, UnitQuaternion, Vector3};
use std::collections::{BTreeMap, BTreeSet};

/// The graph and its outlier decisions, as a snapshot keeps them.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct KeyframeGraphState {
    pub graph: Graph3,
    pub index: Vec<(KeyframeRef, usize)>,
    /// Keyframes added since the last solve.
    pub pending: usize,
    pub candidates: Vec<bool>,
    pub rejected: Vec<usize>,
    /// Each neighbour's anchor variable (its local_from_remote).
    pub anchors: Vec<(RobotId, usize)>,
    pub realigned: Vec<(RobotId, u32)>,
    /// Per neighbour, neighbour keyframe priors moved by its pose updates.
    pub refreshed: Vec<(RobotId, u64)>,
    /// Pose updates of keyframes not yet in the graph: (neighbour, keyframe, pose).
    pub deferred: Vec<(RobotId, KeyframeId, Pose3)>,
    /// Neighbour keyframe variables whose tie holds a pose update's mean.
    pub updated: Vec<usize>,
    /// Per neighbour, the withdrawals handled ([`KeyframeGraph::withdraw_neighbour`]).
    pub withdrawals: Vec<(RobotId, u32)>,
    /// Local keyframes' measured tilts: the world's up in each body ([`KeyframeGraph::record_tilt`]).
    pub tilts: Vec<(KeyframeId, Vector3<f64>)>,
    /// Local keyframes measured by an odometry that learns up: each one's attitude in that
    /// odometry's frame ([`KeyframeGraph::record_up`]).
    pub frame_attitudes: Vec<(KeyframeId, UnitQuaternion<f64>)>,
    /// The latest up in that frame, and its σ, rad.
    pub frame_up: Option<(Vector3<f64>, f64)>,
    /// Our own keyframes and factors, as neighbours read them ([`super::shared_factors`]).
    pub log: FactorLog,
    /// Neighbours' own chains held ([`chains`]).
    pub chains: Vec<(RobotId, NeighbourChain)>,
}

/// What a solve gives: every local keyframe's pose, the newest ones' marginal covariances, and
/// whether the set of rejected factors changed.
#[derive(Clone, Debug, PartialEq)]
pub struct Solved {
    pub poses: Vec<(KeyframeId, Pose3)>,
    pub covariances: Vec<(KeyframeId, Matrix6<f64>)>,
    pub rejection_changed: bool,
    /// Each neighbour's local_from_remote as this solve estimates it.
    pub anchors: Vec<(RobotId, Pose3)>,
}

/// The pose graph at a glance.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct KeyframeGraphStatus {
    pub variables: usize,
    pub between_factors: usize,
    /// Loop closures and inter-robot factors.
    pub candidate_factors: usize,
    /// Of those, rejected by the last solve.
    pub rejected_factors: usize,
    /// Rejected inter-robot factors: (neighbour, local keyframe, neighbour keyframe).
    pub rejected_inter_robot: Vec<(RobotId, KeyframeId, KeyframeId)>,
    /// Per neighbour: inter-robot factors held, and those outside the largest mutually
    /// consistent set (rejected by PCM before the solve).
    pub inter_robot: Vec<InterRobotCounts>,
    /// Per neighbour whose own factors we hold (`optimiser.share_factors`): its chain.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub chains: Vec<ChainCounts>,
}

/// One neighbour's inter-robot factors in the pose graph.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct InterRobotCounts {
    pub robot: RobotId,
    pub factors: usize,
    pub inconsistent: usize,
    /// Times the consistent set's transform was far from the anchor's and the anchor moved.
    pub realigned: u32,
    /// Its keyframes' priors moved by its pose updates (`KeyframePoses`), in all.
    pub refreshed: u64,
}

#[derive(Clone, Debug, Default, PartialEq)]
pub struct KeyframeGraph {
    graph: Graph3,
    index: BTreeMap<KeyframeRef, usize>,
    pending: usize,
    /// Per between factor of `graph`: whether robust estimation may reject it (not odometry).
    candidates: Vec<bool>,
    /// The between factors the last solve rejected.
    rejected: Vec<usize>,
    /// Each neighbour's anchor variable.
    anchors: BTreeMap<RobotId, usize>,
    /// PCM's decision at the last solve: per neighbour, the factors outside the consistent set.
    inconsistent: BTreeMap<RobotId, Vec<usize>>,
    /// Per neighbour, how often PCM moved the anchor.
    realigned: BTreeMap<RobotId, u32>,
    /// Per neighbour, priors moved by [`KeyframeGraph::refresh_neighbour`].
    refreshed: BTreeMap<RobotId, u64>,
    /// Per neighbour, the latest pose update of each keyframe not yet in the graph (at most
    /// [`MAX_DEFERRED_POSES`]): the keyframe takes it when it arrives.
    deferred: BTreeMap<RobotId, BTreeMap<KeyframeId, Pose3>>,
    /// Neighbour keyframe variables whose tie holds a pose update's mean: newer than the pose
    /// the keyframe is served with, which a keyframe received again does not take back.
    updated: BTreeSet<usize>,
    /// Gravity-aligned worlds: anchors held level ([`KeyframeGraph::set_level_anchors`]).
    level: bool,
    /// Per neighbour, the withdrawals handled: which alignment an anchor's estimate belongs to
    /// ([`KeyframeGraph::withdrawals`]).
    withdrawals: BTreeMap<RobotId, u32>,
    /// Local keyframes' tilts as their odometry measured them against gravity: the world's up
    /// in each body ([`KeyframeGraph::record_tilt`]).
    tilts: BTreeMap<KeyframeId, Vector3<f64>>,
    /// Local keyframes' attitudes in the frame of an odometry that learns up, and the latest
    /// up in it with its σ ([`KeyframeGraph::record_up`]).
    frame_attitudes: BTreeMap<KeyframeId, UnitQuaternion<f64>>,
    frame_up: Option<(Vector3<f64>, f64)>,
    /// σ of the gravity priors, rad; `None`: none ([`KeyframeGraph::set_gravity_priors`]).
    gravity_sigma_rad: Option<f64>,
    /// While a solve holds its gravity priors: how many priors the graph has without them. Set
    /// when they are added and cleared when they are taken away; still set only if a solve
    /// was cut short by a panic, and then the next solve and any freeze take them away first.
    transient_from: Option<usize>,
    /// While a solve holds anchors in yaw and position only ([`KeyframeGraph::free_anchor_tilts`]):
    /// those priors whole, by index, put back as `transient_from`'s priors are taken away.
    transient_anchors: Vec<(usize, Prior<Pose3, 6>)>,
    /// Our own keyframes and factors, as neighbours read them.
    log: FactorLog,
    /// Neighbours' own chains ([`chains`]).
    chains: BTreeMap<RobotId, NeighbourChain>,
    /// Keyframes and factors one chain may hold; `None`: [`DEFAULT_CHAIN_ITEMS`]. Set by the
    /// owner, not frozen.
    chain_bound: Option<usize>,
}

/// Pose updates held per neighbour for keyframes not yet in the graph, at most. A keyframe
/// enters the graph when the Matcher's round that asked for it ends (seconds after it was
/// served), and an update may come in between; a round asks for a few keyframes
/// (`matcher.max_keyframes_per_alignment`, `closures.max_keyframes_per_round`), so this bound is
/// never reached by an honest neighbour. Beyond it updates of unknown keyframes are dropped.
pub const MAX_DEFERRED_POSES: usize = 1024;

/// What [`KeyframeGraph::refresh_neighbour`] did with a neighbour's pose updates.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Refreshed {
    /// Ties of keyframes in the graph that took the new pose.
    pub moved: usize,
    /// Keyframes not yet in the graph, held for when they arrive.
    pub deferred: usize,
    /// Keyframes not yet in the graph beyond [`MAX_DEFERRED_POSES`]: dropped.
    pub dropped: usize,
}

/// Standard deviations of the anchor's weak prior (rotation rad, translation m).
const ANCHOR_PRIOR_SIGMAS: [f64; 6] = [100.0, 100.0, 100.0, 1000.0, 1000.0, 1000.0];

/// Standard deviation of a levelled anchor's roll and pitch, rad (0.2°): two gravity-aligned
/// worlds share their vertical to about their odometries' tilt errors (the simulated one's is
/// 0.1°; an IMU's gravity estimate is of that order).
pub const LEVEL_ANCHOR_SIGMA_RAD: f64 = 0.2 * std::f64::consts::PI / 180.0;

/// S with Sᵀ S = Ω, or `None` unless Ω is symmetric positive definite.
fn sqrt_information(information: &Matrix6<f64>) -> Option<Matrix6<f64>> {
    information.cholesky().map(|c| c.l().transpose())
}

fn key_of(r: &KeyframeRef) -> u64 {
    match r {
        KeyframeRef::Local(k) => u64::from(k.0),
        KeyframeRef::Remote { robot, keyframe } => ((u64::from(robot.0) + 1) << 40) | u64::from(keyframe.0),
    }
}

/// The entries of `values` whose flag in `gone` is false, in order.
fn kept<T>(gone: &[bool], values: Vec<T>) -> Vec<T> {
    values.into_iter().zip(gone).filter(|(_, g)| !**g).map(|(x, _)| x).collect()
}

/// The anchor's key: above every keyframe id of its robot (ids are u32).
fn anchor_key(robot: RobotId) -> u64 {
    ((u64::from(robot.0) + 1) << 40) | ((1 << 40) - 1)
}

impl KeyframeGraph {
    pub fn freeze(&self) -> KeyframeGraphState {
        let mut graph = self.graph.clone();
        Self::drop_transient_priors(&mut graph, self.transient_from, &self.transient_anchors);
        KeyframeGraphState {
            graph,
            index: self.index.iter().map(|(r, i)| (*r, *i)).collect(),
            pending: self.pending,
            candidates: self.candidates.clone(),
            rejected: self.rejected.clone(),
            anchors: self.anchors.iter().map(|(r, i)| (*r, *i)).collect(),
            realigned: self.realigned.iter().map(|(r, n)| (*r, *n)).collect(),
            refreshed: self.refreshed.iter().map(|(r, n)| (*r, *n)).collect(),
            deferred: self
                .deferred
                .iter()
                .flat_map(|(r, poses)| poses.iter().map(move |(k, p)| (*r, *k, *p)))
                .collect(),
            updated: self.updated.iter().copied().collect(),
            withdrawals: self.withdrawals.iter().map(|(r, n)| (*r, *n)).collect(),
            tilts: self.tilts.iter().map(|(k, u)| (*k, *u)).collect(),
            frame_attitudes: self.frame_attitudes.iter().map(|(k, r)| (*k, *r)).collect(),
            frame_up: self.frame_up,
            log: self.log.clone(),
            chains: self.chains.iter().map(|(r, c)| (*r, c.clone())).collect(),
        }
    }

    /// The graph without a solve's gravity priors and with its anchors whole again (see
    /// `transient_from`, `transient_anchors`): after every solve, and before the next solve and
    /// in a freeze should a solve have been cut short by a panic.
    fn drop_transient_priors(graph: &mut Graph3, transient_from: Option<usize>, anchors: &[(usize, Prior<Pose3, 6>)]) {
        if let Some(held) = transient_from {
            graph.priors.truncate(held);
        }
        for (k, prior) in anchors {
            if let Some(p) = graph.priors.get_mut(*k) {
                *p = prior.clone();
            }
        }
    }

    /// The graph `state` holds, or `None` if its index does not fit its graph.
    pub fn thaw(state: KeyframeGraphState) -> Option<Self> {
        let n = state.graph.values.len();
        let consistent = state.graph.keys.len() == n
            && state.graph.fixed.len() == n
            && state.index.iter().all(|(_, i)| *i < n)
            && state.graph.betweens.iter().all(|b| b.from < n && b.to < n)
            && state.graph.priors.iter().all(|p| p.variable < n)
            && state.candidates.len() == state.graph.betweens.len()
            && state.rejected.iter().all(|k| *k < state.candidates.len())
            && state.anchors.iter().all(|(_, i)| *i < n)
            && state.updated.iter().all(|i| *i < n)
            && {
                let local: BTreeSet<KeyframeRef> = state.index.iter().map(|(r, _)| *r).collect();
                state.tilts.iter().all(|(k, u)| {
                    local.contains(&KeyframeRef::Local(*k))
                        && u.iter().all(|v| v.is_finite())
                        && (u.norm() - 1.0).abs() < 1e-6
                }) && state
                    .frame_attitudes
                    .iter()
                    .all(|(k, r)| local.contains(&KeyframeRef::Local(*k)) && up_in_body(r).is_some())
                    && state.frame_up.is_none_or(|(u, s)| unit_up(&u) && s.is_finite() && s >= 0.0)
            };
        consistent.then(|| Self {
            graph: state.graph,
            index: state.index.into_iter().collect(),
            pending: state.pending,
            candidates: state.candidates,
            rejected: state.rejected,
            anchors: state.anchors.into_iter().collect(),
            inconsistent: BTreeMap::new(),
            realigned: state.realigned.into_iter().collect(),
            refreshed: state.refreshed.into_iter().collect(),
            deferred: state.deferred.into_iter().fold(BTreeMap::new(), |mut m, (r, k, p)| {
                m.entry(r).or_insert_with(BTreeMap::new).insert(k, p);
                m
            }),
            updated: state.updated.into_iter().collect(),
            level: false,
            withdrawals: state.withdrawals.into_iter().collect(),
            tilts: state.tilts.into_iter().collect(),
            frame_attitudes: state.frame_attitudes.into_iter().collect(),
            frame_up: state.frame_up,
            gravity_sigma_rad: None,
            transient_from: None,
            transient_anchors: Vec::new(),
            log: state.log,
            chains: state.chains.into_iter().collect(),
            chain_bound: None,
        })
    }

    pub fn variables(&self) -> usize {
        self.graph.values.len()
    }

    fn variable(&mut self, r: KeyframeRef, value: Pose3) -> usize {
        if let Some(&i) = self.index.get(&r) {
            return i;
        }
        let i = self.graph.values.len();
        self.graph.keys.push(key_of(&r));
        self.graph.values.push(value);
        self.graph.fixed.push(false);
        self.index.insert(r, i);
        i
    }

    /// Adds `edge` if both ends are variables and its information is positive definite.
    fn add_edge(&mut self, edge: &KeyframeEdge) {
        let (Some(&from), Some(&to)) = (self.index.get(&KeyframeRef::Local(edge.from)), self.index.get(&edge.to))
        else {
            return;
        };
        let Some(s) = sqrt_information(&edge.information) else { return };
        self.graph.betweens.push(Between { from, to, measured: edge.from_from_to, sqrt_information: s });
        self.candidates.push(edge.kind != KeyframeEdgeKind::Odometry);
        self.log.factor(edge);
    }

    /// Adds a local keyframe (the first is anchored by GTSAM's default prior) and its edges.
    /// Whether to solve now: after a loop closure at once, else every `every_keyframes`.
    pub fn add_keyframe(&mut self, keyframe: &Keyframe, edges: &[KeyframeEdge], every_keyframes: usize) -> bool {
        let first = self.index.is_empty();
        if !self.index.contains_key(&KeyframeRef::Local(keyframe.id)) {
            self.log.keyframe(keyframe.id);
        }
        let i = self.variable(KeyframeRef::Local(keyframe.id), keyframe.world_from_body);
        if first {
            self.graph.add_prior_at_current(i, GTSAM_PRIOR_SIGMAS_3D);
        }
        for edge in edges {
            self.add_edge(edge);
        }
        self.pending += 1;
        // A loop closure's correction is worth a solve at once.
        let has_loop = edges.iter().any(|e| e.kind == KeyframeEdgeKind::Loop);
        let due = has_loop || self.pending >= every_keyframes;
        if due {
            self.pending = 0;
        }
        due
    }

    /// Adds `robot`'s keyframes (pose in its world, marginal covariance; a keyframe already
    /// held keeps its variable, and its tie to the anchor takes the new pose and covariance
    /// only if they are at least as informative, see [`KeyframeGraph::keep_more_informative`])
    /// and the inter-robot factors (local keyframe, its keyframe, measured
    /// local_from_neighbour-keyframe pose, information). `local_from_remote` places the
    /// neighbour's anchor when it is new; afterwards the anchor is what the solves make of it.
    pub fn add_neighbour(
        &mut self,
        robot: RobotId,
        local_from_remote: &Pose3,
        keyframes: &[(KeyframeId, Pose3, Matrix6<f64>)],
        factors: &[(KeyframeId, KeyframeId, Pose3, Matrix6<f64>)],
    ) {
        let anchor = match self.anchors.get(&robot) {
            Some(&a) => a,
            None => {
                let a = self.graph.values.len();
                self.graph.keys.push(anchor_key(robot));
                self.graph.values.push(*local_from_remote);
                self.graph.fixed.push(false);
                self.graph.add_prior_at_current(a, ANCHOR_PRIOR_SIGMAS);
                self.anchors.insert(robot, a);
                a
            }
        };
        let anchor_value = self.graph.values[anchor];
        for (keyframe, pose_in_remote, covariance) in keyframes {
            let r = KeyframeRef::Remote { robot, keyframe: *keyframe };
            if let Some(&i) = self.index.get(&r) {
                // A keyframe the neighbour's chain holds: its information is in the chain's
                // factors, and its tie stays without.
                if !self.chain_covers(robot, *keyframe) {
                    self.keep_more_informative(anchor, i, pose_in_remote, covariance);
                }
                continue;
            }
            // A pose update that came before the keyframe is newer than the pose it was served with.
            let deferred = self.deferred.get_mut(&robot).and_then(|d| d.remove(keyframe));
            if deferred.is_some() {
                *self.refreshed.entry(robot).or_default() += 1;
            }
            let i = self.variable(r, anchor_value * deferred.unwrap_or(*pose_in_remote));
            if deferred.is_some() {
                self.updated.insert(i);
            }
            let pose_in_remote = deferred.unwrap_or(*pose_in_remote);
            if let Some(tie) = Prior::from_covariance(i, pose_in_remote, covariance) {
                self.push_tie(anchor, &tie);
            }
        }
        for (local, remote, measured, information) in factors {
            let edge = KeyframeEdge {
                kind: KeyframeEdgeKind::InterRobot,
                from: *local,
                to: KeyframeRef::Remote { robot, keyframe: *remote },
                from_from_to: *measured,
                information: *information,
            };
            self.add_edge(&edge);
        }
    }

    /// A neighbour keyframe held already, received again with `pose_in_remote` and
    /// `covariance`: its tie to the anchor takes them if their information Ω = Σ⁻¹ has at
    /// least the determinant of the held one (|det S|, Sᵀ S = Ω; the later estimate wins a
    /// tie), else keeps what it has. A neighbour's marginals mostly shrink as its graph grows,
    /// and a keyframe first met through a claim that knew little of it (a false factor's, see
    /// `sim::false_factors`) takes the neighbour's own prior when that arrives, instead of
    /// keeping the first for the rest of the mission — its covariance, and its pose unless the
    /// tie holds a pose update, which is newer than the pose a keyframe is served with. A
    /// covariance that is not positive definite changes nothing. The protocol asks for a keyframe once, so an honest mission
    /// never comes here.
    fn keep_more_informative(
        &mut self,
        anchor: usize,
        variable: usize,
        pose_in_remote: &Pose3,
        covariance: &Matrix6<f64>,
    ) {
        let Some(tie) = Prior::from_covariance(variable, *pose_in_remote, covariance) else { return };
        let keep_mean = self.updated.contains(&variable);
        match self.tie_mut(anchor, variable) {
            Some(b) => {
                if tie.sqrt_information.determinant().abs() >= b.sqrt_information.determinant().abs() {
                    if !keep_mean {
                        b.measured = *pose_in_remote;
                    }
                    b.sqrt_information = tie.sqrt_information;
                }
            }
            // Held without a tie (its first covariance was not positive definite).
            None => self.push_tie(anchor, &tie),
        }
    }

    /// The tie of neighbour keyframe `variable` to `anchor`, if it has one.
    fn tie_mut(&mut self, anchor: usize, variable: usize) -> Option<&mut Between<Pose3, 6>> {
        self.graph
            .betweens
            .iter_mut()
            .zip(&self.candidates)
            .find(|(b, candidate)| !**candidate && b.from == anchor && b.to == variable)
            .map(|(b, _)| b)
    }

    /// `robot`'s later estimates (in its world) of keyframes it served us, moved by its own
    /// solves since it sent them: the tie of each keyframe held takes the new mean T_r(j), and
    /// keeps its covariance (a pose update carries none; the neighbour's marginal of a keyframe
    /// mostly shrinks, so the held one errs on the cautious side). A keyframe not yet in the
    /// graph (its round has not ended) keeps the latest update for when it arrives
    /// ([`KeyframeGraph::add_neighbour`] takes it instead of the pose it was served with, also
    /// before the first alignment), up to [`MAX_DEFERRED_POSES`] per neighbour.
    pub fn refresh_neighbour(&mut self, robot: RobotId, poses: &[(KeyframeId, Pose3)]) -> Refreshed {
        let mut out = Refreshed::default();
        // A chain's keyframes: the anchor's fit takes the neighbour's latest word on them.
        if let Some(chain) = self.chains.get_mut(&robot) {
            for (keyframe, pose) in poses {
                if let Some(held) = chain.poses.get_mut(keyframe) {
                    *held = *pose;
                }
            }
        }
        let anchor = self.anchors.get(&robot).copied();
        for (keyframe, pose_in_remote) in poses {
            let held = self.index.get(&KeyframeRef::Remote { robot, keyframe: *keyframe }).copied();
            match anchor.zip(held) {
                Some((anchor, variable)) => {
                    if let Some(tie) = self.tie_mut(anchor, variable) {
                        tie.measured = *pose_in_remote;
                        self.updated.insert(variable);
                        out.moved += 1;
                    }
                }
                None => {
                    let held = self.deferred.entry(robot).or_default();
                    if held.len() < MAX_DEFERRED_POSES || held.contains_key(keyframe) {
                        held.insert(*keyframe, *pose_in_remote);
                        out.deferred += 1;
                    } else {
                        out.dropped += 1;
                    }
                }
            }
        }
        if out.moved > 0 {
            *self.refreshed.entry(robot).or_default() += out.moved as u64;
        }
        out
    }

    /// Takes `robot` out of the graph: its anchor, its keyframe variables, their ties and every
    /// inter-robot factor to them, and the pose updates held for its keyframes (also those
    /// held from before it was first aligned). The rest keeps its order (variables, factors and
    /// the last solve's rejections are renumbered), so the graph is the one that never held it,
    /// but for the values the solves with it left. What the Matcher does when its alignment
    /// with the neighbour was found wrong (a contradicted cycle settled against it): a later
    /// alignment places a fresh anchor. The counts of realignments and refreshed priors stay,
    /// as history, and the withdrawal is counted ([`Self::withdrawals`]) whether or not the
    /// neighbour was held. How many inter-robot factors went, `None` when it was not held.
    pub fn withdraw_neighbour(&mut self, robot: RobotId) -> Option<usize> {
        *self.withdrawals.entry(robot).or_default() += 1;
        let anchor = self.anchors.remove(&robot)?;
        self.deferred.remove(&robot);
        self.chains.remove(&robot);
        self.log.strike(robot);
        self.inconsistent.remove(&robot);
        let mut gone = vec![false; self.graph.values.len()];
        gone[anchor] = true;
        self.index.retain(|r, i| {
            let theirs = matches!(r, KeyframeRef::Remote { robot: owner, .. } if *owner == robot);
            gone[*i] |= theirs;
            !theirs
        });
        // Old variable → new, for those that stay.
        let mut new_of = vec![None; gone.len()];
        let mut next = 0;
        for (i, g) in gone.iter().enumerate() {
            if !g {
                new_of[i] = Some(next);
                next += 1;
            }
        }
        self.graph.keys = kept(&gone, std::mem::take(&mut self.graph.keys));
        self.graph.values = kept(&gone, std::mem::take(&mut self.graph.values));
        self.graph.fixed = kept(&gone, std::mem::take(&mut self.graph.fixed));
        self.graph.priors.retain_mut(|p| match new_of[p.variable] {
            Some(v) => {
                p.variable = v;
                true
            }
            None => false,
        });
        // Old factor → new, for those whose ends both stay.
        let mut factor_of = vec![None; self.graph.betweens.len()];
        let mut removed = 0;
        let (betweens, candidates) = (std::mem::take(&mut self.graph.betweens), std::mem::take(&mut self.candidates));
        for (k, (mut b, candidate)) in betweens.into_iter().zip(candidates).enumerate() {
            match (new_of[b.from], new_of[b.to]) {
                (Some(from), Some(to)) => {
                    (b.from, b.to) = (from, to);
                    factor_of[k] = Some(self.graph.betweens.len());
                    self.graph.betweens.push(b);
                    self.candidates.push(candidate);
                }
                _ => removed += usize::from(candidate),
            }
        }
        self.rejected = self.rejected.iter().filter_map(|k| factor_of.get(*k).copied().flatten()).collect();
        for outliers in self.inconsistent.values_mut() {
            *outliers = outliers.iter().filter_map(|k| factor_of.get(*k).copied().flatten()).collect();
        }
        for a in self.anchors.values_mut() {
            *a = new_of[*a].unwrap_or(*a);
        }
        for i in self.index.values_mut() {
            *i = new_of[*i].unwrap_or(*i);
        }
        self.updated = self.updated.iter().filter_map(|i| new_of[*i]).collect();
        Some(removed)
    }

    /// The withdrawals of `robot` handled so far: an anchor's estimate is of the alignment
    /// that followed the last of them, which the Matcher tells apart from an earlier one.
    pub fn withdrawals(&self, robot: RobotId) -> u32 {
        self.withdrawals.get(&robot).copied().unwrap_or(0)
    }

    /// Ties a neighbour keyframe to its robot's anchor: the neighbour's estimate of it, with its
    /// marginal covariance (never a candidate for rejection).
    fn push_tie(&mut self, anchor: usize, tie: &Prior<Pose3, 6>) {
        let (measured, sqrt_information) = (tie.mean, tie.sqrt_information);
        self.graph.betweens.push(Between { from: anchor, to: tie.variable, measured, sqrt_information });
        self.candidates.push(false);
    }

    /// Gravity priors (`Some(σ)`, rad): every solve holds each local keyframe whose tilt was
    /// recorded ([`Self::record_tilt`]) to that tilt ([`super::gravity`]). Not part of the frozen
    /// state, as `level` is not: the owner sets it.
    pub fn set_gravity_priors(&mut self, sigma_rad: Option<f64>) {
        self.gravity_sigma_rad = sigma_rad.filter(|s| s.is_finite() && *s > 0.0);
    }

    /// Records the attitude local keyframe `keyframe` was measured at against gravity (its
    /// odometry's odom_from_body rotation; only the world's up in the body is kept). Whether it
    /// was recorded: not for a keyframe the graph does not hold, nor for an attitude that is not
    /// a finite rotation (what came from outside is checked once, here).
    pub fn record_tilt(&mut self, keyframe: KeyframeId, odom_from_body: &UnitQuaternion<f64>) -> bool {
        let Some(up) = up_in_body(odom_from_body) else { return false };
        if !self.index.contains_key(&KeyframeRef::Local(keyframe)) {
            return false;
        }
        self.tilts.insert(keyframe, up);
        self.frame_attitudes.remove(&keyframe);
        true
    }

    /// Records local keyframe `keyframe` as measured by an odometry that learns up: its attitude
    /// in that odometry's frame, and up in the frame as the odometry knows it now, which
    /// replaces the up every keyframe measured so is held to (u_m = R_Fᵀ û_latest, σ =
    /// √(σ² + σ_u²): [`super::gravity`]). Whether it was recorded: not for a keyframe the graph
    /// does not hold, nor for a measurement that is not valid ([`MeasuredUp::is_valid`]).
    pub fn record_up(&mut self, keyframe: KeyframeId, measured: &MeasuredUp) -> bool {
        if !measured.is_valid() || !self.index.contains_key(&KeyframeRef::Local(keyframe)) {
            return false;
        }
        self.tilts.remove(&keyframe);
        self.frame_attitudes.insert(keyframe, measured.attitude_in_frame);
        self.frame_up = Some((measured.up_in_frame, measured.sigma_rad));
        true
    }

    /// Each local keyframe's measured up in its body and that up's own σ (0 for those measured
    /// as an attitude alone).
    fn measured_ups(&self) -> (BTreeMap<KeyframeId, Vector3<f64>>, BTreeMap<KeyframeId, f64>) {
        let mut ups = self.tilts.clone();
        let mut sigmas = BTreeMap::new();
        if let Some((up, sigma)) = self.frame_up {
            for (k, attitude) in &self.frame_attitudes {
                ups.insert(*k, attitude.inverse() * up);
                sigmas.insert(*k, sigma);
            }
        }
        (ups, sigmas)
    }

    /// The gravity priors for the next solve, at the current values (none unless set).
    fn gravity_priors(&self) -> Vec<Prior<Pose3, 6>> {
        let Some(sigma) = self.gravity_sigma_rad else { return Vec::new() };
        let variable_of = |k| self.index.get(&KeyframeRef::Local(k)).copied();
        let (ups, up_sigmas) = self.measured_ups();
        let mut priors = gravity_priors(&ups, &up_sigmas, variable_of, &self.graph.values, sigma);
        priors.extend(self.chain_gravity_priors(sigma));
        priors
    }

    /// The measured up of each local keyframe an odometry that learns up measured
    /// ([`Self::record_up`]), by variable; none without gravity priors.
    fn ups_with_uncertainty(&self) -> BTreeMap<usize, Vector3<f64>> {
        if self.gravity_sigma_rad.is_none() {
            return BTreeMap::new();
        }
        let (ups, sigmas) = self.measured_ups();
        sigmas.keys().filter_map(|k| Some((*self.index.get(&KeyframeRef::Local(*k))?, *ups.get(k)?))).collect()
    }

    /// With gravity priors, a prior on a local keyframe (the first one's anchor) whose up an
    /// odometry measured with its uncertainty holds yaw and position only, about that up: its
    /// tilt is then its gravity prior's, at the σ the odometry gave, and not pinned to the first
    /// pose's ([`super::gravity`]). An odometry that tells no uncertainty keeps the anchor whole.
    /// Only variables that hold a gravity prior in this solve (`gravity`) are freed. The priors
    /// as they were, to put back after the solve.
    fn free_anchor_tilts(&mut self, gravity: &[Prior<Pose3, 6>]) -> Vec<(usize, Prior<Pose3, 6>)> {
        let held: BTreeSet<usize> = gravity.iter().map(|p| p.variable).collect();
        let up_of = self.ups_with_uncertainty();
        let mut saved = Vec::new();
        for (k, prior) in self.graph.priors.iter_mut().enumerate() {
            if let Some(up) = up_of.get(&prior.variable).filter(|_| held.contains(&prior.variable)) {
                saved.push((k, prior.clone()));
                *prior = yaw_only(prior, up);
            }
        }
        saved
    }

    /// Gravity-aligned worlds (`level`): every solve holds every anchor level
    /// ([`Self::fit_anchor_priors`]). Not part of the frozen state: the owner sets it.
    pub fn set_level_anchors(&mut self, level: bool) {
        self.level = level;
    }

    /// The anchors' priors for the next solve. Level (gravity-aligned worlds): roll and pitch get
    /// σ_θ = [`LEVEL_ANCHOR_SIGMA_RAD`] (yaw and translation keep [`ANCHOR_PRIOR_SIGMAS`]), about
    /// a mean that is the anchor levelled — its yaw and translation, no roll or pitch — taken
    /// again before each solve (after PCM may have moved the anchor), so that the prior's
    /// residual is the anchor's tilt however far its yaw has moved since it was made:
    ///
    /// ```text
    /// e = Log(L(A)⁻¹ · A'),   L(A) = (R_z(yaw(A)), t(A)),   Σ = diag(σ_θ², σ_θ², 100², 1000² I₃)
    /// ```
    ///
    /// (A the anchor before the solve, A' its value in the solve; yaw as in
    /// [`crate::geometry::levelled`], A = R_z(yaw) R_y(pitch) R_x(roll), so L(A)⁻¹ · A has the
    /// rotation R_y(pitch) R_x(roll)). Not level: the weak prior of [`ANCHOR_PRIOR_SIGMAS`] at
    /// its mean (what a graph thawed from a levelled one goes back to).
    fn fit_anchor_priors(&mut self) {
        let mut sigmas = ANCHOR_PRIOR_SIGMAS;
        if self.level {
            sigmas[0] = LEVEL_ANCHOR_SIGMA_RAD;
            sigmas[1] = LEVEL_ANCHOR_SIGMA_RAD;
        }
        let sqrt_information =
            Matrix6::from_diagonal(&nalgebra::Vector6::from_iterator(sigmas.iter().map(|s| 1.0 / s)));
        for &a in self.anchors.values() {
            let anchor = self.graph.values[a];
            for prior in self.graph.priors.iter_mut().filter(|p| p.variable == a) {
                if self.level {
                    prior.mean = levelled(&anchor);
                }
                prior.sqrt_information = sqrt_information;
            }
        }
    }

    /// Solves (GNC-TLS over the candidate factors with `reject_outliers`, else least squares),
    /// then computes the marginal covariances of the newest `marginals` local keyframes. One
    /// symbolic factorisation serves both (`cargo bench -p sgm-model --bench optimiser_cycle`).
    /// On an error the graph keeps its previous decision.
    pub fn solve(&mut self, reject_outliers: bool, marginals: usize) -> Result<Solved, SolveError> {
        // The gravity priors hold for this solve and its marginals, then go: their means follow
        // the yaw, so they are made again each time.
        let cut_short = std::mem::take(&mut self.transient_anchors);
        Self::drop_transient_priors(&mut self.graph, self.transient_from.take(), &cut_short);
        let held = self.graph.priors.len();
        let gravity = self.gravity_priors();
        self.transient_anchors = self.free_anchor_tilts(&gravity);
        self.graph.priors.extend(gravity);
        self.transient_from = Some(held);
        let solved = self.solve_held(reject_outliers, marginals);
        let anchors = std::mem::take(&mut self.transient_anchors);
        Self::drop_transient_priors(&mut self.graph, self.transient_from.take(), &anchors);
        solved
    }

    fn solve_held(&mut self, reject_outliers: bool, marginals: usize) -> Result<Solved, SolveError> {
        let structure = Structure::new(&self.graph)?;
        let params = LmParams::default();
        if reject_outliers {
            self.inconsistent = self.check_consistency(&Consistency::default());
        }
        self.fit_anchor_priors();
        let rejected = if reject_outliers {
            // PCM's outliers weigh nothing in this solve (zero information, same structure),
            // then count as rejected.
            let excluded: Vec<usize> = self.inconsistent.values().flatten().copied().collect();
            let saved: Vec<(usize, Matrix6<f64>)> = excluded
                .iter()
                .map(|k| (*k, std::mem::replace(&mut self.graph.betweens[*k].sqrt_information, Matrix6::zeros())))
                .collect();
            let solved =
                optimize_gnc_incremental_with(&mut self.graph, &params, &structure, &self.candidates, &self.rejected);
            for (k, s) in saved {
                self.graph.betweens[k].sqrt_information = s;
            }
            let mut rejected = solved?.1;
            rejected.extend(excluded);
            rejected.sort_unstable();
            rejected.dedup();
            rejected
        } else {
            optimize_with(&mut self.graph, &params, &structure, &least_squares).map(|_| Vec::new())?
        };
        let rejection_changed = rejected != self.rejected;
        self.rejected = rejected;
        let weights = rejection_weights(self.graph.betweens.len(), &self.rejected);
        let local = self.local_variables();
        let poses: Vec<(KeyframeId, Pose3)> = local.iter().map(|(k, i)| (*k, self.graph.values[*i])).collect();
        let latest: Vec<(KeyframeId, usize)> = local.iter().rev().take(marginals).copied().collect();
        let variables: Vec<usize> = latest.iter().map(|(_, i)| *i).collect();
        let covariances = marginal_covariances_with(&self.graph, &structure, &variables, &weighted(&weights))
            .map(|c| latest.iter().map(|(k, _)| *k).zip(c).collect())
            .unwrap_or_default();
        self.gauge_chained_anchors();
        let anchors = self.anchors.iter().map(|(r, i)| (*r, self.graph.values[*i])).collect();
        Ok(Solved { poses, covariances, rejection_changed, anchors })
    }

    /// The local keyframes and their variables, in id order.
    fn local_variables(&self) -> Vec<(KeyframeId, usize)> {
        self.index
            .iter()
            .filter_map(|(r, i)| if let KeyframeRef::Local(k) = r { Some((*k, *i)) } else { None })
            .collect()
    }

    /// Each local keyframe's pose from this robot's own measurements alone: the graph without
    /// its neighbours (anchors, their keyframes, inter-robot factors) and without the factors
    /// the last solve rejected, solved from the current values:
    ///
    /// ```text
    /// X_own = argmin Σ_prior ‖r‖² + Σ_{odometry, loops kept} ‖r‖²     (local keyframes only)
    /// ```
    ///
    /// What a neighbour holding our keyframes is told (their priors' means): the joint solve's
    /// poses already hold that neighbour's own keyframes and factors, and telling those back
    /// would count its information twice, round after round (each robot's estimate echoing in
    /// the other's). Without neighbours the joint poses are returned as they are.
    pub fn own_poses(&self) -> Result<Vec<(KeyframeId, Pose3)>, SolveError> {
        let local = self.local_variables();
        if self.anchors.is_empty() {
            return Ok(local.iter().map(|(k, i)| (*k, self.graph.values[*i])).collect());
        }
        let mut own = Graph3::default();
        let mut new_of: BTreeMap<usize, usize> = BTreeMap::new();
        for (_, i) in &local {
            new_of.insert(*i, own.keys.len());
            own.keys.push(self.graph.keys[*i]);
            own.values.push(self.graph.values[*i]);
            own.fixed.push(self.graph.fixed[*i]);
        }
        for p in &self.graph.priors {
            if let Some(&variable) = new_of.get(&p.variable) {
                own.priors.push(Prior { variable, ..p.clone() });
            }
        }
        // A graph that held a neighbour before its first keyframe put no prior on our keyframes
        // (`add_keyframe` anchors only the graph's first variable): the first of ours takes it.
        if own.priors.is_empty() && !own.values.is_empty() {
            own.add_prior_at_current(0, GTSAM_PRIOR_SIGMAS_3D);
        }
        // As in a solve: an anchor whose up came with its uncertainty, and that holds a gravity
        // prior, holds yaw and position only.
        let gravity = self.gravity_priors();
        let held: BTreeSet<usize> = gravity.iter().map(|p| p.variable).collect();
        let up_of = self.ups_with_uncertainty();
        for p in own.priors.iter_mut() {
            // The own graph's variable j is local keyframe j.
            let graph_variable = local.get(p.variable).map(|(_, i)| *i).filter(|i| held.contains(i));
            if let Some(up) = graph_variable.and_then(|i| up_of.get(&i)) {
                *p = yaw_only(p, up);
            }
        }
        for p in gravity {
            if let Some(&variable) = new_of.get(&p.variable) {
                own.priors.push(Prior { variable, ..p });
            }
        }
        for (k, b) in self.graph.betweens.iter().enumerate() {
            if self.rejected.binary_search(&k).is_ok() {
                continue;
            }
            if let (Some(&from), Some(&to)) = (new_of.get(&b.from), new_of.get(&b.to)) {
                own.betweens.push(Between { from, to, ..b.clone() });
            }
        }
        let structure = Structure::new(&own)?;
        optimize_with(&mut own, &LmParams::default(), &structure, &least_squares)?;
        // The own graph's variables are the local keyframes, in order.
        Ok(local.iter().map(|(k, _)| *k).zip(own.values).collect())
    }

    /// PCM over each neighbour's inter-robot factors at the current values: the factors
    /// outside the largest consistent set, per neighbour. When that set's transform (the medoid
    /// of what its factors imply) is farther from the anchor than the consistency tolerance,
    /// the anchor and the neighbour's keyframes are moved to it before the solve.
    fn check_consistency(&mut self, consistency: &Consistency) -> BTreeMap<RobotId, Vec<usize>> {
        let robot_of_anchor: BTreeMap<usize, RobotId> = self.anchors.iter().map(|(r, i)| (*i, *r)).collect();
        // Neighbour keyframe variable → (its robot, its pose in the neighbour's world).
        let mut remote: BTreeMap<usize, (RobotId, Pose3)> = BTreeMap::new();
        for b in &self.graph.betweens {
            if let Some(robot) = robot_of_anchor.get(&b.from) {
                remote.insert(b.to, (*robot, b.measured));
            }
        }
        for (i, robot, pose) in self.chain_remote_poses() {
            remote.insert(i, (robot, pose));
        }
        let mut closures: BTreeMap<RobotId, Vec<(usize, ImpliedClosure)>> = BTreeMap::new();
        for (k, b) in self.graph.betweens.iter().enumerate() {
            let Some((robot, remote_pose)) = remote.get(&b.to) else { continue };
            // Inter-robot factors only: from a local keyframe (not an anchor's tie, nor a
            // neighbour's own loop closure within its chain).
            if !self.candidates.get(k).copied().unwrap_or(false)
                || robot_of_anchor.contains_key(&b.from)
                || remote.contains_key(&b.from)
            {
                continue;
            }
            let implied = ImpliedClosure::new(&self.graph.values[b.from], &b.measured, remote_pose);
            closures.entry(*robot).or_default().push((k, implied));
        }
        let mut out = BTreeMap::new();
        for (robot, list) in closures {
            let implied: Vec<ImpliedClosure> = list.iter().map(|(_, c)| *c).collect();
            let kept = largest_consistent_set(&implied, consistency);
            // No two factors agree: PCM has no evidence to choose by (two disagreeing
            // registrations are a tie, not a verdict); GNC alone decides.
            if kept.len() < 2 {
                continue;
            }
            let outliers: Vec<usize> =
                (0..list.len()).filter(|i| kept.binary_search(i).is_err()).map(|i| list[i].0).collect();
            let poses: Vec<Pose3> = kept.iter().map(|i| implied[*i].local_from_remote).collect();
            // Moving the anchor takes a consistent set of at least three, and a strict majority.
            let decisive = kept.len() >= 3 && 2 * kept.len() > list.len();
            if let (true, Some(consensus), Some(&anchor)) = (decisive, medoid(&poses), self.anchors.get(&robot)) {
                // Level worlds: the consensus levelled, as the anchor is held.
                let consensus = if self.level { levelled(&consensus) } else { consensus };
                let e = pose_error(&consensus, &self.graph.values[anchor]);
                if e.translation_m > consistency.tolerance_m || e.max_axis_rotation_deg() > consistency.tolerance_deg {
                    self.graph.values[anchor] = consensus;
                    for (variable, (owner, pose)) in &remote {
                        if *owner == robot {
                            self.graph.values[*variable] = consensus * pose;
                        }
                    }
                    *self.realigned.entry(robot).or_default() += 1;
                }
            }
            out.insert(robot, outliers);
        }
        out
    }

    pub fn status(&self) -> KeyframeGraphStatus {
        let keyframe_of: BTreeMap<usize, KeyframeRef> = self.index.iter().map(|(r, i)| (*i, *r)).collect();
        let rejected_inter_robot = self
            .rejected
            .iter()
            .filter_map(|k| self.graph.betweens.get(*k))
            .filter_map(|b| match (keyframe_of.get(&b.from)?, keyframe_of.get(&b.to)?) {
                (KeyframeRef::Local(ours), KeyframeRef::Remote { robot, keyframe }) => Some((*robot, *ours, *keyframe)),
                _ => None,
            })
            .collect();
        let robot_of_anchor: BTreeMap<usize, RobotId> = self.anchors.iter().map(|(r, i)| (*i, *r)).collect();
        let mut inter_robot: BTreeMap<RobotId, InterRobotCounts> = BTreeMap::new();
        let fresh =
            |robot: RobotId| InterRobotCounts { robot, factors: 0, inconsistent: 0, realigned: 0, refreshed: 0 };
        for (k, b) in self.graph.betweens.iter().enumerate() {
            let (Some(KeyframeRef::Local(_)), Some(KeyframeRef::Remote { robot, .. })) =
                (keyframe_of.get(&b.from), keyframe_of.get(&b.to))
            else {
                continue;
            };
            if self.candidates.get(k).copied().unwrap_or(false) && !robot_of_anchor.contains_key(&b.from) {
                inter_robot.entry(*robot).or_insert_with(|| fresh(*robot)).factors += 1;
            }
        }
        for (robot, outliers) in &self.inconsistent {
            inter_robot.entry(*robot).or_insert_with(|| fresh(*robot)).inconsistent = outliers.len();
        }
        for (robot, n) in &self.realigned {
            inter_robot.entry(*robot).or_insert_with(|| fresh(*robot)).realigned = *n;
        }
        for (robot, n) in &self.refreshed {
            inter_robot.entry(*robot).or_insert_with(|| fresh(*robot)).refreshed = *n;
        }
        KeyframeGraphStatus {
            inter_robot: inter_robot.into_values().collect(),
            variables: self.graph.values.len(),
            between_factors: self.graph.betweens.len(),
            candidate_factors: self.candidates.iter().filter(|c| **c).count(),
            rejected_factors: self.rejected.len(),
            rejected_inter_robot,
            chains: self.chain_counts(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_yaw_translation;
    use nalgebra::Vector3;

    fn information() -> Matrix6<f64> {
        Matrix6::identity() * 1e4
    }

    fn odometry(from: u32, to: u32, step: &Pose3) -> KeyframeEdge {
        KeyframeEdge {
            kind: KeyframeEdgeKind::Odometry,
            from: KeyframeId(from),
            to: KeyframeRef::Local(KeyframeId(to)),
            from_from_to: *step,
            information: information(),
        }
    }

    #[test]
    fn solves_every_n_keyframes_or_at_once_on_a_loop() {
        let mut graph = KeyframeGraph::default();
        let step = pose_from_yaw_translation(0.0, Vector3::new(1.0, 0.0, 0.0));
        let keyframe = |k: u32| Keyframe { id: KeyframeId(k), stamp: f64::from(k), world_from_body: Pose3::identity() };
        assert!(!graph.add_keyframe(&keyframe(0), &[], 3));
        assert!(!graph.add_keyframe(&keyframe(1), &[odometry(0, 1, &step)], 3));
        assert!(graph.add_keyframe(&keyframe(2), &[odometry(1, 2, &step)], 3), "the third");
        let mut closing = odometry(0, 3, &step);
        closing.kind = KeyframeEdgeKind::Loop;
        assert!(graph.add_keyframe(&keyframe(3), &[odometry(2, 3, &step), closing], 3), "a loop: at once");
        let status = graph.status();
        assert_eq!((status.variables, status.between_factors, status.candidate_factors), (4, 4, 1));
    }

    #[test]
    fn a_chain_solves_to_its_odometry_and_a_neighbour_lands_where_its_factor_says() {
        let mut graph = KeyframeGraph::default();
        let step = pose_from_yaw_translation(0.1, Vector3::new(1.0, 0.0, 0.0));
        // Initial values all at the origin: the solve must move them.
        for k in 0..3u32 {
            let keyframe = Keyframe { id: KeyframeId(k), stamp: f64::from(k), world_from_body: Pose3::identity() };
            let edges: Vec<KeyframeEdge> = (k > 0).then(|| odometry(k - 1, k, &step)).into_iter().collect();
            graph.add_keyframe(&keyframe, &edges, 100);
        }
        // A neighbour keyframe 2 m ahead of our keyframe 2, its world 5 m east of ours.
        let local_from_remote = pose_from_yaw_translation(0.0, Vector3::new(5.0, 0.0, 0.0));
        let measured = pose_from_yaw_translation(0.0, Vector3::new(2.0, 0.0, 0.0));
        let expected_2 = step * step;
        let in_remote = local_from_remote.inverse() * expected_2 * measured;
        let loose = Matrix6::identity() * 100.0;
        graph.add_neighbour(
            RobotId(2),
            &local_from_remote,
            &[(KeyframeId(7), in_remote, loose)],
            &[(KeyframeId(2), KeyframeId(7), measured, information())],
        );
        let solved = graph.solve(false, 2).expect("solves");
        assert_eq!(solved.poses.len(), 3, "local keyframes only");
        let (k, pose) = solved.poses[2];
        assert_eq!(k, KeyframeId(2));
        assert!((pose.translation.vector - expected_2.translation.vector).norm() < 1e-6);
        assert!(pose.rotation.angle_to(&expected_2.rotation) < 1e-6);
        assert_eq!(solved.covariances.iter().map(|(k, _)| *k).collect::<Vec<_>>(), vec![KeyframeId(2), KeyframeId(1)]);
        // The covariance grows along the chain from the anchored first keyframe.
        assert!(solved.covariances[0].1.trace() > solved.covariances[1].1.trace());
        assert!(!solved.rejection_changed);
        // Frozen and thawed, the graph is the same; an index that does not fit is refused.
        let state = graph.freeze();
        assert_eq!(KeyframeGraph::thaw(state.clone()), Some(graph.clone()));
        let mut broken = state;
        broken.index.push((KeyframeRef::Local(KeyframeId(9)), 99));
        assert_eq!(KeyframeGraph::thaw(broken), None);
    }

    /// `n` local keyframes 2 m apart along x with exact odometry: the graph and their poses.
    fn straight_chain(n: u32) -> (KeyframeGraph, Vec<Pose3>) {
        let mut graph = KeyframeGraph::default();
        let step = pose_from_yaw_translation(0.0, Vector3::new(2.0, 0.0, 0.0));
        let mut truth = Vec::new();
        for k in 0..n {
            let pose = (0..k).fold(Pose3::identity(), |p, _| p * step);
            truth.push(pose);
            let edges: Vec<KeyframeEdge> = (k > 0).then(|| odometry(k - 1, k, &step)).into_iter().collect();
            graph.add_keyframe(
                &Keyframe { id: KeyframeId(k), stamp: f64::from(k), world_from_body: pose },
                &edges,
                100,
            );
        }
        (graph, truth)
    }

    /// A neighbour's keyframes, held tight (covariance 1e-8), and two inter-robot factors that disagree with our
    /// odometry by 0.5 m at keyframe 4: the joint solve bends our chain toward the neighbour,
    /// while our own poses are the odometry's alone (the exact chain, closed form). Without a
    /// neighbour, our own poses are the solve's.
    #[test]
    fn own_poses_leave_the_neighbours_out() {
        let (mut graph, truth) = straight_chain(5);
        let solved = graph.solve(false, 0).expect("solves");
        assert_eq!(graph.own_poses().expect("own"), solved.poses, "no neighbour: the joint poses");
        let local_from_remote = pose_from_yaw_translation(0.0, Vector3::new(0.0, 3.0, 0.0));
        let (tight, held) = (Matrix6::identity() * 1e8, Matrix6::identity() * 1e-8);
        // Keyframe 7 3 m left of our keyframe 1, keyframe 8 3.5 m left of our keyframe 4 (the
        // factors say 3 m for both: our keyframe 4 should be 0.5 m further left).
        let beside = pose_from_yaw_translation(0.0, Vector3::new(0.0, 3.0, 0.0));
        let seven = local_from_remote.inverse() * truth[1] * beside;
        let eight =
            local_from_remote.inverse() * truth[4] * pose_from_yaw_translation(0.0, Vector3::new(0.0, 3.5, 0.0));
        graph.add_neighbour(
            RobotId(2),
            &local_from_remote,
            &[(KeyframeId(7), seven, held), (KeyframeId(8), eight, held)],
            &[(KeyframeId(1), KeyframeId(7), beside, tight), (KeyframeId(4), KeyframeId(8), beside, tight)],
        );
        let joint = graph.solve(false, 0).expect("solves");
        let bent = (joint.poses[4].1.translation.vector - truth[4].translation.vector).norm();
        assert!(bent > 0.1, "the joint solve bends our chain: {bent} m");
        let own = graph.own_poses().expect("own");
        assert_eq!(own.len(), 5);
        for ((k, pose), t) in own.iter().zip(&truth) {
            assert!((pose.translation.vector - t.translation.vector).norm() < 1e-6, "keyframe {k}: {pose:?}");
            assert!(pose.rotation.angle_to(&t.rotation) < 1e-9);
        }
    }

    #[test]
    fn the_anchor_is_reestimated_from_every_inter_robot_factor() {
        // A straight local chain of 10 keyframes, 2 m apart; the neighbour's world is turned
        // by 30° and 40 m away. Its keyframes each sit 3 m to the left of one of ours.
        let (mut graph, truth) = straight_chain(10);
        let true_local_from_remote = pose_from_yaw_translation(0.5, Vector3::new(40.0, -5.0, 0.3));
        let measured = pose_from_yaw_translation(0.2, Vector3::new(0.0, 3.0, 0.0));
        let keyframe_in_remote = |k: usize| true_local_from_remote.inverse() * truth[k] * measured;
        let cov = Matrix6::identity() * 0.01;
        // The first estimate is off by 1.5 m and 3°; each round brings two closures.
        let first = pose_from_yaw_translation(0.5 + 0.052, Vector3::new(41.0, -6.0, 0.5));
        for (round, ks) in [[1usize, 2], [5, 6], [8, 9]].iter().enumerate() {
            let keyframes: Vec<_> =
                ks.iter().map(|&k| (KeyframeId(100 + k as u32), keyframe_in_remote(k), cov)).collect();
            let factors: Vec<_> = ks
                .iter()
                .map(|&k| (KeyframeId(k as u32), KeyframeId(100 + k as u32), measured, information()))
                .collect();
            graph.add_neighbour(RobotId(3), &first, &keyframes, &factors);
            let solved = graph.solve(false, 0).expect("solves");
            assert_eq!(solved.anchors.len(), 1);
            let (robot, anchor) = solved.anchors[0];
            assert_eq!(robot, RobotId(3));
            // Exact factors: the anchor is the truth from the first round on (the local chain
            // stays where odometry and its first prior put it).
            let e = crate::geometry::pose_error(&anchor, &true_local_from_remote);
            assert!(e.translation_m < 1e-4 && e.max_axis_rotation_deg() < 1e-4, "round {round}: {e:?}");
        }
        // Frozen and thawed, the anchor is kept.
        let thawed = KeyframeGraph::thaw(graph.freeze()).expect("consistent");
        assert_eq!(thawed, graph);
    }

    /// Factors whose rotations say the neighbour's world is tilted by 1° about our keyframes'
    /// line (the x axis, through the anchor's translation, so that no translation sees it), with
    /// σ = 5°: free, the anchor takes the tilt; levelled it keeps what the prior's σ = 0.2°
    /// allows against them — 4 keyframes, each a 5° factor in series with its 0.1 rad prior
    /// (information 1/(1/131 + 1/100) = 56.7 rad⁻² each, 227 in all, against 1/σ_t² = 82 070),
    /// so 1° · 227 / (227 + 82 070) = 0.003°. Yaw and translation are the factors' either way.
    #[test]
    fn a_levelled_anchor_keeps_its_tilt_against_weak_rotation_evidence() {
        let roll = 1f64.to_radians();
        let translation = Vector3::new(40.0, 0.0, 0.0);
        let tilted = nalgebra::UnitQuaternion::from_axis_angle(&Vector3::x_axis(), roll)
            * nalgebra::UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.5);
        let truth_anchor = Pose3::from_parts(translation.into(), tilted);
        let measured = pose_from_yaw_translation(0.2, Vector3::zeros());
        let sigma_rotation = 5f64.to_radians();
        let weak_rotation = Matrix6::from_diagonal(&nalgebra::Vector6::new(
            sigma_rotation.powi(-2),
            sigma_rotation.powi(-2),
            sigma_rotation.powi(-2),
            1e4,
            1e4,
            1e4,
        ));
        let solve = |level: bool| {
            let (mut graph, truth) = straight_chain(10);
            let ks = [2usize, 4, 6, 8];
            let keyframes: Vec<_> = ks
                .iter()
                .map(|&k| {
                    (
                        KeyframeId(100 + k as u32),
                        truth_anchor.inverse() * truth[k] * measured,
                        Matrix6::identity() * 0.01,
                    )
                })
                .collect();
            let factors: Vec<_> = ks
                .iter()
                .map(|&k| (KeyframeId(k as u32), KeyframeId(100 + k as u32), measured, weak_rotation))
                .collect();
            graph.add_neighbour(RobotId(3), &pose_from_yaw_translation(0.5, translation), &keyframes, &factors);
            graph.set_level_anchors(level);
            graph.solve(false, 0).expect("solves").anchors[0].1
        };
        for (level, expected_tilt) in [(false, roll), (true, roll * 227.0 / (227.0 + 82_070.0))] {
            let anchor = solve(level);
            let tilt = (anchor.rotation * Vector3::z()).angle(&Vector3::z());
            assert!((tilt - expected_tilt).abs() < 0.005f64.to_radians(), "level {level}: tilt {}°", tilt.to_degrees());
            let yaw = crate::geometry::yaw_of(&anchor);
            assert!((yaw - 0.5).abs() < 0.02f64.to_radians(), "level {level}: yaw {yaw}");
            let off = (anchor.translation.vector - translation).norm();
            assert!(off < 1e-3, "level {level}: {off} m");
        }
    }

    /// An odometry that learns up (SGM's own) keeps the frame it levelled at the start, here
    /// 1.5° off gravity about the chain's axis, and learns up in it: for the first three
    /// keyframes it still believes the levelling (û = ẑ, σ_u 2°), from the fourth it knows
    /// (û = the frame's true up, σ_u 0.01°). Recorded as attitudes in that frame
    /// (`record_tilt`), the first keyframe's anchor pins the chain at the frame's tilt. Recorded
    /// as measurements (`record_up`), every keyframe is held to the latest up, so what was
    /// learnt at the fourth levels the first three too, and the anchor holds yaw and position
    /// only: the whole chain settles level, where the anchor and the odometry put it
    /// otherwise. After three keyframes alone it is where the levelling put it. A freeze keeps
    /// the attitudes and the latest up; a thaw refuses an up that is not a unit vector.
    #[test]
    fn keyframes_are_held_to_the_up_their_odometry_learnt_last_and_the_anchor_does_not_pin_it() {
        let tilt = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 1.5f64.to_radians());
        let frame_from_world = Pose3::from_parts(nalgebra::Translation3::identity(), tilt);
        let step = pose_from_yaw_translation(0.0, Vector3::new(2.0, 0.0, 0.0));
        let tilt_deg = |p: &Pose3| (p.rotation * Vector3::z()).angle(&Vector3::z()).to_degrees();
        let build = |measured: bool, keyframes: u32| {
            let mut graph = KeyframeGraph::default();
            for k in 0..keyframes {
                let in_frame = frame_from_world * (0..k).fold(Pose3::identity(), |p, _| p * step);
                let edges: Vec<KeyframeEdge> = (k > 0).then(|| odometry(k - 1, k, &step)).into_iter().collect();
                graph.add_keyframe(
                    &Keyframe { id: KeyframeId(k), stamp: f64::from(k), world_from_body: in_frame },
                    &edges,
                    100,
                );
                let recorded = if measured {
                    let (up_in_frame, sigma_deg) =
                        if k < 3 { (Vector3::z(), 2.0) } else { (tilt * Vector3::z(), 0.01) };
                    let m = MeasuredUp {
                        attitude_in_frame: in_frame.rotation,
                        up_in_frame,
                        sigma_rad: f64::to_radians(sigma_deg),
                    };
                    graph.record_up(KeyframeId(k), &m)
                } else {
                    graph.record_tilt(KeyframeId(k), &UnitQuaternion::identity())
                };
                assert!(recorded);
            }
            graph.set_gravity_priors(Some(0.2f64.to_radians()));
            graph.solve(false, 0).expect("solves");
            let solved = graph.solve(false, 0).expect("solves");
            (graph, solved.poses)
        };
        let (_, pinned) = build(false, 10);
        assert!(tilt_deg(&pinned[0].1) > 1.3, "pinned: {}°", tilt_deg(&pinned[0].1));
        let (_, early) = build(true, 3);
        for (k, p) in &early {
            assert!((tilt_deg(p) - 1.5).abs() < 0.01, "keyframe {} before the odometry knew: {}°", k.0, tilt_deg(p));
        }
        let (mut graph, free) = build(true, 10);
        for (k, p) in &free {
            assert!(tilt_deg(p) < 0.02, "keyframe {}: {}°", k.0, tilt_deg(p));
            assert!(crate::geometry::yaw_of(p).abs() < 1e-6, "keyframe {}", k.0);
            let expected = Vector3::new(2.0 * f64::from(k.0), 0.0, 0.0);
            assert!((p.translation.vector - expected).norm() < 1e-3, "keyframe {}: {}", k.0, p.translation.vector);
        }
        // The anchor is whole again after the solve: what a freeze keeps is unchanged by it.
        let whole = nalgebra::Vector6::from_iterator(GTSAM_PRIOR_SIGMAS_3D.iter().map(|s| 1.0 / s));
        assert_eq!(graph.graph.priors[0].sqrt_information, Matrix6::from_diagonal(&whole));
        // A solve cut short (a panic) with its anchor cut and its gravity priors in: a freeze
        // and the next solve make the anchor whole again.
        let before = graph.freeze();
        let gravity = graph.gravity_priors();
        let held = graph.graph.priors.len();
        graph.transient_anchors = graph.free_anchor_tilts(&gravity);
        graph.graph.priors.extend(gravity);
        graph.transient_from = Some(held);
        assert_ne!(graph.graph.priors[0].sqrt_information, Matrix6::from_diagonal(&whole));
        assert_eq!(graph.freeze(), before);
        graph.solve(false, 0).expect("solves");
        assert_eq!(graph.graph.priors[0].sqrt_information, Matrix6::from_diagonal(&whole));
        assert!(graph.transient_anchors.is_empty() && graph.transient_from.is_none());
        // Bad measurements are refused; a keyframe the graph does not hold too.
        let good =
            MeasuredUp { attitude_in_frame: UnitQuaternion::identity(), up_in_frame: Vector3::z(), sigma_rad: 0.01 };
        assert!(!graph.record_up(KeyframeId(99), &good));
        assert!(!graph.record_up(KeyframeId(3), &MeasuredUp { up_in_frame: Vector3::new(0.0, 0.0, 2.0), ..good }));
        assert!(!graph.record_up(KeyframeId(3), &MeasuredUp { sigma_rad: f64::NAN, ..good }));
        let state = graph.freeze();
        assert_eq!(state.frame_attitudes.len(), 10);
        let mut thawed = KeyframeGraph::thaw(state.clone()).expect("fits");
        thawed.set_gravity_priors(Some(0.2f64.to_radians()));
        assert_eq!(thawed, graph);
        let mut broken = state;
        broken.frame_up = Some((Vector3::new(0.0, 0.0, 2.0), 0.01));
        assert_eq!(KeyframeGraph::thaw(broken), None, "an up that is not a unit vector");
    }

    /// A loop closure that puts keyframe 9 of a level 18 m chain 0.3 m lower than odometry says
    /// bends the chain: the odometry's rotation σ is 0.57° and its translation σ 1 cm a step, so
    /// without gravity priors the drop is mostly taken as pitch (1.3° at the worst keyframe).
    /// With each keyframe's level tilt recorded, σ = 0.2° holds them within 0.3° and σ = 0.02°
    /// within 0.05°: the drop goes to the translations. The yaw and the horizontal positions do
    /// not move either way. A neighbour, loosely held, is beside keyframe 5, so that own poses
    /// are solved apart (without it they are the joint poses): they hold the same priors.
    /// The priors live for one solve: frozen, the graph holds its one first-keyframe prior and
    /// the tilts (not the one recorded for a keyframe it does not hold, nor a non-rotation), and
    /// priors a cut-short solve left are taken away by the next solve and by a freeze.
    #[test]
    fn gravity_priors_keep_a_bent_chain_level() {
        let solve = |sigma_deg: Option<f64>| {
            let (mut graph, truth) = straight_chain(10);
            let mut loop_edge = odometry(0, 9, &(truth[9] * Pose3::translation(0.0, 0.0, -0.3)));
            loop_edge.kind = KeyframeEdgeKind::Loop;
            graph.add_keyframe(
                &Keyframe { id: KeyframeId(10), stamp: 10.0, world_from_body: truth[9] * truth[1] },
                &[odometry(9, 10, &truth[1]), loop_edge],
                100,
            );
            let beside = Pose3::translation(0.0, 3.0, 0.0);
            graph.add_neighbour(
                RobotId(2),
                &Pose3::identity(),
                &[(KeyframeId(50), truth[5] * beside, Matrix6::identity())],
                &[(KeyframeId(5), KeyframeId(50), beside, information())],
            );
            // Measured level; the yaw of the measured attitude is ignored.
            for k in 0..=10u32 {
                let attitude = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.3 * f64::from(k));
                assert!(graph.record_tilt(KeyframeId(k), &attitude));
            }
            assert!(!graph.record_tilt(KeyframeId(99), &UnitQuaternion::identity()), "not the graph's");
            let not_a_rotation = UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(f64::NAN, 0.0, 0.0, 0.0));
            assert!(!graph.record_tilt(KeyframeId(3), &not_a_rotation));
            graph.set_gravity_priors(sigma_deg.map(f64::to_radians));
            let solved = graph.solve(false, 0).expect("solves");
            let own = graph.own_poses().expect("solves");
            (graph, solved.poses, own)
        };
        let max_tilt = |poses: &[(KeyframeId, Pose3)]| {
            poses.iter().map(|(_, p)| (p.rotation * Vector3::z()).angle(&Vector3::z()).to_degrees()).fold(0.0, f64::max)
        };
        let (_, free, own_free) = solve(None);
        let (mut graph, held, own_held) = solve(Some(0.2));
        let (_, tight, _) = solve(Some(0.02));
        assert!(max_tilt(&free) > 1.0, "free: {}°", max_tilt(&free));
        assert!(max_tilt(&held) < 0.3, "held: {}°", max_tilt(&held));
        assert!(max_tilt(&tight) < 0.05, "tight: {}°", max_tilt(&tight));
        assert!(max_tilt(&own_free) > 1.0, "own, free: {}°", max_tilt(&own_free));
        assert!(max_tilt(&own_held) < 0.3, "own, held: {}°", max_tilt(&own_held));
        for ((_, f), (_, h)) in free.iter().zip(&tight) {
            assert!((f.translation.vector.xy() - h.translation.vector.xy()).norm() < 0.01);
            assert!(crate::geometry::yaw_of(h).abs() < 1e-6 && crate::geometry::yaw_of(f).abs() < 1e-6);
        }
        // Held level, the chain meets the loop by height: keyframe 9 is well below the odometry's.
        let z9 = tight[9].1.translation.z;
        assert!(z9 < -0.1, "keyframe 9 at z {z9}");
        let state = graph.freeze();
        let priors = state.graph.priors.len();
        assert_eq!(priors, 2, "the first keyframe's and the anchor's");
        assert_eq!(state.tilts.len(), 11);
        let mut thawed = KeyframeGraph::thaw(state.clone()).expect("fits");
        thawed.set_gravity_priors(Some(0.2f64.to_radians()));
        assert_eq!(thawed, graph);
        // A solve cut short with its priors in the graph.
        let gravity = graph.gravity_priors();
        graph.transient_from = Some(priors);
        graph.graph.priors.extend(gravity);
        assert_eq!(graph.freeze(), state);
        graph.solve(false, 0).expect("solves");
        assert_eq!((graph.graph.priors.len(), graph.transient_from), (priors, None));
        let mut broken = state;
        broken.tilts.push((KeyframeId(4), Vector3::new(0.0, 0.0, 2.0)));
        assert_eq!(KeyframeGraph::thaw(broken), None, "an up that is not a unit vector");
    }

    #[test]
    fn a_stale_neighbour_prior_refreshed_gives_the_graph_built_with_the_fresh_one() {
        // The neighbour sent keyframes 102 and 106 at poses its own solves later moved: 102 by
        // 0.3 m and 1° of yaw. The stale prior pulls the anchor off the truth; the refreshed
        // graph solves to the truth, as a graph given the fresh poses from the start does. A
        // second neighbour holds a keyframe of the same id, whose tie must not move.
        let true_local_from_remote = pose_from_yaw_translation(0.5, Vector3::new(40.0, -5.0, 0.3));
        let other_from_remote = pose_from_yaw_translation(-0.3, Vector3::new(-20.0, 8.0, 0.0));
        let measured = pose_from_yaw_translation(0.2, Vector3::new(0.0, 3.0, 0.0));
        let cov = Matrix6::identity() * 0.01;
        let (_, truth) = straight_chain(10);
        let fresh = |k: usize| true_local_from_remote.inverse() * truth[k] * measured;
        let stale_102 = fresh(2) * pose_from_yaw_translation(1f64.to_radians(), Vector3::new(0.3, 0.0, 0.0));
        // `updates` reach the graph before the neighbour's keyframes do (deferred), if any; with
        // `claimed`, after a vague claim on keyframe 102 (a false factor's) brought it in early.
        let build = |sent_102: Pose3, updates: &[(KeyframeId, Pose3)], claimed: bool| {
            let (mut graph, _) = straight_chain(10);
            if claimed {
                let vague = [(KeyframeId(102), Pose3::identity(), Matrix6::identity() * 1e4)];
                graph.add_neighbour(RobotId(3), &true_local_from_remote, &vague, &[]);
            }
            let early = graph.refresh_neighbour(RobotId(3), updates);
            let (moved, deferred) = if claimed { (updates.len(), 0) } else { (0, updates.len()) };
            assert_eq!(early, Refreshed { moved, deferred, dropped: 0 });
            let keyframes = [(KeyframeId(102), sent_102, cov), (KeyframeId(106), fresh(6), cov)];
            let factors: Vec<_> = [2usize, 6]
                .iter()
                .map(|&k| (KeyframeId(k as u32), KeyframeId(100 + k as u32), measured, information()))
                .collect();
            graph.add_neighbour(RobotId(3), &true_local_from_remote, &keyframes, &factors);
            let other = [(KeyframeId(102), other_from_remote.inverse() * truth[4] * measured, cov)];
            let other_factor = [(KeyframeId(4), KeyframeId(102), measured, information())];
            graph.add_neighbour(RobotId(4), &other_from_remote, &other, &other_factor);
            graph
        };
        let solve = |graph: &mut KeyframeGraph| graph.solve(false, 3).expect("solves");
        let anchor_error = |solved: &Solved, robot: RobotId, truth: &Pose3| {
            let anchor = solved.anchors.iter().find(|(r, _)| *r == robot).expect("anchored").1;
            crate::geometry::pose_error(&anchor, truth)
        };
        let same = |a: &Solved, b: &Solved| {
            a.poses
                .iter()
                .zip(&b.poses)
                .all(|((ka, pa), (kb, pb))| ka == kb && (pa.to_homogeneous() - pb.to_homogeneous()).abs().max() < 1e-9)
        };
        let fresh_solved = solve(&mut build(fresh(2), &[], false));
        let mut graph = build(stale_102, &[], false);
        let stale = anchor_error(&solve(&mut graph), RobotId(3), &true_local_from_remote);
        assert!(stale.translation_m > 0.05 && stale.max_axis_rotation_deg() > 0.2, "{stale:?}");
        // The held keyframe of robot 3 moves; robot 4's keyframe 102 does not; an unknown one
        // is deferred.
        let poses = [(KeyframeId(102), fresh(2)), (KeyframeId(555), Pose3::identity())];
        assert_eq!(graph.refresh_neighbour(RobotId(3), &poses), Refreshed { moved: 1, deferred: 1, dropped: 0 });
        let solved = solve(&mut graph);
        let refreshed = anchor_error(&solved, RobotId(3), &true_local_from_remote);
        assert!(refreshed.translation_m < 1e-6 && refreshed.max_axis_rotation_deg() < 1e-6, "{refreshed:?}");
        let other = anchor_error(&solved, RobotId(4), &other_from_remote);
        assert!(other.translation_m < 1e-6 && other.max_axis_rotation_deg() < 1e-6, "{other:?}");
        assert!(same(&solved, &fresh_solved));
        let counts = graph.status().inter_robot;
        assert_eq!((counts[0].robot, counts[0].refreshed, counts[1].refreshed), (RobotId(3), 1, 0));
        let thawed = KeyframeGraph::thaw(graph.freeze()).expect("consistent");
        assert_eq!(thawed, graph);
        // An update that came before its keyframe is taken when the keyframe arrives.
        let mut early = build(stale_102, &[(KeyframeId(102), fresh(2))], false);
        assert!(same(&solve(&mut early), &fresh_solved));
        assert_eq!(early.status().inter_robot[0].refreshed, 1);
        // Brought in early by a vague claim and updated there, the keyframe served later (its
        // served pose older than the update) takes the served covariance and keeps the update.
        let mut claimed = build(stale_102, &[(KeyframeId(102), fresh(2))], true);
        assert!(same(&solve(&mut claimed), &fresh_solved));
        assert_eq!(KeyframeGraph::thaw(claimed.freeze()).as_ref(), Some(&claimed));
        // Deferred updates are bounded per neighbour; a later update of one held is kept.
        let mut graph = KeyframeGraph::default();
        let many: Vec<_> = (0..MAX_DEFERRED_POSES as u32 + 5).map(|k| (KeyframeId(k), Pose3::identity())).collect();
        let r = graph.refresh_neighbour(RobotId(7), &many);
        assert_eq!((r.deferred, r.dropped), (MAX_DEFERRED_POSES, 5));
        assert_eq!(graph.refresh_neighbour(RobotId(7), &many[..1]).deferred, 1);
        assert_eq!(graph.refresh_neighbour(RobotId(8), &many[..1]).deferred, 1, "per neighbour");
    }

    #[test]
    fn a_wrong_first_alignment_is_outvoted_by_later_consistent_closures() {
        let (mut graph, truth) = straight_chain(12);
        let true_local_from_remote = pose_from_yaw_translation(0.3, Vector3::new(20.0, 4.0, 0.0));
        // The first round: three registrations that agree with each other and with a wrong
        // match 4 m and 8° off.
        let wrong = pose_from_yaw_translation(0.3 + 0.14, Vector3::new(23.0, 7.0, 0.0));
        let cov = Matrix6::identity() * 0.01;
        let measured = pose_from_yaw_translation(0.0, Vector3::new(0.0, 2.0, 0.0));
        let remote_pose = |l: &Pose3, k: usize| l.inverse() * truth[k] * measured;
        let round = |l: &Pose3, ks: &[usize], base: u32| {
            let keyframes: Vec<_> = ks.iter().map(|&k| (KeyframeId(base + k as u32), remote_pose(l, k), cov)).collect();
            let factors: Vec<_> = ks
                .iter()
                .map(|&k| (KeyframeId(k as u32), KeyframeId(base + k as u32), measured, information()))
                .collect();
            (keyframes, factors)
        };
        let (keyframes, factors) = round(&wrong, &[0, 1, 2], 100);
        graph.add_neighbour(RobotId(2), &wrong, &keyframes, &factors);
        let first = graph.solve(true, 0).expect("solves");
        assert!(crate::geometry::pose_error(&first.anchors[0].1, &wrong).translation_m < 1e-3);
        // Five honest closures over the rest of the chain.
        let (keyframes, factors) = round(&true_local_from_remote, &[4, 6, 8, 10, 11], 200);
        graph.add_neighbour(RobotId(2), &wrong, &keyframes, &factors);
        let solved = graph.solve(true, 0).expect("solves");
        let e = crate::geometry::pose_error(&solved.anchors[0].1, &true_local_from_remote);
        assert!(e.translation_m < 1e-3 && e.max_axis_rotation_deg() < 1e-3, "{e:?}");
        let status = graph.status();
        assert_eq!(
            status.inter_robot,
            vec![InterRobotCounts { robot: RobotId(2), factors: 8, inconsistent: 3, realigned: 1, refreshed: 0 }]
        );
        assert_eq!(status.rejected_inter_robot.len(), 3);
        // The local chain kept its odometry: the lie bent nothing.
        for (k, pose) in &solved.poses {
            assert!((pose.translation.vector - truth[k.0 as usize].translation.vector).norm() < 1e-3);
        }
    }

    /// A neighbour withdrawn (its alignment found wrong) leaves the graph that never held it:
    /// with a second neighbour aligned after it and local keyframes added after both (so every
    /// index behind it moves), the solve is the one of the graph built without it, to the bit;
    /// a later alignment places a fresh anchor where its round says.
    #[test]
    fn a_withdrawn_neighbour_leaves_the_graph_that_never_held_it() {
        let step = pose_from_yaw_translation(0.0, Vector3::new(2.0, 0.0, 0.0));
        let cov = Matrix6::identity() * 0.01;
        let measured = pose_from_yaw_translation(0.0, Vector3::new(0.0, 2.0, 0.0));
        let right = pose_from_yaw_translation(0.3, Vector3::new(20.0, 4.0, 0.0));
        let wrong = pose_from_yaw_translation(0.3 + std::f64::consts::PI, Vector3::new(-9.0, 30.0, 0.0));
        let round = |robot: u16, l: &Pose3, ks: &[u32], truth: &[Pose3]| {
            let keyframes: Vec<_> =
                ks.iter().map(|&k| (KeyframeId(100 + k), l.inverse() * truth[k as usize] * measured, cov)).collect();
            let factors: Vec<_> =
                ks.iter().map(|&k| (KeyframeId(k), KeyframeId(100 + k), measured, information())).collect();
            (RobotId(robot), keyframes, factors)
        };
        let build = |with_wrong: bool| {
            let (mut graph, truth) = straight_chain(6);
            if with_wrong {
                let (robot, keyframes, factors) = round(2, &wrong, &[1, 3, 5], &truth);
                graph.add_neighbour(robot, &wrong, &keyframes, &factors);
                graph.solve(true, 0).expect("solves");
            }
            let (robot, keyframes, factors) = round(3, &right, &[0, 2, 4], &truth);
            graph.add_neighbour(robot, &right, &keyframes, &factors);
            for k in 6..9 {
                let pose = truth[5] * (5..k).fold(Pose3::identity(), |p, _| p * step);
                let keyframe = Keyframe { id: KeyframeId(k), stamp: f64::from(k), world_from_body: pose };
                graph.add_keyframe(&keyframe, &[odometry(k - 1, k, &step)], 100);
            }
            // Held behind the withdrawn neighbour's variables and factors, so that the
            // withdrawal renumbers them: a false loop closure (keyframe 8 said to be at 2, 12 m
            // away) that the solve rejects, and a pose update of one of robot 3's keyframes.
            let mut false_loop = odometry(2, 8, &Pose3::identity());
            false_loop.kind = KeyframeEdgeKind::Loop;
            let pose = truth[5] * (5..9).fold(Pose3::identity(), |p, _| p * step);
            let edges = [odometry(8, 9, &step), false_loop];
            graph.add_keyframe(&Keyframe { id: KeyframeId(9), stamp: 9.0, world_from_body: pose }, &edges, 100);
            graph.refresh_neighbour(RobotId(3), &[(KeyframeId(102), right.inverse() * truth[2] * measured)]);
            graph.solve(true, 0).expect("solves");
            (graph, truth)
        };
        let (mut withdrawn, truth) = build(true);
        withdrawn.refresh_neighbour(RobotId(2), &[(KeyframeId(500), Pose3::identity())]);
        assert_eq!(withdrawn.withdraw_neighbour(RobotId(2)), Some(3), "its three inter-robot factors");
        assert_eq!(withdrawn.withdraw_neighbour(RobotId(2)), None, "gone already");
        assert_eq!((withdrawn.withdrawals(RobotId(2)), withdrawn.withdrawals(RobotId(3))), (2, 0), "both counted");
        let (mut never, _) = build(false);
        // The same variables and factors; the values differ by what the solve with the
        // withdrawn neighbour moved them (it agreed with itself: ~1e-23 m).
        let (w, n) = (&withdrawn.graph, &never.graph);
        assert_eq!((&w.keys, &w.fixed, &w.betweens, &w.priors), (&n.keys, &n.fixed, &n.betweens, &n.priors));
        let (fw, fn_) = (withdrawn.freeze(), never.freeze());
        assert_eq!(
            (&fw.index, &fw.candidates, &fw.rejected, &fw.updated),
            (&fn_.index, &fn_.candidates, &fn_.rejected, &fn_.updated)
        );
        assert_eq!((fw.rejected.len(), fw.updated.len()), (1, 1), "the false loop rejected, the update held");
        assert_eq!(withdrawn.inconsistent, never.inconsistent);
        let (a, b) = (withdrawn.solve(true, 2).expect("solves"), never.solve(true, 2).expect("solves"));
        let near = |x: &Pose3, y: &Pose3| {
            let e = crate::geometry::pose_error(x, y);
            e.translation_m < 1e-9 && e.max_axis_rotation_deg() < 1e-9
        };
        assert_eq!(a.poses.len(), b.poses.len());
        assert!(a.poses.iter().zip(&b.poses).all(|(x, y)| x.0 == y.0 && near(&x.1, &y.1)));
        assert!(a.anchors.len() == 1 && a.anchors[0].0 == RobotId(3) && near(&a.anchors[0].1, &b.anchors[0].1));
        assert_eq!(a.covariances.len(), 2);
        assert!(a.covariances.iter().zip(&b.covariances).all(|(x, y)| (x.1 - y.1).norm() < 1e-12));
        assert_eq!(withdrawn.status().inter_robot.iter().map(|c| c.robot).collect::<Vec<_>>(), [RobotId(3)]);
        assert!(withdrawn.freeze().deferred.is_empty(), "its held pose updates went with it");
        // Aligned again, rightly this time: a fresh anchor where the round puts it.
        let (robot, keyframes, factors) = round(2, &right, &[1, 3, 5], &truth);
        withdrawn.add_neighbour(robot, &right, &keyframes, &factors);
        let solved = withdrawn.solve(true, 0).expect("solves");
        let anchor = solved.anchors.iter().find(|(r, _)| *r == RobotId(2)).expect("anchored again").1;
        let e = crate::geometry::pose_error(&anchor, &right);
        assert!(e.translation_m < 1e-6 && e.max_axis_rotation_deg() < 1e-6, "{e:?}");
    }

    #[test]
    fn a_neighbour_keyframe_received_again_keeps_its_more_informative_prior() {
        let (_, truth) = straight_chain(6);
        let local_from_remote = pose_from_yaw_translation(0.2, Vector3::new(10.0, 0.0, 0.0));
        let measured = pose_from_yaw_translation(0.0, Vector3::new(0.0, 2.0, 0.0));
        let honest_pose = local_from_remote.inverse() * truth[3] * measured;
        let honest = (KeyframeId(103), honest_pose, Matrix6::identity() * 0.01);
        // A claim that knew little of the keyframe: 3 m off, and next to no information.
        let vague_pose = honest_pose * pose_from_yaw_translation(0.3, Vector3::new(3.0, 0.0, 0.0));
        let vague_cov = Matrix6::from_diagonal(&nalgebra::Vector6::new(1.0, 1.0, 1.0, 1e4, 1e4, 1e4));
        let vague = (KeyframeId(103), vague_pose, vague_cov);
        let not_finite = (KeyframeId(103), vague_pose, Matrix6::identity() * f64::NAN);
        let not_positive = (KeyframeId(103), vague_pose, -Matrix6::identity());
        let factors = [(KeyframeId(1), KeyframeId(103), measured, information())];
        let factor_of_5 = [(KeyframeId(5), KeyframeId(105), measured, information())];
        let other = (KeyframeId(105), local_from_remote.inverse() * truth[5] * measured, Matrix6::identity() * 0.01);
        // Every arrival order ends as the graph that only ever got the honest prior.
        let solved = |arrivals: &[(KeyframeId, Pose3, Matrix6<f64>)]| {
            let (mut graph, _) = straight_chain(6);
            for (n, a) in arrivals.iter().enumerate() {
                let with = if n + 1 == arrivals.len() { &factors[..] } else { &[] };
                graph.add_neighbour(RobotId(2), &local_from_remote, &[*a], with);
            }
            graph.add_neighbour(RobotId(2), &local_from_remote, &[other], &factor_of_5);
            let anchor = graph.solve(false, 0).expect("solves").anchors[0].1;
            let state = graph.freeze();
            let ties: Vec<(Pose3, Matrix6<f64>)> = state
                .graph
                .betweens
                .iter()
                .zip(&state.candidates)
                .filter(|(b, c)| !**c && b.from == state.anchors[0].1)
                .map(|(b, _)| (b.measured, b.sqrt_information))
                .collect();
            (anchor, ties)
        };
        let (anchor, ties) = solved(&[honest]);
        assert_eq!(ties.len(), 2);
        // As informative as the honest one, from an earlier estimate: the later one wins.
        let earlier = (KeyframeId(103), vague_pose, Matrix6::identity() * 0.01);
        for arrivals in [
            vec![vague, honest],
            vec![honest, vague],
            vec![not_finite, honest],
            vec![honest, not_finite],
            vec![not_positive, honest],
            vec![honest, not_positive],
            vec![earlier, honest],
        ] {
            let (a, t) = solved(&arrivals);
            assert_eq!(t, ties, "the ties to the anchor");
            // The same problem from other starting values (the variable was made at the vague
            // pose): the same answer to LM's tolerance.
            let e = crate::geometry::pose_error(&a, &anchor);
            assert!(e.translation_m < 1e-3 && e.max_axis_rotation_deg() < 1e-2, "{e:?}");
        }
        // Alone, the vague claim is what the graph has of the keyframe.
        let (_, t) = solved(&[vague]);
        assert_eq!(t[0].0, vague_pose);
    }

    #[test]
    fn two_disagreeing_factors_are_a_tie_not_a_verdict() {
        let (mut graph, truth) = straight_chain(6);
        let near = pose_from_yaw_translation(0.2, Vector3::new(10.0, 0.0, 0.0));
        let far = pose_from_yaw_translation(0.2, Vector3::new(13.0, 2.0, 0.0));
        let measured = pose_from_yaw_translation(0.0, Vector3::new(0.0, 2.0, 0.0));
        let cov = Matrix6::identity() * 0.01;
        let keyframe = |l: &Pose3, k: usize| (KeyframeId(100 + k as u32), l.inverse() * truth[k] * measured, cov);
        let factor = |k: usize| (KeyframeId(k as u32), KeyframeId(100 + k as u32), measured, information());
        graph.add_neighbour(RobotId(2), &near, &[keyframe(&near, 1), keyframe(&far, 4)], &[factor(1), factor(4)]);
        graph.solve(true, 0).expect("solves");
        let status = graph.status();
        assert_eq!(
            status.inter_robot,
            vec![InterRobotCounts { robot: RobotId(2), factors: 2, inconsistent: 0, realigned: 0, refreshed: 0 }]
        );
    }
}
