//! The neighbours this robot holds suspect (`sgm_model::matching::suspect`), judged at each
//! status from the Matcher's and the Optimiser's counts: in the status JSON
//! (`neighbours[].suspect`), and in the log when the kinds of a neighbour's findings change.

use sgm_actors::matcher::NeighbourStatus;
use sgm_model::matching::suspect::{findings, Finding};
use sgm_model::optim::keyframe_graph::KeyframeGraphStatus;
use sgm_model::scene_graph::RobotId;
use std::collections::BTreeMap;

/// The findings last logged, per neighbour.
#[derive(Default)]
pub(super) struct Suspects {
    logged: BTreeMap<RobotId, Vec<Finding>>,
}

impl Suspects {
    /// Each neighbour's findings now, one line each (empty: nothing stands out); a warning when
    /// a neighbour's kinds of finding change to some (not at each new count), a note when they
    /// clear.
    pub(super) fn judge(
        &mut self,
        robot: &str,
        neighbours: &[NeighbourStatus],
        graph: &KeyframeGraphStatus,
    ) -> BTreeMap<RobotId, Vec<String>> {
        let mut now = BTreeMap::new();
        for n in neighbours {
            let found = findings(&n.suspect_evidence(graph.inter_robot.iter().find(|c| c.robot == n.robot)));
            let before = self.logged.get(&n.robot).map_or(&[][..], |v| &v[..]);
            let same = found.len() == before.len() && found.iter().zip(before).all(|(a, b)| a.same_kind(b));
            if !same {
                if found.is_empty() {
                    tracing::info!(robot, neighbour = %n.robot, "the neighbour is no longer held suspect");
                } else {
                    let why = found.iter().map(ToString::to_string).collect::<Vec<_>>().join("; ");
                    tracing::warn!(robot, neighbour = %n.robot, %why, "the neighbour is held suspect");
                }
                self.logged.insert(n.robot, found.clone());
            }
            now.insert(n.robot, found.iter().map(ToString::to_string).collect());
        }
        now
    }
}
