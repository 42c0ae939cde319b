//! Intra-robot loop closure as in LIO-SAM (paper §IV: "a Euclidean distance-based approach
//! similar to that of LIO-SAM"): the nearest keyframe within `search_radius_m` whose stamp is at
//! least `time_gap_s` older than the current one, and whose scan the cloud store still holds,
//! is the candidate; the current keyframe's scan is registered by ICP against a submap of the
//! candidate and its `submap_neighbours` neighbours on either side (all in the world frame, at
//! the current estimates; neighbours whose scans were evicted add nothing); a registration that
//! converged with inlier RMSE ≤ `max_rmse_m` gives the loop factor
//!   z = x_candidate⁻¹ · (T_icp · x_current),
//! with LIO-SAM's noise model: an isotropic σ equal to the RMSE on all six axes.

use super::icp::{register_to, Freedom, IcpConfig, IcpTarget};
use crate::geometry::Pose3;
use crate::scene_graph::{KeyframeEdge, KeyframeEdgeKind, KeyframeId, KeyframeRef, SceneGraph};
use crate::workers::Workers;
use nalgebra::{Matrix6, Point3};
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LoopClosureConfig {
    /// Default 15 m (LIO-SAM `historyKeyframeSearchRadius`).
    pub search_radius_m: f64,
    /// Default 30 s (LIO-SAM `historyKeyframeSearchTimeDiff`).
    pub time_gap_s: f64,
    /// Keyframes on each side of the candidate in its submap. Default 12.
    pub submap_neighbours: usize,
    /// Largest inlier RMSE of an accepted registration, m. Default 0.3 (LIO-SAM
    /// `historyKeyframeFitnessScore`).
    pub max_rmse_m: f64,
    /// Shortest interval between two detection attempts, s: a submap registration is the
    /// mapper's most expensive step, and LIO-SAM runs it at 1 Hz for the same reason.
    /// Default 2.
    pub min_interval_s: f64,
    pub icp: IcpConfig,
}

impl Default for LoopClosureConfig {
    fn default() -> Self {
        Self {
            search_radius_m: 15.0,
            time_gap_s: 30.0,
            submap_neighbours: 12,
            max_rmse_m: 0.3,
            min_interval_s: 2.0,
            icp: IcpConfig { max_correspondence_distance_m: 2.0, voxel_m: 0.4, ..IcpConfig::default() },
        }
    }
}

/// A keyframe's held scan in the world frame, at its current estimate (nothing if it holds none).
fn scan_in_world(graph: &SceneGraph, id: KeyframeId) -> impl Iterator<Item = Point3<f64>> + '_ {
    let held = graph.keyframe(id).zip(graph.semantic_scan(id));
    held.into_iter().flat_map(|(kf, scan)| scan.points_in_body.iter().map(|p| kf.world_from_body * p.cast::<f64>()))
}

