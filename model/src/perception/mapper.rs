//! The robot's own map as plain state (paper §IV-A, §IV-E): which scans become keyframes, how
//! a keyframe is placed, the object layer, intra-robot loop closures and the cloud budget. The
//! Tracker actor owns one and sends on what it returns.
//!
//! A new keyframe k is placed by chaining the odometry increment since the previous keyframe
//! p onto p's *optimised* pose, so that corrections the pose graph made are kept:
//!
//!   Δ = odom_from_body(p)⁻¹ · odom_from_body(k),   world_from_body(k) = world_from_body(p) · Δ
//!
//! and the odometry edge p → k measures Δ. Its information is the inverse of Cov(e_Δ) when the
//! odometry gives each scan's motion covariance since the scan before (the robot's own odometry,
//! `odometry::clone`), composed scan by scan from p to k as independent steps:
//!
//!   Σ_{p→s} = Ad(δ⁻¹) Σ_{p→s−1} Ad(δ⁻¹)ᵀ + Σ_{s−1→s},   δ = odom_from_body(s−1)⁻¹ · odom_from_body(s)
//!
//! and the configured odometry information otherwise. The first keyframe takes its odometry
//! pose as is. Then the object layer is updated (Hungarian LAP
//! against nearby map objects, [`ObjectTracker`]), a loop closure is looked for at most once per
//! `loop_closure.min_interval_s` ([`loop_closure::detect`]), and the semantic layer is fitted
//! to `cloud_store` (old scans compacted, then evicted).

use super::classes::ClassTable;
use super::clustering::ObjectCandidate;
use super::keyframes::{is_keyframe, KeyframeConfig};
use super::loop_closure::{self, LoopClosureConfig};
use super::object_cloud::UNLABELLED;
use super::tracker::{ObjectTracker, TrackerConfig};
use crate::geometry::lie::se3_adjoint;
use crate::geometry::Pose3;
use crate::scene_graph::cloud_store::{CloudChange, CloudStoreConfig};
use crate::scene_graph::{
    Keyframe, KeyframeEdge, KeyframeEdgeKind, KeyframeId, KeyframeRef, LabelId, ObjectId, SceneGraph, SceneGraphError,
    SemanticScan, Stamp,
};
use crate::workers::Workers;
use nalgebra::{Matrix6, Point3};

/// What the mapper decides with.
#[derive(Clone, Debug, PartialEq)]
pub struct MapperConfig {
    pub keyframes: KeyframeConfig,
    pub tracking: TrackerConfig,
    pub loop_closure: LoopClosureConfig,
    pub cloud_store: CloudStoreConfig,
    /// Information of an odometry edge (the inverse of its covariance over (ω, v)).
    pub odometry_information: Matrix6<f64>,
}

/// One labelled scan, borrowed: the body's odometry pose and its points with their classes.
#[derive(Clone, Copy, Debug)]
pub struct ScanInput<'a> {
    pub stamp: Stamp,
    pub odom_from_body: &'a Pose3,
    pub points_in_body: &'a [Point3<f64>],
    pub labels: &'a [Option<LabelId>],
    pub candidates: &'a [ObjectCandidate],
    /// Cov(e_Δ) of the odometry's motion since the scan before, (ω, v) in the body frame, when the
    /// odometry gives it.
    pub motion_covariance: Option<&'a Matrix6<f64>>,
}

/// The odometry's motion since the latest keyframe: the latest scan's odometry pose and the
/// motion's covariance up to it (`None` once a scan came without one).
#[derive(Clone, Debug, PartialEq)]
pub struct MotionSinceKeyframe {
    pub odom_from_body: Pose3,
    pub covariance: Option<Matrix6<f64>>,
}

