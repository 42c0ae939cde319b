//! Keyframes we served, told again when our solves move them (`[comms.pose_updates]`), as plain
//! state.
//!
//! A neighbour holding one of our keyframes ties it to its anchor of our map by the pose we sent
//! with it (`model::optim::keyframe_graph`: e_j = Log(T_r(j)⁻¹ · A_r⁻¹ · X_j)). Our later solves
//! (a loop closure, an alignment) move the keyframe in our world; the neighbour's T_r(j) stays
//! where it was, and its inter-robot factors on the keyframe then pull its anchor by our
//! correction. So we remember, per neighbour, the pose each keyframe was last told at, and when
//! our estimate has moved farther than `move_m` or turned more than `turn_deg` from it,
//! the keyframe's new pose goes out in a `KeyframePoses` message — at most once per
//! `interval_s` per neighbour, only to a neighbour heard within `link_timeout_s` (and not
//! down), in envelopes of at most
//! `limits.max_ids` poses. Our estimate is the map's (the joint solve's), or with `own_estimates`
//! what our own measurements alone say of the keyframe (`MapView::told`: a solve of our graph
//! without the neighbours, `KeyframeGraph::own_poses`): the joint one holds the neighbour's own
//! keyframes and factors, and telling it back counts the neighbour's information twice, round
//! after round. A keyframe
//! whose scan our map evicted is no longer in the map view:
//! it is forgotten, and never told again (so what is remembered is bounded by the map's cloud
//! budget per neighbour). A neighbour that restarted (a new incarnation) is told every served
//! keyframe at its next update. An update lost on the radio is made good only when the keyframe next
//! moves beyond the thresholds from the pose it carried.

use crate::config::PoseUpdatesConfig;
use crate::map_view::MapView;
use sgm_model::geometry::Pose3;
use sgm_model::scene_graph::{KeyframeId, RobotId, Stamp};
use sgm_model::wire::messages::{KeyframePoses, WireKeyframePose};
use std::collections::{BTreeMap, BTreeSet};

/// Per neighbour, each keyframe we served and the pose it was last told.
pub type Told = BTreeMap<RobotId, BTreeMap<KeyframeId, Pose3>>;

#[derive(Clone, Debug, Default)]
pub struct ServedPoses {
    told: Told,
    /// When each neighbour was last sent an update.
    last: BTreeMap<RobotId, Stamp>,
    /// Neighbours to be told every served keyframe's pose at their next update, whatever it
    /// was told before (restarted: they may hold older priors than we told them).
    retell: BTreeSet<RobotId>,
}

impl ServedPoses {
    /// Restored from a snapshot: what each neighbour was told.
    pub fn with_told(told: Told) -> Self {
        Self { told, ..Self::default() }
    }

    pub fn told(&self) -> &Told {
        &self.told
    }

    /// A keyframe response left for `to` with `world_from_body`. A keyframe served before keeps
    /// what it was told (the neighbour may keep its earlier prior, see
    /// `KeyframeGraph::add_neighbour`): the next update tells any difference.
    pub fn served(&mut self, to: RobotId, keyframe: KeyframeId, world_from_body: Pose3) {
        self.told.entry(to).or_default().entry(keyframe).or_insert(world_from_body);
    }

    /// `robot` restarted (a new incarnation): from a snapshot older than what we told it, maybe.
    /// Its next update tells every served keyframe still in our map.
    pub fn retell(&mut self, robot: RobotId) {
        if self.told.contains_key(&robot) {
            self.retell.insert(robot);
        }
    }

