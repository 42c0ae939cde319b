//! End to end across crates: two robots build scene graphs of the same place from their own
//! start poses, a loop closure moves one robot's keyframes, and the object layers, exported as
//! object graphs through the CLI's file format, match to the true transform between the maps.

use nalgebra::{Point3, Vector3};
use sgm_model::geometry::{pose_error, pose_from_yaw_translation, Pose3};
use sgm_model::matching::{match_graphs, LabelSimilarity, MatcherConfig, ObjectGraph};
use sgm_model::scene_graph::{Keyframe, KeyframeId, LabelId, SceneGraph};
use sgm_scenarios::object_file::{graphs_from_files, ObjectEntry, ObjectFile};

/// Objects of a small campus in the world frame (label, x, y, z).
const CAMPUS: [(u16, f64, f64, f64); 9] = [
    (0, 3.0, 4.0, 0.5),
    (1, 15.0, -2.0, 0.4),
    (0, 22.0, 10.0, 0.5),
    (2, 9.0, 18.0, 2.5),
    (1, -6.0, 12.0, 0.4),
    (3, 30.0, 25.0, 0.6),
    (2, -10.0, -8.0, 2.5),
    (0, 18.0, 30.0, 0.5),
    (3, 5.0, -15.0, 0.6),
];

/// A robot whose world frame is `world_from_robot` drives past every object; each object is
/// observed from a keyframe near it.
fn build(world_from_robot: &Pose3) -> SceneGraph {
    let robot_from_world = world_from_robot.inverse();
    let mut g = SceneGraph::new();
    for (k, &(label, x, y, z)) in CAMPUS.iter().enumerate() {
        let body_in_world = pose_from_yaw_translation(0.3 * k as f64, Vector3::new(x - 2.0, y - 1.0, 0.0));
        let kf = KeyframeId(k as u32);
        g.add_keyframe(Keyframe { id: kf, stamp: k as f64, world_from_body: robot_from_world * body_in_world })
            .unwrap();
        g.add_object(LabelId(label), robot_from_world * Point3::new(x, y, z), Vector3::repeat(0.8), kf).unwrap();
    }
    g
}

fn to_file(robot: &str, g: &SceneGraph) -> ObjectFile {
    let names = ["chair", "bench", "lamp_post", "trash_can"];
    let objects = ObjectGraph::from_scene_graph(g, |_| true)
        .objects()
        .iter()
        .map(|o| ObjectEntry {
            id: o.id.0,
            label: names[o.label.0 as usize].to_string(),
            centroid: [o.centroid.x, o.centroid.y, o.centroid.z],
            size: o.size.map(|s| [s.x, s.y, s.z]),
        })
        .collect();
    ObjectFile { robot: robot.to_string(), objects }
}

#[test]
fn scene_graphs_of_two_robots_match_after_a_loop_closure() {
    let world_from_a = pose_from_yaw_translation(0.2, Vector3::new(-5.0, 2.0, 0.0));
    let world_from_b = pose_from_yaw_translation(-2.4, Vector3::new(40.0, 12.0, 0.3));
    let a = build(&world_from_a);
    let mut b = build(&world_from_b);

    // A loop closure corrects robot b's drift: all its keyframes move by one small transform of
    // its world frame. Objects follow their anchor keyframes, so b's map is now expressed in a
    // frame `corrected_from_b`, and the true transform changes accordingly.
    let corrected_from_b = pose_from_yaw_translation(0.05, Vector3::new(1.5, -0.5, 0.0));
    let moved: Vec<(KeyframeId, Pose3)> = b.keyframes().map(|k| (k.id, corrected_from_b * k.world_from_body)).collect();
    b.update_keyframe_poses(moved.iter().map(|(id, p)| (*id, p))).unwrap();

    let config = MatcherConfig::default();
    let (local, remote, labels) = graphs_from_files(&to_file("a", &a), &to_file("b", &b), &config).unwrap();
    let report = match_graphs(&local, &remote, &labels, &config);
    let alignment = report.outcome.alignment().expect("same campus, matched");
    let truth = world_from_a.inverse() * world_from_b * corrected_from_b.inverse();
    let e = pose_error(&alignment.local_from_remote, &truth);
    assert!(e.translation_m < 1e-6 && e.max_axis_rotation_deg() < 1e-6, "{e:?}");
    assert_eq!(alignment.matches.len(), CAMPUS.len());
    assert!(alignment.matches.iter().all(|m| m.local == m.remote), "both robots numbered objects in visiting order");

    // With hard labels the answer is the same.
    let hard = match_graphs(&local, &remote, &LabelSimilarity::hard(labels_len(&local, &remote)), &config);
    assert!(hard.outcome.alignment().is_some());
}

fn labels_len(a: &ObjectGraph, b: &ObjectGraph) -> usize {
    a.objects().iter().chain(b.objects()).map(|o| o.label.0 as usize + 1).max().unwrap_or(0)
}