/// A keyframe the map took, and what changed with it.
#[derive(Clone, Debug)]
pub struct KeyframeAdded {
    pub keyframe: Keyframe,
    /// The odometry edge from the previous keyframe (none for the first) and a loop closure
    /// found at this keyframe, in that order.
    pub edges: Vec<KeyframeEdge>,
    /// A loop closure found but refused by the scene graph (it names a keyframe the graph no
    /// longer accepts an edge to), for the caller to report.
    pub refused_loop: Option<SceneGraphError>,
    /// Scans the cloud budget compacted (`Some`) or evicted (`None`) afterwards.
    pub scans_changed: Vec<CloudChange>,
}

/// The map and what continues it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mapper {
    pub graph: SceneGraph,
    pub objects: ObjectTracker,
    /// The id the next keyframe takes.
    pub next_keyframe: u32,
    /// The latest keyframe and its odometry pose (for increments).
    pub last_odometry: Option<(KeyframeId, Pose3)>,
    /// Stamp of the latest loop-closure attempt.
    pub last_loop_attempt: Option<Stamp>,
    /// Since the latest keyframe (none before the first; not in snapshots).
    pub motion: Option<MotionSinceKeyframe>,
}

impl Mapper {
    /// Whether a scan at `odom_from_body` becomes a keyframe (LIO-SAM's distance and angle
    /// thresholds against the latest keyframe's odometry pose).
    pub fn wants(&self, odom_from_body: &Pose3, config: &MapperConfig) -> bool {
        let last = self.last_odometry.map(|(_, p)| p);
        is_keyframe(last.as_ref(), odom_from_body, &config.keyframes)
    }

    /// Composes a scan's motion covariance (since the scan before; at `odom_from_body`) onto the
    /// motion since the latest keyframe (the module's equations). Every scan goes through here,
    /// a keyframe or not, before [`Self::add_keyframe`].
    pub fn note_scan(&mut self, odom_from_body: &Pose3, motion_covariance: Option<&Matrix6<f64>>) {
        let Some(motion) = &mut self.motion else { return };
        let step = motion.odom_from_body.inverse() * odom_from_body;
        motion.covariance = match (motion.covariance, motion_covariance) {
            (Some(before), Some(step_covariance)) => {
                let ad = se3_adjoint(&step.inverse());
                Some(ad * before * ad.transpose() + step_covariance)
            }
            _ => None,
        };
        motion.odom_from_body = *odom_from_body;
    }

    /// The odometry edge's information: the inverse of the composed motion covariance, or the
    /// configured information when there is none (or it is not positive definite).
    fn odometry_information(&self, config: &MapperConfig) -> Matrix6<f64> {
        self.motion
            .as_ref()
            .and_then(|m| m.covariance)
            .and_then(|c| c.cholesky())
            .map_or(config.odometry_information, |c| c.inverse())
    }

