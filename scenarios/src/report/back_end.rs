//! The robust back end at the end of a run: how many loop closures and inter-robot factors the
//! robots' Optimisers hold and reject, and how many of the false factors injected
//! (`[[false_factors]]`) are among the rejected.

use crate::record::RunRecord;
use serde::Serialize;
use sgm_model::scene_graph::KeyframeId;
use sgm_model::scene_graph::RobotId;
use std::collections::BTreeMap;

/// A factor's ends: robot index, neighbour, its keyframe, the neighbour's keyframe.
type Ends = (usize, RobotId, KeyframeId, KeyframeId);

#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct BackEndReport {
    /// Loop closures and inter-robot factors in every robot's pose graph.
    pub candidate_factors: usize,
    /// Of those, rejected as outliers by the last solve.
    pub rejected_factors: usize,
    /// False inter-robot factors injected.
    pub false_factors_injected: usize,
    /// Of those, rejected.
    pub false_factors_rejected: usize,
    /// Solves of a pose graph that failed, over all robots (the map kept its poses).
    pub failed_solves: u64,
    /// Solves of a robot's own poses (`comms.pose_updates.own_estimates`) that failed, over all
    /// robots (neighbours were told the joint poses).
    pub failed_own_solves: u64,
}

pub fn compute(record: &RunRecord) -> BackEndReport {
    let mut report = BackEndReport { false_factors_injected: record.false_factors.len(), ..Default::default() };
    // Factors are told apart by their ends, counted with multiplicity: two false factors may
    // tie the same keyframes, and only as many of them count as rejected as the Optimiser
    // rejected with those ends.
    let mut rejected: BTreeMap<Ends, usize> = BTreeMap::new();
    for (k, status) in record.optimisers.iter().enumerate() {
        let Some(status) = status else { continue };
        report.candidate_factors += status.graph.candidate_factors;
        report.rejected_factors += status.graph.rejected_factors;
        report.failed_solves += status.failures.failed_solves;
        report.failed_own_solves += status.failures.failed_own_solves;
        for (robot, local, remote) in &status.graph.rejected_inter_robot {
            *rejected.entry((k, *robot, *local, *remote)).or_default() += 1;
        }
    }
    let mut injected: BTreeMap<Ends, usize> = BTreeMap::new();
    for f in &record.false_factors {
        *injected.entry((f.robot, RobotId::from_index(f.neighbour), f.local, f.remote)).or_default() += 1;
    }
    report.false_factors_rejected =
        injected.iter().map(|(ends, n)| (*n).min(rejected.get(ends).copied().unwrap_or(0))).sum();
    report
}