    /// The updates due at `now` against `view` (our map's latest estimates), per neighbour
    /// whose interval has passed and that is heard (`up`), each split into messages of at
    /// most `max_per_message` poses. What goes out counts as told.
    pub fn due(
        &mut self,
        now: Stamp,
        view: &MapView,
        config: &PoseUpdatesConfig,
        max_per_message: usize,
        up: impl Fn(RobotId) -> bool,
    ) -> Vec<(RobotId, Vec<KeyframePoses>)> {
        if !config.enabled {
            return Vec::new();
        }
        let turn_rad = config.turn_deg.to_radians();
        let mut out = Vec::new();
        for (&robot, told) in &mut self.told {
            let waited = self.last.get(&robot).is_none_or(|&t| now - t >= config.interval_s);
            if !waited || !up(robot) {
                continue;
            }
            // A keyframe whose scan the map evicted never comes back to the view: forgotten.
            told.retain(|id, _| view.keyframes.contains_key(id));
            let all = self.retell.remove(&robot);
            let mut moved = Vec::new();
            for (&id, pose) in told.iter_mut() {
                let Some(kf) = view.keyframes.get(&id) else { continue };
                // Our own measurements' estimate with `own_estimates` (module doc); else the map's.
                let now_pose = view.told.get(&id).copied().unwrap_or(kf.world_from_body);
                let shift = (now_pose.translation.vector - pose.translation.vector).norm();
                let turn = (pose.rotation.inverse() * now_pose.rotation).angle();
                if all || shift > config.move_m || turn > turn_rad {
                    *pose = now_pose;
                    moved.push(WireKeyframePose::new(id, &now_pose));
                }
            }
            if moved.is_empty() {
                continue;
            }
            self.last.insert(robot, now);
            let messages = moved.chunks(max_per_message.max(1)).map(|c| KeyframePoses { poses: c.to_vec() }).collect();
            out.push((robot, messages));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map_view::ViewKeyframe;
    use nalgebra::Vector3;
    use sgm_model::geometry::pose_from_rpy_translation;
    use sgm_model::scene_graph::SemanticScan;
    use std::sync::Arc;

    fn view(poses: &[(u32, Pose3)]) -> MapView {
        let scan = Arc::new(SemanticScan::default());
        let keyframes = poses
            .iter()
            .map(|(id, p)| (KeyframeId(*id), ViewKeyframe { world_from_body: *p, scan: scan.clone() }))
            .collect();
        MapView { keyframes, ..MapView::default() }
    }

    fn at(x: f64, yaw_deg: f64) -> Pose3 {
        pose_from_rpy_translation(0.0, 0.0, yaw_deg.to_radians(), Vector3::new(x, 0.0, 0.0))
    }

    /// The updates due at `now` with the default configuration, every neighbour heard.
    fn tell(s: &mut ServedPoses, now: f64, view: &MapView) -> Vec<(u16, Vec<u32>)> {
        told(&s.due(now, view, &PoseUpdatesConfig::default(), 256, |_| true))
    }

    fn told(out: &[(RobotId, Vec<KeyframePoses>)]) -> Vec<(u16, Vec<u32>)> {
        out.iter().map(|(r, m)| (r.0, m.iter().flat_map(|m| m.poses.iter().map(|p| p.keyframe.0)).collect())).collect()
    }

    #[test]
    fn keyframes_that_moved_beyond_a_threshold_are_told_again_at_most_once_per_interval() {
        let config = PoseUpdatesConfig::default();
        let mut s = ServedPoses::default();
        s.served(RobotId(2), KeyframeId(1), at(0.0, 0.0));
        s.served(RobotId(2), KeyframeId(2), at(5.0, 0.0));
        s.served(RobotId(3), KeyframeId(1), at(0.0, 0.0));
        // Within both thresholds: nothing.
        let small = view(&[(1, at(0.04, 0.09)), (2, at(5.0, 0.0))]);
        assert!(tell(&mut s, 0.0, &small).is_empty());
        // Keyframe 1 moved 6 cm: both neighbours that hold it are told, keyframe 2 is not.
        let moved = view(&[(1, at(0.06, 0.0)), (2, at(5.0, 0.0))]);
        let out = s.due(1.0, &moved, &config, 256, |_| true);
        assert_eq!(told(&out), [(2, vec![1]), (3, vec![1])]);
        let pose = out[0].1[0].poses[0].to_pose().unwrap();
        assert!((pose.translation.x - 0.06).abs() < 1e-6);
        // Keyframe 2 turns 0.2°: not before the interval has passed, then told.
        let turned = view(&[(1, at(0.06, 0.0)), (2, at(5.0, 0.2))]);
        assert!(tell(&mut s, 5.0, &turned).is_empty());
        assert_eq!(tell(&mut s, 11.0, &turned), [(2, vec![2])]);
        // What was told is the reference now: no repeat.
        assert!(tell(&mut s, 30.0, &turned).is_empty());
    }

    #[test]
    fn each_neighbour_has_its_own_interval_and_a_threshold_is_exceeded_not_met() {
        let mut s = ServedPoses::default();
        s.served(RobotId(2), KeyframeId(1), at(0.0, 0.0));
        let first = view(&[(1, at(0.1, 0.0))]);
        assert_eq!(tell(&mut s, 0.0, &first), [(2, vec![1])]);
        // Robot 3 is served keyframe 1 later, at its old pose: told at once, robot 2's interval
        // notwithstanding; robot 2 waits.
        s.served(RobotId(3), KeyframeId(1), at(0.0, 0.0));
        let second = view(&[(1, at(0.2, 0.0))]);
        assert_eq!(tell(&mut s, 1.0, &second), [(3, vec![1])]);
        assert_eq!(tell(&mut s, 10.0, &second), [(2, vec![1])]);
        // Exactly at the thresholds is not beyond them.
        let mut s = ServedPoses::default();
        s.served(RobotId(2), KeyframeId(1), at(0.0, 0.0));
        s.served(RobotId(2), KeyframeId(2), at(10.0, 0.0));
        let edge = view(&[(1, at(0.05, 0.0)), (2, at(10.0, 0.1))]);
        assert!(tell(&mut s, 0.0, &edge).is_empty());
    }

    #[test]
    fn evicted_keyframes_are_forgotten_a_resent_one_keeps_what_was_told_and_a_restart_hears_all() {
        let mut s = ServedPoses::default();
        s.served(RobotId(2), KeyframeId(1), at(0.0, 0.0));
        s.served(RobotId(2), KeyframeId(2), at(5.0, 0.0));
        // Keyframe 2's scan was evicted: it leaves the view and what was told of it is dropped.
        assert!(tell(&mut s, 0.0, &view(&[(1, at(0.0, 0.0))])).is_empty());
        assert_eq!(s.told()[&RobotId(2)].keys().copied().collect::<Vec<_>>(), [KeyframeId(1)]);
        // Served again at a new pose: the neighbour may keep its earlier prior, so the update
        // compares with what it was told first.
        s.served(RobotId(2), KeyframeId(1), at(1.0, 0.0));
        let moved = view(&[(1, at(1.0, 0.0))]);
        assert_eq!(tell(&mut s, 10.0, &moved), [(2, vec![1])]);
        // Restarted: told again though nothing moved; a neighbour never served is not.
        s.retell(RobotId(2));
        s.retell(RobotId(5));
        assert_eq!(tell(&mut s, 20.0, &moved), [(2, vec![1])]);
        assert!(tell(&mut s, 30.0, &moved).is_empty());
    }

    #[test]
    fn a_neighbour_whose_link_is_down_waits_and_messages_hold_at_most_the_limit() {
        let config = PoseUpdatesConfig::default();
        let mut s = ServedPoses::default();
        for id in 0..5 {
            s.served(RobotId(2), KeyframeId(id), at(f64::from(id), 0.0));
        }
        let moved = view(&(0..5).map(|id| (id, at(f64::from(id) + 1.0, 0.0))).collect::<Vec<_>>());
        assert!(s.due(0.0, &moved, &config, 2, |_| false).is_empty(), "link down");
        let out = s.due(1.0, &moved, &config, 2, |_| true);
        assert_eq!(out[0].1.iter().map(|m| m.poses.len()).collect::<Vec<_>>(), [2, 2, 1]);
        // An evicted keyframe (absent from the view) is not told; disabled tells nothing.
        let mut s = ServedPoses::default();
        s.served(RobotId(2), KeyframeId(9), at(0.0, 0.0));
        assert!(s.due(0.0, &moved, &config, 2, |_| true).is_empty());
        s.served(RobotId(2), KeyframeId(1), at(0.0, 0.0));
        let off = PoseUpdatesConfig { enabled: false, ..config };
        assert!(s.due(0.0, &moved, &off, 2, |_| true).is_empty());
    }

    /// A solve that moved keyframe 1 only because of the neighbour's own factors leaves our own
    /// estimate (`MapView::told`) where it was: nothing is told. When our own estimate moves
    /// (a loop closure of ours), that is what is told, not the joint pose.
    #[test]
    fn what_is_told_is_our_own_estimate_not_the_joint_one() {
        let mut s = ServedPoses::default();
        s.served(RobotId(2), KeyframeId(1), at(0.0, 0.0));
        let mut joint_moved = view(&[(1, at(0.3, 1.0))]);
        joint_moved.told = [(KeyframeId(1), at(0.0, 0.0))].into();
        assert!(tell(&mut s, 0.0, &joint_moved).is_empty(), "the joint solve's move is the neighbour's own");
        let mut own_moved = view(&[(1, at(0.3, 1.0))]);
        own_moved.told = [(KeyframeId(1), at(0.2, 0.0))].into();
        let out = s.due(1.0, &own_moved, &PoseUpdatesConfig::default(), 256, |_| true);
        assert_eq!(told(&out), [(2, vec![1])]);
        let pose = out[0].1[0].poses[0].to_pose().unwrap();
        assert!((pose.translation.x - 0.2).abs() < 1e-6, "{pose:?}");
    }
}