    /// Adds `scan` as the next keyframe (see the module's equations). On an error the steps
    /// already taken stay (a keyframe added before its scan was refused stays, and its id is not
    /// reused). The loop closure's registration may split its work over `workers`.
    pub fn add_keyframe(
        &mut self,
        scan: ScanInput<'_>,
        classes: &ClassTable,
        config: &MapperConfig,
        workers: &Workers,
    ) -> Result<KeyframeAdded, SceneGraphError> {
        let id = KeyframeId(self.next_keyframe);
        let (world_from_body, odometry_edge) = match self.last_odometry {
            None => (*scan.odom_from_body, None),
            Some((previous, odometry)) => {
                let increment = odometry.inverse() * scan.odom_from_body;
                let optimised = self.graph.keyframe(previous).map(|k| k.world_from_body).unwrap_or(odometry);
                let edge = KeyframeEdge {
                    kind: KeyframeEdgeKind::Odometry,
                    from: previous,
                    to: KeyframeRef::Local(id),
                    from_from_to: increment,
                    information: self.odometry_information(config),
                };
                (optimised * increment, Some(edge))
            }
        };
        let keyframe = Keyframe { id, stamp: scan.stamp, world_from_body };
        self.graph.add_keyframe(keyframe.clone())?;
        self.next_keyframe += 1;
        self.last_odometry = Some((id, *scan.odom_from_body));
        self.motion =
            Some(MotionSinceKeyframe { odom_from_body: *scan.odom_from_body, covariance: Some(Matrix6::zeros()) });
        let semantic = SemanticScan {
            points_in_body: scan.points_in_body.iter().map(|p| p.cast::<f32>()).collect(),
            labels: scan.labels.iter().map(|l| l.unwrap_or(UNLABELLED)).collect(),
        };
        self.graph.set_semantic_scan(id, semantic)?;
        let mut edges = Vec::new();
        if let Some(edge) = odometry_edge {
            self.graph.add_edge(edge.clone())?;
            edges.push(edge);
        }
        self.objects.update(&mut self.graph, id, scan.candidates, &config.tracking)?;
        let due = self.last_loop_attempt.is_none_or(|t| scan.stamp - t >= config.loop_closure.min_interval_s);
        if due {
            self.last_loop_attempt = Some(scan.stamp);
        }
        let mut refused_loop = None;
        if let Some(edge) = due.then(|| loop_closure::detect(&self.graph, id, &config.loop_closure, workers)).flatten()
        {
            match self.graph.add_edge(edge.clone()) {
                Ok(()) => edges.push(edge),
                Err(e) => refused_loop = Some(e),
            }
        }
        let scans_changed = self.graph.fit_clouds(&config.cloud_store, |l| classes.object_label(l.0).is_some());
        Ok(KeyframeAdded { keyframe, edges, refused_loop, scans_changed })
    }

    /// Counts a scan that is not a keyframe as a sighting of the objects its candidates
    /// associate with (`tracking.glimpse_spacing_m`; tracker module doc), seen from the pose the scan
    /// would take as a keyframe, `world_from_body(p) · Δ`. Returns the objects this confirmed
    /// (none before the first keyframe, or with `glimpse_spacing_m` 0).
    pub fn glimpse(&mut self, scan: &ScanInput<'_>, config: &MapperConfig) -> Vec<ObjectId> {
        let Some((previous, odometry)) = self.last_odometry else { return Vec::new() };
        let keyframe_from_body = odometry.inverse() * scan.odom_from_body;
        self.objects.glimpse(&self.graph, previous, &keyframe_from_body, scan.candidates, &config.tracking)
    }

    /// Moves the keyframes the map knows to their optimised poses (others are ignored: they may
    /// have been made after the solve started, or belong to a neighbour).
    pub fn apply_poses(&mut self, poses: &[(KeyframeId, Pose3)]) -> Result<(), SceneGraphError> {
        let known: Vec<&(KeyframeId, Pose3)> =
            poses.iter().filter(|(k, _)| self.graph.keyframe(*k).is_some()).collect();
        self.graph.update_keyframe_poses(known.into_iter().map(|(k, p)| (*k, p)))
    }