/// Looks for a loop closure for `current`; returns the loop edge (not yet added to the graph).
/// The registration may split its correspondence search over `workers` (same answer).
pub fn detect(
    graph: &SceneGraph,
    current: KeyframeId,
    config: &LoopClosureConfig,
    workers: &Workers,
) -> Option<KeyframeEdge> {
    let now = graph.keyframe(current)?;
    let here = now.world_from_body.translation.vector;
    let candidate = graph
        .keyframes()
        .filter(|k| k.stamp <= now.stamp - config.time_gap_s && graph.semantic_scan(k.id).is_some())
        .map(|k| ((k.world_from_body.translation.vector - here).norm(), k))
        .filter(|(d, _)| *d <= config.search_radius_m)
        .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.id.cmp(&b.1.id)))?
        .1;
    // Submap: the candidate and its neighbours in keyframe order.
    let ordered: Vec<KeyframeId> = graph.keyframes().map(|k| k.id).collect();
    let at = ordered.iter().position(|&k| k == candidate.id)?;
    let lo = at.saturating_sub(config.submap_neighbours);
    let hi = (at + config.submap_neighbours + 1).min(ordered.len());
    // The submap is voxelised as it is gathered (up to 25 scans: never collected whole).
    let submap = || ordered[lo..hi].iter().filter(|&&k| k != current);
    let expected = submap().filter_map(|&k| graph.semantic_scan(k)).map(|s| s.points_in_body.len()).sum();
    let mut target =
        IcpTarget::gathered(submap().flat_map(|&k| scan_in_world(graph, k)), expected, &config.icp).ok()?;
    let source: Vec<Point3<f64>> = scan_in_world(graph, current).collect();
    let result = register_to(&source, &mut target, &Pose3::identity(), &config.icp, workers, Freedom::Full).ok()?;
    if !result.converged || result.rmse_m > config.max_rmse_m {
        return None;
    }
    let corrected = result.target_from_source * now.world_from_body;
    let sigma = result.rmse_m.max(1e-3);
    Some(KeyframeEdge {
        kind: KeyframeEdgeKind::Loop,
        from: candidate.id,
        to: KeyframeRef::Local(current),
        from_from_to: candidate.world_from_body.inverse() * corrected,
        information: Matrix6::identity() / (sigma * sigma),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{pose_error, pose_from_yaw_translation};
    use crate::scene_graph::{Keyframe, LabelId, SemanticScan};
    use nalgebra::Vector3;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Points of a courtyard (ground, two walls, a kiosk) in the world frame.
    fn courtyard(seed: u64) -> Vec<Point3<f64>> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..6000)
            .map(|k| {
                let (a, b) = (rng.random_range(-1.0..1.0), rng.random_range(0.0..1.0));
                match k % 4 {
                    0 => Point3::new(15.0 * a, 15.0 * b - 5.0, 0.0),
                    1 => Point3::new(15.0 * a, 10.0, 4.0 * b),
                    2 => Point3::new(-12.0, 10.0 * a, 4.0 * b),
                    _ => Point3::new(3.0 + a, 2.0 + b, 2.5 * b),
                }
            })
            .collect()
    }

    fn add(graph: &mut SceneGraph, id: u32, stamp: f64, estimate: Pose3, truth: Pose3, seed: u64) {
        let kf = KeyframeId(id);
        graph.add_keyframe(Keyframe { id: kf, stamp, world_from_body: estimate }).unwrap();
        let body_from_world = truth.inverse();
        let points: Vec<nalgebra::Point3<f32>> =
            courtyard(seed).iter().map(|p| (body_from_world * p).cast::<f32>()).collect();
        let labels = vec![LabelId(0); points.len()];
        graph.set_semantic_scan(kf, SemanticScan { points_in_body: points, labels }).unwrap();
    }

    #[test]
    fn revisiting_a_place_after_drift_closes_the_loop_with_the_true_relative_pose() {
        let mut graph = SceneGraph::new();
        let first = pose_from_yaw_translation(0.2, Vector3::new(0.0, 0.0, 0.0));
        add(&mut graph, 0, 0.0, first, first, 1);
        // A minute later the robot is back, 1 m from where it started; odometry has drifted
        // by 0.6 m and 2°.
        let truth = pose_from_yaw_translation(0.5, Vector3::new(1.0, 0.3, 0.0));
        let drifted = pose_from_yaw_translation(0.5 + 2f64.to_radians(), Vector3::new(1.5, -0.1, 0.0));
        add(&mut graph, 1, 60.0, drifted, truth, 2);
        let edge =
            detect(&graph, KeyframeId(1), &LoopClosureConfig::default(), &Workers::sequential()).expect("loop found");
        assert_eq!(
            (edge.kind, edge.from, edge.to),
            (KeyframeEdgeKind::Loop, KeyframeId(0), KeyframeRef::Local(KeyframeId(1)))
        );
        let e = pose_error(&edge.from_from_to, &(first.inverse() * truth));
        assert!(e.translation_m < 0.05 && e.max_axis_rotation_deg() < 0.5, "{e:?}");
        assert!(edge.information[(0, 0)] > 1.0);
        // Too recent: no candidate.
        let config = LoopClosureConfig { time_gap_s: 90.0, ..LoopClosureConfig::default() };
        assert!(detect(&graph, KeyframeId(1), &config, &Workers::sequential()).is_none());
    }
}
