//! `Optimiser` (paper §III, §IV-E): a thin actor over `model::optim::keyframe_graph`, the
//! robot's pose graph — local keyframes with odometry and intra-robot loop factors, neighbour
//! keyframes as variables with priors from their marginal covariances (expressed in our world
//! through `local_from_remote`), and inter-robot factors from ICP — solved by
//! Levenberg–Marquardt on faer. Publishes optimised poses and marginal covariances to the
//! Tracker, which applies them to the map (the Matcher sees them in the next map snapshot), and
//! each neighbour's transform as the graph now estimates it (its anchor) to the Matcher. A
//! neighbour's later estimates of keyframes it served us (`KeyframePoses`, through Comms) move
//! the means of their priors (or wait for keyframes not yet in the graph), and the graph is
//! solved again at the next tick. With `comms.pose_updates.own_estimates`, what we tell
//! neighbours of our own keyframes is a second solve's, of our graph without them
//! (`KeyframeGraph::own_poses`): the joint poses hold each neighbour's own factors, and telling
//! them back echoes its information into its graph.
//!
//! A wrong loop closure or inter-robot factor (a false match that passed every check) would
//! bend the whole trajectory toward it. With `reject_outliers`, each solve is GNC-TLS over those
//! factors (`robust::optimize_gnc_incremental`): the previous decision is kept while it still
//! holds — one solve — and made again from scratch when it does not. Rejected factors stay in
//! the graph with weight 0 (a later solve may take them back) and add no information to the
//! marginals.
//!
//! With `optimiser.share_factors`, every `share_period_s` each aligned neighbour is asked (a
//! `GraphFactorRequest` through Comms) for its factor log from where its chain ends, and asked
//! again at once after a full reply (more may be waiting); a neighbour's request is answered from our
//! log (`KeyframeGraph::factor_slice`, at most `comms.limits.max_ids` keyframes and factors).
//! A slice received goes into the graph as the neighbour's chain and is solved at the next
//! tick.

use crate::config::OptimiserConfig;
use crate::containment::contained;
use crate::messages::*;
use actix::{Actor, Context, Handler, Recipient, Supervised};
use sgm_model::optim::keyframe_graph::{ChainAdded, KeyframeGraph, KeyframeGraphState, KeyframeGraphStatus};
use sgm_model::scene_graph::{RobotId, Stamp};
use sgm_model::wire::messages::{GraphFactorRequest, GraphFactors};
use sgm_model::wire::Message as WireMessage;

/// Where optimised poses go (the Tracker applies them to the map and shares the map).
#[derive(Clone)]
pub struct OptimiserLinks {
    pub tracker: Recipient<PosesOptimised>,
    /// Each solve's estimate of every aligned neighbour's transform.
    pub matcher: Recipient<NeighbourTransforms>,
    /// Factor-log requests and slices for neighbours (`optimiser.share_factors`).
    pub comms: Recipient<Outgoing>,
}

/// Most keyframes whose marginal covariance is computed after each optimisation (the latest).
const MARGINALS: usize = 200;

pub struct Optimiser {
    robot: RobotId,
    config: OptimiserConfig,
    links: Option<OptimiserLinks>,
    graph: KeyframeGraph,
    /// Neighbour keyframe priors moved since the last solve (solved at the next tick).
    refreshed_since_solve: bool,
    /// Hold the anchors level (gravity-aligned worlds).
    level_anchors: bool,
    /// Solve our own poses for what neighbours are told (`comms.pose_updates.own_estimates`).
    own_estimates: bool,
    failures: SolveFailures,
    /// When each neighbour was last asked for its log (`share_factors`).
    asked_at: std::collections::BTreeMap<RobotId, Stamp>,
    /// The latest tick's time.
    now: Stamp,
    /// Neighbours told (in the log) that we do not share, having asked for our log.
    refused_logs: std::collections::BTreeSet<RobotId>,
    /// Most keyframes and factors in one slice we send (the wire's `limits.max_ids`).
    slice_items: usize,
}

/// Solves that failed since the Optimiser started (each is also logged at warn; a thawed
/// Optimiser counts anew).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct SolveFailures {
    /// Solves of the pose graph that failed: the map kept its previous poses.
    pub failed_solves: u64,
    /// Solves of our own poses (`comms.pose_updates.own_estimates`) that failed: neighbours
    /// were told the joint poses instead.
    pub failed_own_solves: u64,
    /// The latest failure's reason.
    pub last_failure: Option<String>,
    /// Keyframes whose odometry attitude was not a rotation: held by no gravity prior.
    pub refused_attitudes: u64,
}

