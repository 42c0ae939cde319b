//! TUM trajectory files (`stamp tx ty tz qx qy qz qw`), for `evo_ape tum TRUTH ESTIMATE -a`:
//! per robot `NAME.tum` (optimised keyframes, the robot's world) and `NAME.truth.tum`; for the
//! team `team.tum` (every merged robot in the reference robot's world) and `team.truth.tum`.
//! evo pairs poses by stamp, so in the team files robot k's stamps are shifted by k × 100 000 s
//! to keep them apart; the ATE is unchanged.

use super::figures::{reference_from, trajectory};
use crate::record::RunRecord;
use sgm_model::geometry::Pose3;
use std::fmt::Write as _;

/// Stamp shift between robots in the team files, s.
pub const TEAM_STAMP_SHIFT_S: f64 = 100_000.0;

/// One TUM line: `stamp tx ty tz qx qy qz qw`.
pub fn line(out: &mut String, stamp: f64, pose: &Pose3) {
    let t = pose.translation.vector;
    let q = pose.rotation.coords; // (i, j, k, w)
    let _ = writeln!(out, "{stamp:.6} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}", t.x, t.y, t.z, q.x, q.y, q.z, q.w);
}

/// (file name, contents) of every TUM file.
pub fn files(record: &RunRecord) -> Vec<(String, String)> {
    let last = &record.last;
    let mut out = Vec::new();
    let (mut team, mut team_truth) = (String::new(), String::new());
    for (k, robot) in record.robots.iter().enumerate() {
        let samples = trajectory(last, k, robot);
        let (mut estimate, mut truth) = (String::new(), String::new());
        for (stamp, e, t) in &samples {
            line(&mut estimate, *stamp, e);
            line(&mut truth, *stamp, t);
        }
        out.push((format!("{}.tum", robot.name), estimate));
        out.push((format!("{}.truth.tum", robot.name), truth));
        if let Some(reference_from_robot) = reference_from(last, k) {
            let shift = k as f64 * TEAM_STAMP_SHIFT_S;
            for (stamp, e, t) in &samples {
                line(&mut team, stamp + shift, &(reference_from_robot * e));
                line(&mut team_truth, stamp + shift, t);
            }
        }
    }
    out.push(("team.tum".into(), team));
    out.push(("team.truth.tum".into(), team_truth));
    out
}
