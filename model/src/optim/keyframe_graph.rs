//! A robot's pose graph over keyframes, as plain state (paper §III, §IV-E): local keyframes with
//! odometry and intra-robot loop factors, neighbour keyframes as variables with priors from
//! their marginal covariances (expressed in our world through `local_from_remote`), and
//! inter-robot factors — solved by Levenberg–Marquardt ([`super::solver`]). The Optimiser actor
//! owns one and publishes what [`KeyframeGraph::solve`] returns.
//!
//! A neighbour keyframe j with pose T_r(j) in the neighbour's world and covariance Σ_j enters
//! at T = local_from_remote · T_r(j) with the prior N(T, Σ_j): with right perturbations,
//! T · Exp(δ), the covariance is unchanged by the left product.
//!
//! With outlier rejection each solve is GNC-TLS over the loop and inter-robot factors
//! ([`super::robust::optimize_gnc_incremental_with`]): the previous decision is kept while it
//! still holds, and made again from scratch when it does not. Rejected factors stay in the
//! graph with weight 0 and add no information to the marginals.

use super::factors::{Between, Prior};
use super::graph::{Graph3, GTSAM_PRIOR_SIGMAS_3D};
use super::marginals::marginal_covariances_with;
use super::robust::{optimize_gnc_incremental_with, rejection_weights, weighted};
use super::solver::{least_squares, optimize_with, LmParams, SolveError, Structure};
use crate::geometry::Pose3;
use crate::scene_graph::{Keyframe, KeyframeEdge, KeyframeEdgeKind, KeyframeId, KeyframeRef, RobotId};
use nalgebra::Matrix6;
use std::collections::BTreeMap;

/// The graph and its outlier decisions, as a snapshot keeps them.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct KeyframeGraphState {
    pub graph: Graph3,
    pub index: Vec<(KeyframeRef, usize)>,
    /// Keyframes added since the last solve.
    pub pending: usize,
    pub candidates: Vec<bool>,
    pub rejected: Vec<usize>,
}

/// What a solve gives: every local keyframe's pose, the newest ones' marginal covariances, and
/// whether the set of rejected factors changed.
#[derive(Clone, Debug, PartialEq)]
pub struct Solved {
    pub poses: Vec<(KeyframeId, Pose3)>,
    pub covariances: Vec<(KeyframeId, Matrix6<f64>)>,
    pub rejection_changed: bool,
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

impl KeyframeGraph {
    pub fn freeze(&self) -> KeyframeGraphState {
        KeyframeGraphState {
            graph: self.graph.clone(),
            index: self.index.iter().map(|(r, i)| (*r, *i)).collect(),
            pending: self.pending,
            candidates: self.candidates.clone(),
            rejected: self.rejected.clone(),
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
            && state.rejected.iter().all(|k| *k < state.candidates.len());
        consistent.then(|| Self {
            graph: state.graph,
            index: state.index.into_iter().collect(),
            pending: state.pending,
            candidates: state.candidates,
            rejected: state.rejected,
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
    }

    /// Adds a local keyframe (the first is anchored by GTSAM's default prior) and its edges.
    /// Whether to solve now: after a loop closure at once, else every `every_keyframes`.
    pub fn add_keyframe(&mut self, keyframe: &Keyframe, edges: &[KeyframeEdge], every_keyframes: usize) -> bool {
        let first = self.index.is_empty();
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
    /// held keeps its variable and prior) and the inter-robot factors (local keyframe, its
    /// keyframe, measured local_from_neighbour-keyframe pose, information).
    pub fn add_neighbour(
        &mut self,
        robot: RobotId,
        local_from_remote: &Pose3,
        keyframes: &[(KeyframeId, Pose3, Matrix6<f64>)],
        factors: &[(KeyframeId, KeyframeId, Pose3, Matrix6<f64>)],
    ) {
        for (keyframe, pose_in_remote, covariance) in keyframes {
            let r = KeyframeRef::Remote { robot, keyframe: *keyframe };
            let fresh = !self.index.contains_key(&r);
            let mean = local_from_remote * pose_in_remote;
            let i = self.variable(r, mean);
            if fresh {
                if let Some(prior) = Prior::from_covariance(i, mean, covariance) {
                    self.graph.priors.push(prior);
                }
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

    /// Solves (GNC-TLS over the candidate factors with `reject_outliers`, else least squares),
    /// then computes the marginal covariances of the newest `marginals` local keyframes. One
    /// symbolic factorisation serves both (`cargo bench -p sgm-model --bench optimiser_cycle`).
    /// On an error the graph keeps its previous decision.
    pub fn solve(&mut self, reject_outliers: bool, marginals: usize) -> Result<Solved, SolveError> {
        let structure = Structure::new(&self.graph)?;
        let params = LmParams::default();
        let rejected = if reject_outliers {
            optimize_gnc_incremental_with(&mut self.graph, &params, &structure, &self.candidates, &self.rejected)
                .map(|(_, r)| r)?
        } else {
            optimize_with(&mut self.graph, &params, &structure, &least_squares).map(|_| Vec::new())?
        };
        let rejection_changed = rejected != self.rejected;
        self.rejected = rejected;
        let weights = rejection_weights(self.graph.betweens.len(), &self.rejected);
        let local: Vec<(KeyframeId, usize)> = self
            .index
            .iter()
            .filter_map(|(r, i)| if let KeyframeRef::Local(k) = r { Some((*k, *i)) } else { None })
            .collect();
        let poses: Vec<(KeyframeId, Pose3)> = local.iter().map(|(k, i)| (*k, self.graph.values[*i])).collect();
        let latest: Vec<(KeyframeId, usize)> = local.iter().rev().take(marginals).copied().collect();
        let variables: Vec<usize> = latest.iter().map(|(_, i)| *i).collect();
        let covariances = marginal_covariances_with(&self.graph, &structure, &variables, &weighted(&weights))
            .map(|c| latest.iter().map(|(k, _)| *k).zip(c).collect())
            .unwrap_or_default();
        Ok(Solved { poses, covariances, rejection_changed })
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
        KeyframeGraphStatus {
            variables: self.graph.values.len(),
            between_factors: self.graph.betweens.len(),
            candidate_factors: self.candidates.iter().filter(|c| **c).count(),
            rejected_factors: self.rejected.len(),
            rejected_inter_robot,
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
}