/// What of the Optimiser a snapshot keeps: the whole pose graph and its outlier decisions.
pub type OptimiserState = KeyframeGraphState;

/// The Optimiser at a glance: its pose graph, and the solves that failed.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct OptimiserStatus {
    #[serde(flatten)]
    pub graph: KeyframeGraphStatus,
    #[serde(flatten)]
    pub failures: SolveFailures,
}

/// Runner / operator → Optimiser: what the pose graph holds.
#[derive(actix::Message)]
#[rtype(result = "OptimiserStatus")]
pub struct GetOptimiserStatus;

impl Optimiser {
    pub fn new(robot: RobotId, config: OptimiserConfig) -> Self {
        Self {
            robot,
            config,
            links: None,
            graph: KeyframeGraph::default(),
            refreshed_since_solve: false,
            level_anchors: false,
            own_estimates: false,
            failures: SolveFailures::default(),
            asked_at: Default::default(),
            now: 0.0,
            refused_logs: Default::default(),
            slice_items: sgm_model::wire::WireLimits::default().max_ids,
        }
        .with_chain_bound()
    }

    fn with_chain_bound(mut self) -> Self {
        self.graph.set_chain_bound(self.config.max_chain_items);
        self
    }

    /// The most keyframes and factors one slice of our log may carry: the wire's
    /// `comms.limits.max_ids`, which a receiver enforces.
    pub fn with_slice_items(mut self, max_ids: usize) -> Self {
        self.slice_items = max_ids.max(1);
        self
    }

    /// Neighbours are told our own measurements' estimate of our keyframes
    /// (`comms.pose_updates.own_estimates`): each solve is followed by a solve of the graph
    /// without them ([`KeyframeGraph::own_poses`]), sent with the poses.
    pub fn with_own_estimates(mut self, own: bool) -> Self {
        self.own_estimates = own;
        self
    }

    /// Gravity-aligned worlds (`matcher.max_tilt_deg = 0`: an IMU's): every neighbour's anchor is
    /// held level at each solve ([`KeyframeGraph::set_level_anchors`]; a thawed graph takes it
    /// too), and each own keyframe to the tilt its odometry measured, σ =
    /// `optimiser.gravity_sigma_deg` ([`KeyframeGraph::set_gravity_priors`]).
    pub fn with_level_anchors(mut self, level: bool) -> Self {
        self.level_anchors = level;
        self
    }

    pub fn freeze(&self) -> OptimiserState {
        self.graph.freeze()
    }

    /// Continues from `state`. An index that does not fit the graph (a snapshot from another
    /// build would have failed its checksum or decode first) leaves the optimiser empty.
    pub fn thawed(mut self, state: OptimiserState) -> Self {
        match KeyframeGraph::thaw(state) {
            Some(graph) => {
                self.graph = graph;
                self.graph.set_chain_bound(self.config.max_chain_items);
            }
            None => {
                tracing::error!(robot = %self.robot, "snapshot pose graph is inconsistent: starting the optimiser empty")
            }
        }
        self
    }

    /// Adds the keyframe and its edges, and in gravity-aligned worlds its measured tilt (held by
    /// a prior unless `gravity_sigma_deg` is 0): the up its odometry measured with its σ when it
    /// did, else the attitude's; whether to solve now.
    fn add_keyframe(&mut self, msg: &NewKeyframe) -> bool {
        let due = self.graph.add_keyframe(&msg.keyframe, &msg.edges, self.config.every_keyframes);
        // Recorded whenever the frames are level, so that σ can be changed on a resumed graph.
        if !self.level_anchors {
            return due;
        }
        let recorded = match &msg.measured_up {
            Some(up) => self.graph.record_up(msg.keyframe.id, up),
            None => self.graph.record_tilt(msg.keyframe.id, &msg.odom_from_body_rotation),
        };
        if !recorded {
            self.failures.refused_attitudes += 1;
            tracing::warn!(robot = %self.robot, keyframe = msg.keyframe.id.0,
                "keyframe's measured up or odometry attitude is not valid: no gravity prior for it");
        }
        due
    }

