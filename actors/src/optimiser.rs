//! `Optimiser` (paper §III, §IV-E): the robot's pose graph — local keyframes with odometry and
//! intra-robot loop factors, neighbour keyframes as variables with priors from their marginal
//! covariances (expressed in our world through `local_from_remote`), and inter-robot factors
//! from ICP — solved by Levenberg–Marquardt on faer (`model::optim`). Publishes optimised poses
//! and marginal covariances to the Tracker and Matcher.
//!
//! A wrong loop closure or inter-robot factor (a false match that passed every check) would
//! bend the whole trajectory toward it. With `reject_outliers`, each solve is GNC-TLS over those
//! factors (`robust::optimize_gnc_incremental`): the previous decision is kept while it still
//! holds — one solve — and made again from scratch when it does not. Rejected factors stay in
//! the graph with weight 0 (a later solve may take them back) and add no information to the
//! marginals.

use crate::config::OptimiserConfig;
use crate::containment::contained;
use crate::messages::*;
use actix::{Actor, Context, Handler, Recipient, Supervised};
use nalgebra::Matrix6;
use sgm_model::geometry::Pose3;
use sgm_model::optim::factors::{Between, Prior};
use sgm_model::optim::graph::{Graph3, GTSAM_PRIOR_SIGMAS_3D};
use sgm_model::optim::marginals::marginal_covariances_with;
use sgm_model::optim::robust::{optimize_gnc_incremental_with, rejection_weights, weighted};
use sgm_model::optim::solver::{least_squares, optimize_with, LmParams, SolveError, Structure};
use sgm_model::scene_graph::{KeyframeEdge, KeyframeEdgeKind, KeyframeId, KeyframeRef, RobotId};
use std::collections::BTreeMap;

/// Where optimised poses go.
#[derive(Clone)]
pub struct OptimiserLinks {
    pub tracker: Recipient<PosesOptimised>,
    pub matcher: Recipient<PosesOptimised>,
}

/// Most keyframes whose marginal covariance is computed after each optimisation (the latest).
const MARGINALS: usize = 200;

pub struct Optimiser {
    robot: RobotId,
    config: OptimiserConfig,
    links: Option<OptimiserLinks>,
    graph: Graph3,
    index: BTreeMap<KeyframeRef, usize>,
    pending: usize,
    /// Per between factor of `graph`: whether robust estimation may reject it (not odometry).
    candidates: Vec<bool>,
    /// The between factors the last solve rejected.
    rejected: Vec<usize>,
}

/// What of the Optimiser a snapshot keeps: the whole pose graph and its outlier decisions.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OptimiserState {
    pub graph: Graph3,
    pub index: Vec<(KeyframeRef, usize)>,
    pub pending: usize,
    pub candidates: Vec<bool>,
    pub rejected: Vec<usize>,
}

/// The Optimiser's pose graph at a glance.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct OptimiserStatus {
    pub variables: usize,
    pub between_factors: usize,
    /// Loop closures and inter-robot factors.
    pub candidate_factors: usize,
    /// Of those, rejected by the last solve.
    pub rejected_factors: usize,
    /// Rejected inter-robot factors: (neighbour, local keyframe, neighbour keyframe).
    pub rejected_inter_robot: Vec<(RobotId, KeyframeId, KeyframeId)>,
}

/// Runner / operator → Optimiser: what the pose graph holds.
#[derive(actix::Message)]
#[rtype(result = "OptimiserStatus")]
pub struct GetOptimiserStatus;

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

impl Optimiser {
    pub fn new(robot: RobotId, config: OptimiserConfig) -> Self {
        Self {
            robot,
            config,
            links: None,
            graph: Graph3::default(),
            index: BTreeMap::new(),
            pending: 0,
            candidates: Vec::new(),
            rejected: Vec::new(),
        }
    }

    pub fn freeze(&self) -> OptimiserState {
        OptimiserState {
            graph: self.graph.clone(),
            index: self.index.iter().map(|(r, i)| (*r, *i)).collect(),
            pending: self.pending,
            candidates: self.candidates.clone(),
            rejected: self.rejected.clone(),
        }
    }