    /// Whether object `id` has been seen often enough to be shared and matched.
    pub fn is_confirmed(&self, id: crate::scene_graph::ObjectId, config: &MapperConfig) -> bool {
        self.objects.is_confirmed(id, &config.tracking)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_yaw_translation;
    use crate::perception::classes::ClassTable;
    use nalgebra::Vector3;

    fn config() -> MapperConfig {
        MapperConfig {
            keyframes: KeyframeConfig::default(),
            tracking: TrackerConfig::default(),
            loop_closure: LoopClosureConfig::default(),
            cloud_store: CloudStoreConfig::default(),
            odometry_information: Matrix6::identity() * 100.0,
        }
    }

    fn scan_at<'a>(stamp: Stamp, pose: &'a Pose3, points: &'a [Point3<f64>]) -> ScanInput<'a> {
        ScanInput {
            stamp,
            odom_from_body: pose,
            points_in_body: points,
            labels: &[],
            candidates: &[],
            motion_covariance: None,
        }
    }

    /// Closed form: two steps of 1 m along x, each known to variance a about each axis and b
    /// along each axis. Composed, the first step's yaw swings the second's end sideways by its
    /// lever of 1 m: the motion's y variance is 2b + a (likewise z: 2b + a), x only 2b, and
    /// each rotation 2a. Its inverse is the odometry edge's information; a scan without a
    /// covariance (an external odometry) gives the configured information.
    #[test]
    fn the_odometry_edge_carries_the_composed_motion_covariance() {
        let (config, classes) = (config(), ClassTable::default());
        let (a, b) = (1e-4, 4e-4);
        let step = Matrix6::from_diagonal(&nalgebra::Vector6::new(a, a, a, b, b, b));
        let poses: Vec<Pose3> = (0..3).map(|k| Pose3::translation(f64::from(k), 0.0, 0.0)).collect();
        let mut mapper = Mapper::default();
        let scan =
            |k: usize, covariance| ScanInput { motion_covariance: covariance, ..scan_at(k as f64, &poses[k], &[]) };
        mapper.note_scan(&poses[0], None);
        mapper.add_keyframe(scan(0, None), &classes, &config, &Workers::sequential()).expect("first");
        mapper.note_scan(&poses[1], Some(&step));
        mapper.note_scan(&poses[2], Some(&step));
        let added =
            mapper.add_keyframe(scan(2, Some(&step)), &classes, &config, &Workers::sequential()).expect("second");
        let covariance = added.edges[0].information.try_inverse().expect("invertible");
        let expected = nalgebra::Vector6::new(2.0 * a, 2.0 * a, 2.0 * a, 2.0 * b, 2.0 * b + a, 2.0 * b + a);
        assert!((covariance.diagonal() - expected).norm() < 1e-12, "{}", covariance.diagonal());
        // The yaw and the sideways swing move together: y and yaw correlated by the lever.
        assert!((covariance[(2, 4)] - a).abs() < 1e-12 && (covariance[(1, 5)] + a).abs() < 1e-12, "{covariance}");
        let later = ScanInput { stamp: 3.0, ..scan(1, None) };
        mapper.note_scan(later.odom_from_body, None);
        let third = mapper.add_keyframe(later, &classes, &config, &Workers::sequential()).expect("third");
        assert_eq!(third.edges[0].information, config.odometry_information);
    }

    #[test]
    fn keyframes_chain_odometry_increments_onto_optimised_poses() {
        let (config, classes) = (config(), ClassTable::default());
        let mut mapper = Mapper::default();
        let points = [Point3::new(1.0, 2.0, 0.5), Point3::new(-3.0, 0.0, 1.0)];
        let labels = [None, None];
        let odom0 = pose_from_yaw_translation(0.3, Vector3::new(1.0, 2.0, 0.0));
        let first = ScanInput { labels: &labels, ..scan_at(0.0, &odom0, &points) };
        let added = mapper.add_keyframe(first, &classes, &config, &Workers::sequential()).expect("first keyframe");
        assert_eq!(added.keyframe.world_from_body, odom0, "the first keyframe takes its odometry pose");
        assert!(added.edges.is_empty());
        assert_eq!(mapper.graph.semantic_scan(added.keyframe.id).map(|s| s.points_in_body.len()), Some(2));
        // The optimiser moves keyframe 0; the next keyframe keeps the odometry increment from it.
        let corrected = pose_from_yaw_translation(0.25, Vector3::new(1.2, 1.9, 0.0));
        mapper.apply_poses(&[(KeyframeId(0), corrected), (KeyframeId(99), Pose3::identity())]).expect("poses");
        let odom1 = odom0 * pose_from_yaw_translation(0.1, Vector3::new(2.0, 0.0, 0.0));
        let second =
            mapper.add_keyframe(scan_at(1.0, &odom1, &[]), &classes, &config, &Workers::sequential()).expect("second");
        let expected = corrected * pose_from_yaw_translation(0.1, Vector3::new(2.0, 0.0, 0.0));
        assert!((second.keyframe.world_from_body.translation.vector - expected.translation.vector).norm() < 1e-12);
        assert!(second.keyframe.world_from_body.rotation.angle_to(&expected.rotation) < 1e-12);
        let edge = &second.edges[0];
        assert_eq!(
            (edge.kind, edge.from, edge.to),
            (KeyframeEdgeKind::Odometry, KeyframeId(0), KeyframeRef::Local(KeyframeId(1)))
        );
        assert!((edge.from_from_to.translation.vector - Vector3::new(2.0, 0.0, 0.0)).norm() < 1e-12);
        assert_eq!(edge.information, config.odometry_information);
        assert_eq!(mapper.last_odometry, Some((KeyframeId(1), odom1)), "increments are taken between odometry poses");
    }

    /// A scan between keyframes sees from the pose it would take as a keyframe: the odometry
    /// increment chained onto the latest keyframe's *optimised* pose. A chair at (6, 3) in the
    /// world, keyframe 0 at odometry (1, 2) seeing it, then the optimiser moving keyframe 0 by
    /// 1.5 m: a scan 1 m on sees the chair where it is only through the optimised pose (through
    /// the odometry alone it would be 1.5 m off, beyond c_max). With `glimpse_spacing_m` 0
    /// nothing counts.
    #[test]
    fn glimpses_see_from_the_optimised_pose() {
        let (mut config, classes) = (config(), ClassTable::default());
        let chair = |pose: &Pose3| ObjectCandidate {
            label: LabelId(6),
            centroid: pose.inverse() * Point3::new(6.0, 3.0, 0.5),
            size: Vector3::repeat(0.5),
            points: 50,
        };
        let odom0 = pose_from_yaw_translation(0.0, Vector3::new(1.0, 2.0, 0.0));
        let mut mapper = Mapper::default();
        let seen = [chair(&odom0)];
        config.tracking.glimpse_spacing_m = 0.5;
        assert!(mapper.glimpse(&ScanInput { candidates: &seen, ..scan_at(0.0, &odom0, &[]) }, &config).is_empty());
        let first = ScanInput { candidates: &seen, ..scan_at(0.0, &odom0, &[]) };
        mapper.add_keyframe(first, &classes, &config, &Workers::sequential()).expect("first");
        let object = ObjectId(0);
        // The map says keyframe 0 stood 1.5 m further along y: the world (and the chair) with it.
        let corrected = pose_from_yaw_translation(0.0, Vector3::new(1.0, 3.5, 0.0));
        mapper.apply_poses(&[(KeyframeId(0), corrected)]).expect("poses");
        let at = |x: f64| odom0 * Pose3::translation(x, 0.0, 0.0);
        let (odom1, odom2) = (at(0.6), at(1.2));
        let (in_1, in_2) = ([chair(&odom1)], [chair(&odom2)]);
        let scan1 = ScanInput { candidates: &in_1, ..scan_at(0.5, &odom1, &[]) };
        let scan2 = ScanInput { candidates: &in_2, ..scan_at(0.6, &odom2, &[]) };
        config.tracking.glimpse_spacing_m = 0.0;
        assert!(mapper.glimpse(&scan1, &config).is_empty());
        assert_eq!(mapper.objects.sightings(object), 1, "spacing 0: not counted");
        config.tracking.glimpse_spacing_m = 0.5;
        assert!(mapper.glimpse(&scan1, &config).is_empty());
        assert_eq!(mapper.objects.sightings(object), 2, "seen through the optimised pose");
        assert_eq!(mapper.glimpse(&scan2, &config), vec![object]);
        assert!(mapper.is_confirmed(object, &config));
        assert_eq!(mapper.graph.object_count(), 1);
    }

    #[test]
    fn a_keyframe_only_past_the_thresholds_and_never_out_of_order() {
        let (config, classes) = (config(), ClassTable::default());
        let mut mapper = Mapper::default();
        let origin = Pose3::identity();
        assert!(mapper.wants(&origin, &config), "the first scan is always a keyframe");
        mapper.add_keyframe(scan_at(0.0, &origin, &[]), &classes, &config, &Workers::sequential()).expect("first");
        let near = pose_from_yaw_translation(0.0, Vector3::new(0.01, 0.0, 0.0));
        assert!(!mapper.wants(&near, &config), "1 cm is below the distance threshold");
        let far = pose_from_yaw_translation(0.0, Vector3::new(5.0, 0.0, 0.0));
        assert!(mapper.wants(&far, &config));
        // A stamp earlier than the latest keyframe's is refused by the scene graph: nothing is
        // added, and the next keyframe still gets a fresh id.
        let err = mapper
            .add_keyframe(scan_at(-1.0, &far, &[]), &classes, &config, &Workers::sequential())
            .expect_err("older stamp");
        assert!(matches!(err, SceneGraphError::StampNotIncreasing { .. }), "{err}");
        assert_eq!(mapper.graph.keyframe_count(), 1);
        let next = mapper
            .add_keyframe(scan_at(2.0, &far, &[]), &classes, &config, &Workers::sequential())
            .expect("later stamp");
        assert_eq!(next.keyframe.id, KeyframeId(1));
    }

    #[test]
    fn a_revisit_closes_a_loop_at_most_once_per_interval() {
        let (mut config, classes) = (config(), ClassTable::default());
        config.loop_closure.min_interval_s = 5.0;
        let mut mapper = Mapper::default();
        // The walls of one room around the world's origin, seen from each keyframe's pose.
        let room: Vec<Point3<f64>> = (0..400)
            .map(|i| {
                let a = f64::from(i) * std::f64::consts::TAU / 400.0;
                Point3::new(6.0 * a.cos(), 4.0 * a.sin() + 0.5 * (3.0 * a).sin(), f64::from(i % 10) * 0.2)
            })
            .collect();
        // Away beyond the 15 m search radius, back after 40 s (the time gap is 30 s), and once
        // more 2 s later: within the interval, so not tried again.
        let route = [
            (0.0, 0.0, 0.0),
            (5.0, 20.0, 0.0),
            (10.0, 20.0, 20.0),
            (15.0, 0.0, 20.0),
            (40.0, 0.0, 0.3),
            (42.0, 0.0, 0.6),
        ];
        let labels = vec![None; room.len()];
        let mut loops = Vec::new();
        for (t, x, y) in route {
            let pose = pose_from_yaw_translation(0.0, Vector3::new(x, y, 0.0));
            let body_from_world = pose.inverse();
            let points: Vec<Point3<f64>> = room.iter().map(|p| body_from_world * p).collect();
            let scan = ScanInput { labels: &labels, ..scan_at(t, &pose, &points) };
            let added = mapper.add_keyframe(scan, &classes, &config, &Workers::sequential()).expect("add");
            loops.extend(added.edges.into_iter().filter(|e| e.kind == KeyframeEdgeKind::Loop));
        }
        assert_eq!(mapper.last_loop_attempt, Some(40.0), "42 s is within the interval of 40 s");
        assert_eq!(loops.len(), 1, "one loop, at the revisit: {loops:?}");
        let ends = (loops[0].from, loops[0].to);
        assert!(
            ends == (KeyframeId(0), KeyframeRef::Local(KeyframeId(4)))
                || ends == (KeyframeId(4), KeyframeRef::Local(KeyframeId(0))),
            "between the first keyframe and the revisit: {ends:?}"
        );
        // Odometry is exact here: the loop measures the odometry's own increment.
        assert!(loops[0].from_from_to.translation.vector.norm() - 0.3 < 0.05);
    }
}