    /// σ of the gravity priors: in gravity-aligned worlds and unless `gravity_sigma_deg` is 0.
    fn gravity_sigma_rad(&self) -> Option<f64> {
        (self.level_anchors && self.config.gravity_sigma_deg > 0.0).then(|| self.config.gravity_sigma_deg.to_radians())
    }

    /// Solves, then publishes the poses and the newest keyframes' marginal covariances.
    fn solve_and_publish(&mut self) {
        self.refreshed_since_solve = false;
        self.graph.set_level_anchors(self.level_anchors);
        self.graph.set_gravity_priors(self.gravity_sigma_rad());
        let solved = match self.graph.solve(self.config.reject_outliers, MARGINALS) {
            Ok(solved) => solved,
            Err(e) => {
                tracing::warn!(robot = %self.robot, "pose graph not optimised: {e} (optimiser status failed_solves)");
                self.failures.failed_solves += 1;
                self.failures.last_failure = Some(format!("pose graph not optimised: {e}"));
                return;
            }
        };
        if solved.rejection_changed {
            let status = self.graph.status();
            tracing::info!(robot = %self.robot, rejected = status.rejected_factors, candidates = status.candidate_factors, "outlier factors");
        }
        // What neighbours are told of our keyframes, when asked: our own measurements' word, not
        // the joint solve's, which holds the neighbours' own factors already. None: the joint.
        let own_poses = if self.own_estimates {
            self.graph.own_poses().unwrap_or_else(|e| {
                tracing::warn!(robot = %self.robot, "own poses not solved ({e}): neighbours are told the joint ones (optimiser status failed_own_solves)");
                self.failures.failed_own_solves += 1;
                self.failures.last_failure = Some(format!("own poses not solved: {e}"));
                solved.poses.clone()
            })
        } else {
            Vec::new()
        };
        if let Some(links) = &self.links {
            links.tracker.do_send(PosesOptimised { poses: solved.poses, covariances: solved.covariances, own_poses });
            if !solved.anchors.is_empty() {
                let anchors = solved.anchors.into_iter().map(|(r, t)| (r, t, self.graph.withdrawals(r))).collect();
                links.matcher.do_send(NeighbourTransforms(anchors));
            }
        }
    }
}

impl Actor for Optimiser {
    type Context = Context<Self>;

    fn started(&mut self, _: &mut Context<Self>) {
        if self.level_anchors {
            // Said once, because frames declared level that are not cost accuracy silently.
            tracing::info!(robot = %self.robot, "frames declared gravity-aligned (matcher.max_tilt_deg = 0): neighbours' anchors held level");
        }
    }
}

impl Supervised for Optimiser {
    fn restarting(&mut self, _: &mut Context<Self>) {
        tracing::warn!(robot = %self.robot, variables = self.graph.variables(), "optimiser restarting with its graph");
    }
}

impl Handler<NewKeyframe> for Optimiser {
    type Result = ();
    fn handle(&mut self, msg: NewKeyframe, ctx: &mut Context<Self>) {
        contained(ctx, "optimiser", || {
            if self.add_keyframe(&msg) {
                self.solve_and_publish();
            }
        });
    }
}

impl Handler<InterRobotConstraints> for Optimiser {
    type Result = ();
    fn handle(&mut self, msg: InterRobotConstraints, ctx: &mut Context<Self>) {
        contained(ctx, "optimiser", || {
            self.graph.add_neighbour(msg.robot, &msg.local_from_remote, &msg.neighbour_keyframes, &msg.factors);
            self.solve_and_publish();
        });
    }
}

impl Handler<NeighbourWithdrawn> for Optimiser {
    type Result = ();
    fn handle(&mut self, msg: NeighbourWithdrawn, ctx: &mut Context<Self>) {
        contained(ctx, "optimiser", || {
            // Not held (no factor ever reached the graph): nothing to solve again.
            if let Some(factors) = self.graph.withdraw_neighbour(msg.robot) {
                tracing::info!(robot = %self.robot, neighbour = %msg.robot, factors, "neighbour withdrawn from the pose graph");
                self.solve_and_publish();
            }
        });
    }
}

