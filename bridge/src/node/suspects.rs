//! The neighbours this robot holds suspect (`sgm_model::matching::suspect`), judged at each
//! status from the Matcher's and the Optimiser's counts: in the status JSON
//! (`neighbours[].suspect`), and in the log when a neighbour's findings change.

use sgm_actors::matcher::NeighbourStatus;
use sgm_model::matching::suspect::{suspicions, Evidence};
use sgm_model::optim::keyframe_graph::KeyframeGraphStatus;
use sgm_model::scene_graph::RobotId;
use std::collections::BTreeMap;

/// The findings last logged, per neighbour.
#[derive(Default)]
pub(super) struct Suspects {
    logged: BTreeMap<RobotId, Vec<String>>,
}

impl Suspects {
    /// Each neighbour's findings now (empty: nothing stands out); a warning when a neighbour's
    /// findings change to some, a note when they clear.
    pub(super) fn judge(
        &mut self,
        robot: &str,
        neighbours: &[NeighbourStatus],
        graph: &KeyframeGraphStatus,
    ) -> BTreeMap<RobotId, Vec<String>> {
        let mut now = BTreeMap::new();
        for n in neighbours {
            let held = graph.inter_robot.iter().find(|c| c.robot == n.robot);
            let evidence = Evidence {
                factors: held.map_or(0, |h| h.factors),
                inconsistent: held.map_or(0, |h| h.inconsistent),
                rounds_refuted: n.match_attempts.rounds_refuted,
            };
            let found = suspicions(&evidence);
            let before = self.logged.get(&n.robot).map_or(&[][..], |v| &v[..]);
            if found != before {
                if found.is_empty() {
                    tracing::info!(robot, neighbour = %n.robot, "the neighbour is no longer held suspect");
                } else {
                    tracing::warn!(robot, neighbour = %n.robot, why = %found.join("; "), "the neighbour is held suspect");
                }
                self.logged.insert(n.robot, found.clone());
            }
            now.insert(n.robot, found);
        }
        now
    }
}
