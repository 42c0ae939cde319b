//! `Optimiser` (paper §III, §IV-E): the robot's pose graph — local keyframes with odometry and
//! intra-robot loop factors, neighbour keyframes as variables with priors from their marginal
//! covariances (expressed in our world through `local_from_remote`), and inter-robot factors
//! from ICP — solved by Levenberg–Marquardt on faer (`model::optim`). Publishes optimised poses
//! and marginal covariances to the Tracker and Matcher.

use crate::config::OptimiserConfig;
use crate::containment::contained;
use crate::messages::*;
use actix::{Actor, Context, Handler, Recipient, Supervised};
use nalgebra::Matrix6;
use sgm_model::geometry::Pose3;
use sgm_model::optim::factors::{Between, Prior};
use sgm_model::optim::graph::{Graph3, GTSAM_PRIOR_SIGMAS_3D};
use sgm_model::optim::marginals::marginal_covariances;
use sgm_model::optim::solver::{optimize, LmParams, Structure};
use sgm_model::scene_graph::{KeyframeEdge, KeyframeId, KeyframeRef, RobotId};
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
}

/// What of the Optimiser a snapshot keeps: the whole pose graph.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OptimiserState {
    pub graph: Graph3,
    pub index: Vec<(KeyframeRef, usize)>,
    pub pending: usize,
}

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
        Self { robot, config, links: None, graph: Graph3::default(), index: BTreeMap::new(), pending: 0 }
    }

    pub fn freeze(&self) -> OptimiserState {
        OptimiserState {
            graph: self.graph.clone(),
            index: self.index.iter().map(|(r, i)| (*r, *i)).collect(),
            pending: self.pending,
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
            && state.graph.priors.iter().all(|p| p.variable < n);
        if consistent {
            self.graph = state.graph;
            self.index = state.index.into_iter().collect();
            self.pending = state.pending;
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
    }

    fn solve_and_publish(&mut self) {
        if let Err(e) = optimize(&mut self.graph, &LmParams::default()) {
            tracing::warn!(robot = %self.robot, "pose graph not optimised: {e}");
            return;
        }
        let local: Vec<(KeyframeId, usize)> = self
            .index
            .iter()
            .filter_map(|(r, i)| if let KeyframeRef::Local(k) = r { Some((*k, *i)) } else { None })
            .collect();
        let poses: Vec<(KeyframeId, Pose3)> = local.iter().map(|(k, i)| (*k, self.graph.values[*i])).collect();
        let latest: Vec<(KeyframeId, usize)> = local.iter().rev().take(MARGINALS).copied().collect();
        let covariances = Structure::new(&self.graph)
            .and_then(|s| marginal_covariances(&self.graph, &s, &latest.iter().map(|(_, i)| *i).collect::<Vec<_>>()))
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
            let has_loop = msg.edges.iter().any(|e| e.kind == sgm_model::scene_graph::KeyframeEdgeKind::Loop);
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
                    kind: sgm_model::scene_graph::KeyframeEdgeKind::InterRobot,
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

connects!(Optimiser => OptimiserLinks);
freezes!(Optimiser => OptimiserState);
stops_on_injected_failure!(Optimiser => "optimiser");