impl Handler<NeighbourKeyframePoses> for Optimiser {
    type Result = ();
    fn handle(&mut self, msg: NeighbourKeyframePoses, ctx: &mut Context<Self>) {
        contained(ctx, "optimiser", || {
            let r = self.graph.refresh_neighbour(msg.robot, &msg.poses);
            tracing::debug!(robot = %self.robot, neighbour = %msg.robot, moved = r.moved, deferred = r.deferred, "neighbour keyframe poses");
            if r.dropped > 0 {
                tracing::warn!(robot = %self.robot, neighbour = %msg.robot, dropped = r.dropped,
                    "pose updates of keyframes we do not hold dropped: too many waiting for their keyframes");
            }
            // Solved at the next tick: updates split over several envelopes make one solve.
            self.refreshed_since_solve |= r.moved > 0;
        });
    }
}

impl Handler<Tick> for Optimiser {
    type Result = ();
    fn handle(&mut self, msg: Tick, ctx: &mut Context<Self>) {
        contained(ctx, "optimiser", || {
            self.ask_neighbours(msg.now);
            if self.refreshed_since_solve {
                self.solve_and_publish();
            }
        });
    }
}

impl Optimiser {
    /// Asks `robot` for its log from `from` on.
    fn ask(&mut self, robot: RobotId, from: u32) {
        self.asked_at.insert(robot, self.now);
        if let Some(links) = &self.links {
            let message = WireMessage::GraphFactorRequest(GraphFactorRequest { from });
            links.comms.do_send(Outgoing { to: robot, message });
        }
    }

    /// Each aligned neighbour whose chain is not full and that was not asked within
    /// `share_period_s` is asked.
    fn ask_neighbours(&mut self, now: Stamp) {
        self.now = now;
        if !self.config.share_factors {
            return;
        }
        for (robot, from) in self.graph.chain_requests() {
            if self.asked_at.get(&robot).is_none_or(|t| now - t >= self.config.share_period_s) {
                self.ask(robot, from);
            }
        }
    }

    fn neighbour_graph(&mut self, msg: NeighbourGraph) {
        if !self.config.share_factors {
            // Said once per neighbour: its chain of us stays empty, and it may not know why.
            if let NeighbourGraph::Request { robot, .. } = msg {
                if self.refused_logs.insert(robot) {
                    tracing::warn!(robot = %self.robot, neighbour = %robot,
                        "neighbour asks for our factor log, but optimiser.share_factors is off here: not answered");
                }
            }
            return;
        }
        match msg {
            NeighbourGraph::Request { robot, from } => {
                let slice = self.graph.factor_slice(robot, from, self.slice_items);
                if let Some(links) = &self.links {
                    let message = WireMessage::GraphFactors(GraphFactors::from_slice(&slice));
                    links.comms.do_send(Outgoing { to: robot, message });
                }
            }
            NeighbourGraph::Slice { robot, slice } => match self.graph.add_chain(robot, &slice) {
                ChainAdded::Added { keyframes, factors, dropped } => {
                    if dropped > 0 {
                        tracing::warn!(robot = %self.robot, neighbour = %robot, dropped,
                            "neighbour factors to keyframes we do not hold, or not positive definite: left out (optimiser status chains)");
                    }
                    if keyframes + factors > 0 {
                        self.refreshed_since_solve = true;
                    }
                    // A full slice: more may be waiting, ask on at once.
                    if slice.next > slice.from && slice.items() >= self.slice_items {
                        self.ask(robot, slice.next);
                    }
                }
                ChainAdded::Full => {
                    tracing::warn!(robot = %self.robot, neighbour = %robot, bound = self.config.max_chain_items,
                        "neighbour's chain full: its further factors are not held (optimiser.max_chain_items)");
                }
                ChainAdded::NotAligned | ChainAdded::Stale => {
                    tracing::debug!(robot = %self.robot, neighbour = %robot, from = slice.from, "neighbour factor slice not taken");
                }
            },
        }
    }
}

impl Handler<NeighbourGraph> for Optimiser {
    type Result = ();
    fn handle(&mut self, msg: NeighbourGraph, ctx: &mut Context<Self>) {
        contained(ctx, "optimiser", || self.neighbour_graph(msg));
    }
}

impl Handler<GetOptimiserStatus> for Optimiser {
    type Result = actix::MessageResult<GetOptimiserStatus>;
    fn handle(&mut self, _: GetOptimiserStatus, _: &mut Context<Self>) -> Self::Result {
        actix::MessageResult(OptimiserStatus { graph: self.graph.status(), failures: self.failures.clone() })
    }
}

