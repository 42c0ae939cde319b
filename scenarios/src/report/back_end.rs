//! The robust back end at the end of a run: how many loop closures and inter-robot factors the
//! robots' Optimisers hold and reject, and how many of the false factors injected
//! (`[[false_factors]]`) are among the rejected.

use crate::record::RunRecord;
use serde::Serialize;
use sgm_model::scene_graph::RobotId;
use std::collections::BTreeSet;

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
}

pub fn compute(record: &RunRecord) -> BackEndReport {
    let mut report = BackEndReport { false_factors_injected: record.false_factors.len(), ..Default::default() };
    let mut rejected = BTreeSet::new();
    for (k, status) in record.optimisers.iter().enumerate() {
        let Some(status) = status else { continue };
        report.candidate_factors += status.candidate_factors;
        report.rejected_factors += status.rejected_factors;
        rejected.extend(status.rejected_inter_robot.iter().map(|(robot, local, remote)| (k, *robot, *local, *remote)));
    }
    report.false_factors_rejected = record
        .false_factors
        .iter()
        .filter(|f| rejected.contains(&(f.robot, RobotId::from_index(f.neighbour), f.local, f.remote)))
        .count();
    report
}
