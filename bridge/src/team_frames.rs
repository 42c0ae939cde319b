//! The team's worlds as one tf tree. Every robot maps in its own world frame (`ros.frames.world`,
//! unique per robot: `{robot}/odom`, or an alias of its odometry's frame). Once robots align,
//! each publishes one transform at most: its world's place in the world of the lowest-id robot it
//! is aligned with, if that robot's id is below its own:
//!
//! ```text
//! parent(r) = min { n aligned with r : id(n) < id(r) }        (none: r is a root)
//! parent_world_from_r_world = local_from_remote(r ← parent)⁻¹
//! ```
//!
//! Every frame gets at most one parent, from one publisher (the robot itself), and parents have
//! lower ids: the team's worlds form a tree, never a loop, and RViz with any robot's world as the
//! fixed frame shows every robot connected to it. A neighbour's world frame is the one it
//! registered on the master (`/sgm/world_frames/robot_{id}`), or the world template with the
//! name `robot_{id}` while it has not.

use crate::config::RosConfig;
use crate::convert::geometry::transform_msg;
use crate::msg::{geometry_msgs, std_msgs};
use sgm_actors::matcher::NeighbourStatus;
use sgm_model::geometry::Pose3;
use sgm_model::scene_graph::RobotId;
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, PoisonError};

/// The master parameter under which robot `id` registers its world frame.
pub fn world_frame_param(id: u16) -> String {
    format!("/sgm/world_frames/robot_{id}")
}

/// The parent of robot `own`'s world and `parent_world_from_own_world`, if it has one.
pub fn team_parent(own: RobotId, neighbours: &[NeighbourStatus]) -> Option<(RobotId, Pose3)> {
    neighbours
        .iter()
        .filter(|n| n.robot < own)
        .filter_map(|n| Some((n.robot, n.local_from_remote?.inverse())))
        .min_by_key(|(robot, _)| *robot)
}

/// The one transform robot `own` publishes for the team's tree (`header` stamps it and names
/// `own`'s world frame): its parent's world → its own. None for a root, or when the parent's
/// world has the same name (a world frame without `{robot}`: it would be a loop).
pub fn team_transform(
    header: &std_msgs::Header,
    own: RobotId,
    neighbours: &[NeighbourStatus],
    frames: &WorldFrames,
) -> Option<geometry_msgs::TransformStamped> {
    let (parent, parent_from_own) = team_parent(own, neighbours)?;
    let parent_frame = frames.of(parent);
    (parent_frame.trim_start_matches('/') != header.frame_id.trim_start_matches('/')).then(|| {
        geometry_msgs::TransformStamped {
            header: std_msgs::Header { frame_id: parent_frame, ..header.clone() },
            child_frame_id: header.frame_id.clone(),
            transform: transform_msg(&parent_from_own),
        }
    })
}

/// The world frames of the team's robots, as they registered them.
#[derive(Clone, Debug)]
pub struct WorldFrames {
    world_template: String,
    known: Arc<Mutex<BTreeMap<u16, String>>>,
}

impl WorldFrames {
    pub fn new(ros: &RosConfig) -> Self {
        Self { world_template: ros.frames.world.clone(), known: Arc::default() }
    }

    /// Robot `id`'s world frame: registered, or the template with the name `robot_{id}`.
    pub fn of(&self, id: RobotId) -> String {
        let known = self.known.lock().unwrap_or_else(PoisonError::into_inner);
        known
            .get(&id.0)
            .cloned()
            .unwrap_or_else(|| RosConfig::resolve(&self.world_template, &format!("robot_{}", id.0), id.0))
    }

    /// Takes the registrations read from the master (`robot_{id}` → frame).
    pub fn update(&self, registered: &BTreeMap<String, String>) {
        let parsed = registered.iter().filter_map(|(key, frame)| {
            let id = key.strip_prefix("robot_")?.parse::<u16>().ok()?;
            let frame = frame.trim_start_matches('/');
            (!frame.is_empty()).then(|| (id, frame.to_string()))
        });
        let mut known = self.known.lock().unwrap_or_else(PoisonError::into_inner);
        known.extend(parsed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn aligned(robot: u16, x: f64) -> NeighbourStatus {
        NeighbourStatus {
            robot: RobotId(robot),
            state: Some(sgm_actors::protocol::ProtocolStage::Aligned),
            local_from_remote: Some(Pose3::translation(x, 0.0, 0.0)),
            first_aligned: Some(1.0),
            closures: Default::default(),
            aligned_via: None,
            contradicted_by: Vec::new(),
            withdrawals: 0,
            last_withdrawal: None,
            keyframes_held: 0,
            objects_revision: None,
            match_attempts: Default::default(),
            graph_rounds_refuted: 0,
        }
    }

    /// Robot 3 aligned with 4 and 2 (and matched, not aligned, with 1): its parent is 2, and
    /// the transform is the inverse of 2's place in 3's world; robot 1 is a root.
    #[test]
    fn a_robots_parent_is_its_lowest_aligned_lower_id() {
        let mut not_aligned = aligned(1, 9.0);
        not_aligned.local_from_remote = None;
        let neighbours = [aligned(4, 1.0), aligned(2, 5.0), not_aligned];
        let (parent, parent_from_own) = team_parent(RobotId(3), &neighbours).unwrap();
        assert_eq!(parent, RobotId(2));
        assert_eq!(parent_from_own.translation.vector, Vector3::new(-5.0, 0.0, 0.0));
        assert_eq!(team_parent(RobotId(1), &neighbours), None);
        assert_eq!(team_parent(RobotId(2), &neighbours), None, "1 is not aligned with 2");
    }

    /// Every robot's parent has a lower id: following parents always ends at a root.
    #[test]
    fn parents_never_form_a_loop() {
        let ids = 1..=6u16;
        for own in ids.clone() {
            let neighbours: Vec<_> = ids.clone().filter(|&n| n != own).map(|n| aligned(n, 1.0)).collect();
            if let Some((parent, _)) = team_parent(RobotId(own), &neighbours) {
                assert!(parent < RobotId(own));
            }
        }
    }

    #[test]
    fn the_transform_names_the_parents_world_and_skips_a_self_loop() {
        let header = std_msgs::Header { frame_id: "charlie/odom".into(), ..Default::default() };
        let frames = WorldFrames::new(&RosConfig::default());
        frames.update(&[("robot_2".to_string(), "bravo/odom".to_string())].into_iter().collect());
        let t = team_transform(&header, RobotId(3), &[aligned(2, 5.0)], &frames).unwrap();
        assert_eq!((t.header.frame_id.as_str(), t.child_frame_id.as_str()), ("bravo/odom", "charlie/odom"));
        assert_eq!(t.transform.translation.x, -5.0);
        let shared = std_msgs::Header { frame_id: "camera_init".into(), ..Default::default() };
        let mut same = RosConfig::default();
        same.frames.world = "camera_init".into();
        assert!(team_transform(&shared, RobotId(3), &[aligned(2, 5.0)], &WorldFrames::new(&same)).is_none());
    }

    #[test]
    fn registered_frames_replace_the_template() {
        let frames = WorldFrames::new(&RosConfig::default());
        assert_eq!(frames.of(RobotId(2)), "robot_2/odom");
        let registered = [("robot_2", "/bravo/odom"), ("robot_x", "junk"), ("robot_3", "")]
            .map(|(k, v)| (k.to_string(), v.to_string()));
        frames.update(&registered.into_iter().collect());
        assert_eq!(frames.of(RobotId(2)), "bravo/odom");
        assert_eq!(frames.of(RobotId(3)), "robot_3/odom");
    }
}