connects!(Optimiser => OptimiserLinks);
freezes!(Optimiser => OptimiserState);
stops_on_injected_failure!(Optimiser => "optimiser");

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix6;
    use sgm_model::geometry::Pose3;
    use sgm_model::scene_graph::{Keyframe, KeyframeEdge, KeyframeEdgeKind, KeyframeId, KeyframeRef};

    fn keyframe(id: u32, x: f64) -> Keyframe {
        Keyframe { id: KeyframeId(id), stamp: f64::from(id), world_from_body: Pose3::translation(x, 0.0, 0.0) }
    }

    /// An odometry edge whose information overflows the normal equations (finite, positive
    /// definite, 1e300 on the diagonal) makes the solve fail: the failure is counted in the
    /// status with its reason, and the actor keeps taking keyframes.
    #[actix_rt::test]
    async fn a_failed_solve_is_counted_in_the_status() {
        let optimiser = Optimiser::new(RobotId(0), OptimiserConfig::default()).start();
        optimiser
            .send(NewKeyframe {
                keyframe: keyframe(0, 0.0),
                edges: Vec::new(),
                odom_from_body_rotation: nalgebra::UnitQuaternion::identity(),
                measured_up: None,
            })
            .await
            .unwrap();
        let status = optimiser.send(GetOptimiserStatus).await.unwrap();
        assert_eq!(status.failures, SolveFailures::default(), "{status:?}");
        let edge = KeyframeEdge {
            kind: KeyframeEdgeKind::Loop,
            from: KeyframeId(0),
            to: KeyframeRef::Local(KeyframeId(1)),
            from_from_to: Pose3::translation(1.0, 0.0, 0.0),
            information: Matrix6::identity() * 1e300,
        };
        optimiser
            .send(NewKeyframe {
                keyframe: keyframe(1, 5.0),
                edges: vec![edge],
                odom_from_body_rotation: nalgebra::UnitQuaternion::identity(),
                measured_up: None,
            })
            .await
            .unwrap();
        let status = optimiser.send(GetOptimiserStatus).await.unwrap();
        assert_eq!(status.failures.failed_solves, 1, "{status:?}");
        assert!(status.failures.last_failure.as_deref().is_some_and(|r| r.starts_with("pose graph not optimised")));
        assert_eq!(status.graph.variables, 2);
    }

    /// Tilts are recorded in gravity-aligned worlds only (whatever σ: 0 only turns the priors
    /// off), as the world's up in each body.
    #[test]
    fn keyframe_tilts_are_recorded_in_gravity_aligned_worlds() {
        let tilted = nalgebra::UnitQuaternion::from_euler_angles(0.02, -0.01, 1.0);
        let recorded = |level: bool, sigma_deg: f64| {
            let config = OptimiserConfig { gravity_sigma_deg: sigma_deg, ..OptimiserConfig::default() };
            let mut optimiser = Optimiser::new(RobotId(0), config).with_level_anchors(level);
            for k in 0..3 {
                let keyframe = keyframe(k, f64::from(k));
                optimiser.add_keyframe(&NewKeyframe {
                    keyframe,
                    edges: Vec::new(),
                    odom_from_body_rotation: tilted,
                    measured_up: None,
                });
            }
            optimiser.freeze().tilts
        };
        let tilts = recorded(true, 0.2);
        assert_eq!(tilts.iter().map(|(k, _)| k.0).collect::<Vec<_>>(), vec![0, 1, 2]);
        assert!((tilts[0].1 - tilted.inverse() * nalgebra::Vector3::z()).norm() < 1e-15);
        assert!(recorded(false, 0.2).is_empty());
        assert_eq!(recorded(true, 0.0), tilts);
        // An attitude that is not a rotation: no tilt, and the status counts it.
        let mut optimiser = Optimiser::new(RobotId(0), OptimiserConfig::default()).with_level_anchors(true);
        let not_a_rotation =
            nalgebra::UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(f64::NAN, 0.0, 0.0, 0.0));
        let keyframe = keyframe(0, 0.0);
        optimiser.add_keyframe(&NewKeyframe {
            keyframe,
            edges: Vec::new(),
            odom_from_body_rotation: not_a_rotation,
            measured_up: None,
        });
        assert!(optimiser.freeze().tilts.is_empty());
        assert_eq!(optimiser.failures.refused_attitudes, 1);
    }
}