    /// Continues from `state`. An index that does not fit the graph (a snapshot from another
    /// build would have failed its checksum or decode first) leaves the optimiser empty.
    pub fn thawed(mut self, state: OptimiserState) -> Self {
        let n = state.graph.values.len();
        let consistent = state.graph.keys.len() == n
            && state.graph.fixed.len() == n
            && state.index.iter().all(|(_, i)| *i < n)
            && state.graph.betweens.iter().all(|b| b.from < n && b.to < n)
            && state.graph.priors.iter().all(|p| p.variable < n)
            && state.candidates.len() == state.graph.betweens.len()
            && state.rejected.iter().all(|k| *k < state.candidates.len());
        if consistent {
            self.graph = state.graph;
            self.index = state.index.into_iter().collect();
            self.pending = state.pending;
            self.candidates = state.candidates;
            self.rejected = state.rejected;
        } else {
            tracing::error!(robot = %self.robot, "snapshot pose graph is inconsistent: starting the optimiser empty");
        }
        self
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

    fn add_edge(&mut self, edge: &KeyframeEdge) {
        let (Some(&from), Some(&to)) = (self.index.get(&KeyframeRef::Local(edge.from)), self.index.get(&edge.to))
        else {
            return;
        };
        let Some(s) = sqrt_information(&edge.information) else { return };
        self.graph.betweens.push(Between { from, to, measured: edge.from_from_to, sqrt_information: s });
        self.candidates.push(edge.kind != KeyframeEdgeKind::Odometry);
    }

    /// Solves the graph on `structure` (built for it); returns the between factors rejected as
    /// outliers.
    fn solve(&mut self, structure: &Structure<6>) -> Result<Vec<usize>, SolveError> {
        let params = LmParams::default();
        if self.config.reject_outliers {
            optimize_gnc_incremental_with(&mut self.graph, &params, structure, &self.candidates, &self.rejected)
                .map(|(_, r)| r)
        } else {
            optimize_with(&mut self.graph, &params, structure, &least_squares).map(|_| Vec::new())
        }
    }

    /// Solves, then publishes the poses and the newest keyframes' marginal covariances. One
    /// symbolic factorisation serves both (`cargo bench -p sgm-model --bench optimiser_cycle`).
    fn solve_and_publish(&mut self) {
        let solved = Structure::new(&self.graph).and_then(|s| Ok((self.solve(&s)?, s)));
        let (rejected, structure) = match solved {
            Ok(solved) => solved,
            Err(e) => {
                tracing::warn!(robot = %self.robot, "pose graph not optimised: {e}");
                return;
            }
        };
        if rejected != self.rejected {
            tracing::info!(robot = %self.robot, rejected = rejected.len(), candidates = self.candidates.iter().filter(|c| **c).count(), "outlier factors");
        }
        self.rejected = rejected;
        let weights = rejection_weights(self.graph.betweens.len(), &self.rejected);
        let local: Vec<(KeyframeId, usize)> = self
            .index
            .iter()
            .filter_map(|(r, i)| if let KeyframeRef::Local(k) = r { Some((*k, *i)) } else { None })
            .collect();
        let poses: Vec<(KeyframeId, Pose3)> = local.iter().map(|(k, i)| (*k, self.graph.values[*i])).collect();
        let latest: Vec<(KeyframeId, usize)> = local.iter().rev().take(MARGINALS).copied().collect();
        let variables: Vec<usize> = latest.iter().map(|(_, i)| *i).collect();
        let covariances = marginal_covariances_with(&self.graph, &structure, &variables, &weighted(&weights))
            .map(|c| latest.iter().map(|(k, _)| *k).zip(c).collect())
            .unwrap_or_default();
        if let Some(links) = &self.links {
            let message = PosesOptimised { poses, covariances };
            links.tracker.do_send(message.clone());
            links.matcher.do_send(message);
        }
    }
}

impl Actor for Optimiser {
    type Context = Context<Self>;
}

impl Supervised for Optimiser {
    fn restarting(&mut self, _: &mut Context<Self>) {
        tracing::warn!(robot = %self.robot, variables = self.graph.values.len(), "optimiser restarting with its graph");
    }
}

impl Handler<NewKeyframe> for Optimiser {
    type Result = ();
    fn handle(&mut self, msg: NewKeyframe, ctx: &mut Context<Self>) {
        contained(ctx, "optimiser", || {
            let first = self.index.is_empty();
            let i = self.variable(KeyframeRef::Local(msg.keyframe.id), msg.keyframe.world_from_body);
            if first {
                self.graph.add_prior_at_current(i, GTSAM_PRIOR_SIGMAS_3D);
            }
            for edge in &msg.edges {
                self.add_edge(edge);
            }
            self.pending += 1;
            // A loop closure's correction is worth a solve at once.
            let has_loop = msg.edges.iter().any(|e| e.kind == KeyframeEdgeKind::Loop);
            if has_loop || self.pending >= self.config.every_keyframes {
                self.pending = 0;
                self.solve_and_publish();
            }
        });
    }
}

impl Handler<InterRobotConstraints> for Optimiser {
    type Result = ();
    fn handle(&mut self, msg: InterRobotConstraints, ctx: &mut Context<Self>) {
        contained(ctx, "optimiser", || {
            for (keyframe, pose_in_remote, covariance) in &msg.neighbour_keyframes {
                let r = KeyframeRef::Remote { robot: msg.robot, keyframe: *keyframe };
                let fresh = !self.index.contains_key(&r);
                let mean = msg.local_from_remote * pose_in_remote;
                let i = self.variable(r, mean);
                // Right-perturbation covariance is unchanged by the left product with local_from_remote.
                if fresh {
                    if let Some(prior) = Prior::from_covariance(i, mean, covariance) {
                        self.graph.priors.push(prior);
                    }
                }
            }
            for (local, remote, measured, information) in &msg.factors {
                let edge = KeyframeEdge {
                    kind: KeyframeEdgeKind::InterRobot,
                    from: *local,
                    to: KeyframeRef::Remote { robot: msg.robot, keyframe: *remote },
                    from_from_to: *measured,
                    information: *information,
                };
                self.add_edge(&edge);
            }
            self.solve_and_publish();
        });
    }
}

impl Handler<GetOptimiserStatus> for Optimiser {
    type Result = actix::MessageResult<GetOptimiserStatus>;
    fn handle(&mut self, _: GetOptimiserStatus, _: &mut Context<Self>) -> Self::Result {
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
        actix::MessageResult(OptimiserStatus {
            variables: self.graph.values.len(),
            between_factors: self.graph.betweens.len(),
            candidate_factors: self.candidates.iter().filter(|c| **c).count(),
            rejected_factors: self.rejected.len(),
            rejected_inter_robot,
        })
    }
}

connects!(Optimiser => OptimiserLinks);
freezes!(Optimiser => OptimiserState);
stops_on_injected_failure!(Optimiser => "optimiser");
