//! `Tracker`: the robot's map (paper §IV-A, §IV-E), a thin actor over
//! `model::perception::mapper::Mapper`, which selects keyframes, chains odometry increments onto
//! the optimised poses, keeps the object layer, detects intra-robot loop closures and fits the
//! cloud budget. The actor sends on what the mapper returns (new keyframes to the Optimiser; after
//! every change, one read-only snapshot of the map, `crate::map_view::MapView`, to the Matcher
//! and Comms) and answers
//! neighbours' requests for object clouds and keyframes. A restart keeps the map (the keyframe
//! database survives).

use crate::config::{OptimiserConfig, TrackerSection};
use crate::containment::contained;
use crate::map_view::MapView;
use crate::messages::*;
use actix::{Actor, Context, Handler, Message, MessageResult, Recipient, Supervised};
use nalgebra::{Matrix6, Point3};
use sgm_model::geometry::Pose3;
use sgm_model::perception::classes::ClassTable;
use sgm_model::perception::mapper::{Mapper, MapperConfig, ScanInput};
use sgm_model::perception::object_cloud::{object_cloud, MAX_VIEWS};
use sgm_model::perception::tracker::ObjectTracker;
use sgm_model::scene_graph::{CloudStoreStats, Keyframe, KeyframeId, ObjectId, RobotId, SceneGraph, SceneGraphError};
use sgm_model::spatial::voxel::downsample;
use sgm_model::wire::cloud_codec;
use sgm_model::wire::messages::{
    expand_covariance, pack_covariance, KeyframeRefusal, KeyframeRefusalReason, KeyframeResponse, ObjectCloud,
    ObjectCloudResponse, WirePose,
};
use sgm_model::wire::Message as WireMessage;
use sgm_model::workers::Workers;
use std::collections::BTreeMap;
use std::sync::Arc;

/// Where the Tracker sends what it produces.
#[derive(Clone)]
pub struct TrackerLinks {
    pub optimiser: Recipient<NewKeyframe>,
    pub matcher_map: Recipient<MapChanged>,
    pub comms_map: Recipient<MapChanged>,
    pub comms_outgoing: Recipient<Outgoing>,
}

/// A copy of the map, for status and reports.
#[derive(Message)]
#[rtype(result = "SceneGraph")]
pub struct GetSceneGraph;

/// The map without its clouds: cheap enough to ask for every few seconds (reports, status).
#[derive(Message)]
#[rtype(result = "MapSummary")]
pub struct GetMapSummary;

/// Keyframe poses (optimised, world frame) and every object, in id order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MapSummary {
    pub keyframes: Vec<Keyframe>,
    pub objects: Vec<MapObject>,
    /// What the map's cloud store holds (`tracker.cloud_store`).
    pub clouds: CloudStoreStats,
    /// Objects found moving (`tracker.tracking.moving_m`): never confirmed, so neither shared
    /// nor matched.
    pub moving_objects: usize,
    /// Objects merged into another, one object seen as two (`tracker.tracking.merge_stacked`).
    pub merged_objects: u64,
    /// Tentative objects removed, unseen for `tracker.tracking.tentative_expiry_s`.
    pub expired_objects: u64,
    /// Sightings counted from scans between keyframes (`tracker.tracking.glimpse_spacing_m`).
    pub glimpse_sightings: u64,
}

/// One object of the map, in the world frame.
#[derive(Clone, Debug, PartialEq)]
pub struct MapObject {
    pub id: ObjectId,
    pub label: sgm_model::scene_graph::LabelId,
    pub centroid: Point3<f64>,
    pub size: nalgebra::Vector3<f64>,
    /// The keyframe it hangs from (the scene graph's cross-layer edge).
    pub anchor: sgm_model::scene_graph::KeyframeId,
    /// Sightings reached the confirmation count: shared with and matched by other robots.
    pub confirmed: bool,
}

/// What of the Tracker a snapshot keeps: the whole map and what continues it.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrackerState {
    pub graph: SceneGraph,
    pub objects: ObjectTracker,
    pub next_keyframe: u32,
    pub last_odometry: Option<(KeyframeId, Pose3)>,
    pub covariances: BTreeMap<KeyframeId, Matrix6<f64>>,
    pub last_loop_attempt: Option<f64>,
    /// Each keyframe's pose from our own measurements alone (what neighbours are told).
    pub own_poses: BTreeMap<KeyframeId, Pose3>,
}

/// A thawed robot numbers its next keyframe from the next multiple of this above the
/// snapshot's: keyframes made between the snapshot and a crash may be known to neighbours, and
/// their ids are never reused.
pub const KEYFRAME_ID_EPOCH: u32 = 1 << 16;

/// A keyframe's pose, points (body) and labels, borrowed from the map.
type ScanRef<'a> = (&'a Pose3, &'a [Point3<f32>], &'a [sgm_model::scene_graph::LabelId]);

pub struct Tracker {
    robot: RobotId,
    config: MapperConfig,
    classes: ClassTable,
    clouds: ServedClouds,
    links: Option<TrackerLinks>,
    map: Mapper,
    /// The latest marginal covariance of each keyframe, as served: the wire's packed upper
    /// triangle (84 bytes, not a 288-byte `Matrix6<f64>`; one per keyframe, kept for hours).
    covariances: BTreeMap<KeyframeId, [f32; 21]>,
    /// Each keyframe's pose from our own measurements alone, as of the latest solve
    /// (`KeyframeGraph::own_poses`, with `comms.pose_updates.own_estimates`; empty without):
    /// what neighbours are told ([`Tracker::told_pose`]).
    own_poses: BTreeMap<KeyframeId, Pose3>,
    /// The newest frame handled, for latency measurement outside the robot.
    progress: crate::progress::FrameProgress,
    workers: Workers,
}

/// How the clouds we serve are encoded (`[comms]`): the codec's quantum, and the voxel a
/// keyframe's scan is thinned to first — the centroid of each occupied voxel, as the
/// requester's registration thins it again (`matcher.keyframe_voxel_m`; a few percent of the
/// centroids, rounded by the codec onto a voxel face, fall in the next voxel there and merge
/// with its centroid); 0: the whole scan.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ServedClouds {
    pub resolution_m: f64,
    pub keyframe_voxel_m: f64,
}

impl ServedClouds {
    /// A keyframe's scan as a keyframe response carries it: thinned to `keyframe_voxel_m` (0:
    /// every return, not copied again), then encoded at `resolution_m`.
    pub fn keyframe_cloud(&self, points_in_body: &[Point3<f32>]) -> Result<Vec<u8>, cloud_codec::CodecError> {
        let mut points: Vec<Point3<f64>> = points_in_body.iter().map(|p| p.cast::<f64>()).collect();
        if self.keyframe_voxel_m > 0.0 {
            points = downsample(&points, self.keyframe_voxel_m);
        }
        cloud_codec::encode(&points, self.resolution_m).map(|c| c.bytes)
    }
}

impl Tracker {
    pub fn new(
        robot: RobotId,
        config: TrackerSection,
        classes: ClassTable,
        optimiser: &OptimiserConfig,
        clouds: ServedClouds,
    ) -> Self {
        let s = optimiser.odometry_sigmas;
        let odometry_information =
            Matrix6::from_diagonal(&nalgebra::Vector6::from_iterator(s.iter().map(|v| 1.0 / (v * v))));
        let TrackerSection { keyframes, tracking, loop_closure, cloud_store } = config;
        Self {
            robot,
            config: MapperConfig { keyframes, tracking, loop_closure, cloud_store, odometry_information },
            classes,
            clouds,
            links: None,
            map: Mapper::default(),
            covariances: BTreeMap::new(),
            own_poses: BTreeMap::new(),
            progress: crate::progress::FrameProgress::default(),
            workers: Workers::sequential(),
        }
    }

    /// The state a snapshot keeps.
    pub fn freeze(&self) -> TrackerState {
        TrackerState {
            graph: self.map.graph.clone(),
            objects: self.map.objects.clone(),
            next_keyframe: self.map.next_keyframe,
            last_odometry: self.map.last_odometry,
            covariances: self.covariances.iter().map(|(k, p)| (*k, expand_covariance(p))).collect(),
            last_loop_attempt: self.map.last_loop_attempt,
            own_poses: self.own_poses.clone(),
        }
    }

    /// Reports each handled frame's stamp to `progress`.
    pub fn with_progress(mut self, progress: crate::progress::FrameProgress) -> Self {
        self.progress = progress;
        self
    }

    /// Lets a loop closure's registration split its work over `workers` (the same map for any
    /// number of threads).
    pub fn with_workers(mut self, workers: Workers) -> Self {
        self.workers = workers;
        self
    }

    /// Continues from `state` (see [`KEYFRAME_ID_EPOCH`]).
    pub fn thawed(mut self, state: TrackerState) -> Self {
        let epoch = state.next_keyframe.div_ceil(KEYFRAME_ID_EPOCH).saturating_add(1);
        self.map = Mapper {
            graph: state.graph,
            objects: state.objects,
            next_keyframe: epoch.saturating_mul(KEYFRAME_ID_EPOCH),
            last_odometry: state.last_odometry,
            last_loop_attempt: state.last_loop_attempt,
            motion: None,
        };
        self.covariances = state.covariances.iter().map(|(k, m)| (*k, pack_covariance(m))).collect();
        self.own_poses = state.own_poses;
        self
    }

    /// Adds `scan` as a keyframe (`Mapper::add_keyframe`) and sends the keyframe and its edges
    /// to the Optimiser.
    fn add_keyframe(&mut self, scan: &LabelledScan) -> Result<KeyframeId, SceneGraphError> {
        let moving_before = self.map.objects.moving_count();
        let added = self.map.add_keyframe(scan_input(scan), &self.classes, &self.config, &self.workers)?;
        let id = added.keyframe.id;
        let moving = self.map.objects.moving_count();
        if moving > moving_before {
            tracing::info!(robot = %self.robot, keyframe = id.0, moving,
                "object found moving: kept out of the shared map (tracker.tracking.moving_m)");
        }
        if let Some(e) = &added.refused_loop {
            tracing::warn!(robot = %self.robot, keyframe = id.0, "loop closure not added: {e}");
        }
        if let Some(links) = &self.links {
            let odom_from_body_rotation = scan.odom_from_body.rotation;
            links.optimiser.do_send(NewKeyframe {
                keyframe: added.keyframe,
                edges: added.edges,
                odom_from_body_rotation,
                measured_up: scan.measured_up,
            });
        }
        if !added.scans_changed.is_empty() {
            let stats = self.map.graph.cloud_stats();
            tracing::debug!(robot = %self.robot, changed = added.scans_changed.len(), scans = stats.scans,
                bytes = stats.bytes, "cloud store fitted to its budget");
        }
        Ok(id)
    }

    /// Counts a scan between keyframes as a sighting of the objects it saw
    /// (`tracker.tracking.glimpse_spacing_m`). Objects it confirms are shared with the next keyframe's map.
    fn glimpse(&mut self, scan: &LabelledScan) {
        let confirmed = self.map.glimpse(&scan_input(scan), &self.config);
        if !confirmed.is_empty() {
            tracing::debug!(robot = %self.robot, stamp = scan.stamp, confirmed = confirmed.len(),
                "objects confirmed between keyframes");
        }
    }

    /// What neighbours are told of keyframe `id`'s pose: our own measurements' estimate
    /// ([`PosesOptimised::own_poses`]), or the map's when there is none (`own_estimates` off).
    /// A keyframe made since the latest solve has none yet; it takes the correction of the
    /// latest one before it that has,
    ///
    /// ```text
    /// told(k) = own(j) · map(j)⁻¹ · map(k)      (j: the latest keyframe before k with an own pose)
    /// ```
    ///
    /// and its map pose before any solve.
    fn told_pose(&self, id: KeyframeId) -> Option<Pose3> {
        told_pose(&self.own_poses, &self.map.graph, id)
    }

    /// Shares the map as it is now with the Matcher and Comms (with what neighbours are told of
    /// its keyframes, when that is our own estimates rather than the map's poses).
    fn publish_map(&self) {
        if let Some(links) = &self.links {
            let mut view = MapView::of(&self.map, &self.classes, &self.config);
            if !self.own_poses.is_empty() {
                view.told = view.keyframes.keys().filter_map(|k| Some((*k, self.told_pose(*k)?))).collect();
            }
            let view = Arc::new(view);
            links.matcher_map.do_send(MapChanged(view.clone()));
            links.comms_map.do_send(MapChanged(view));
        }
    }

    /// The scans the map still holds of `keyframes`, in their order (evicted ones skipped).
    fn scans_of<'a>(
        &'a self,
        keyframes: impl IntoIterator<Item = KeyframeId> + 'a,
    ) -> impl Iterator<Item = ScanRef<'a>> {
        keyframes.into_iter().filter_map(|k| {
            let kf = self.map.graph.keyframe(k)?;
            let scan = self.map.graph.semantic_scan(k)?;
            Some((&kf.world_from_body, &scan.points_in_body[..], &scan.labels[..]))
        })
    }

    fn serve_object_clouds(&self, robot: RobotId, ids: &[ObjectId]) -> WireMessage {
        let objects = ids
            .iter()
            .filter_map(|id| {
                let o = self.map.graph.object(*id)?;
                let centroid = self.map.graph.centroid_in_world(*id)?;
                // The latest views that still hold a scan (older ones may have been evicted).
                let views = self.scans_of(o.observed_in.iter().rev().copied()).take(MAX_VIEWS);
                let points = object_cloud(views, o.label, &centroid, &o.size, 0.3, 0.1);
                let cloud = match cloud_codec::encode(&points, self.clouds.resolution_m) {
                    Ok(c) => c.bytes,
                    Err(e) => {
                        tracing::warn!(robot = %self.robot, object = %id.0, error = %e, "object cloud served empty: it cannot be encoded");
                        Vec::new()
                    }
                };
                Some(ObjectCloud { id: *id, keyframes: o.observed_in.iter().copied().collect(), cloud })
            })
            .collect();
        tracing::debug!(robot = %self.robot, to = %robot, "serving object clouds");
        WireMessage::ObjectCloudResponse(ObjectCloudResponse { objects })
    }

    fn serve_keyframe(&self, id: KeyframeId) -> Option<WireMessage> {
        let kf = self.map.graph.keyframe(id)?;
        let told = self.told_pose(id)?;
        let scan = self.map.graph.semantic_scan(id)?;
        let cloud = match self.clouds.keyframe_cloud(&scan.points_in_body) {
            Ok(cloud) => cloud,
            Err(e) => {
                tracing::warn!(robot = %self.robot, keyframe = %id.0, error = %e, "keyframe not served: its cloud cannot be encoded");
                return None;
            }
        };
        let covariance = self.covariances.get(&id).copied().unwrap_or_else(|| {
            pack_covariance(&self.config.odometry_information.try_inverse().unwrap_or_else(Matrix6::identity))
        });
        Some(WireMessage::KeyframeResponse(KeyframeResponse {
            keyframe: id,
            stamp: kf.stamp,
            world_from_body: WirePose::from(&told),
            covariance,
            cloud,
        }))
    }
}

/// [`Tracker::told_pose`] over `own` poses and the map's `graph`.
fn told_pose(own: &BTreeMap<KeyframeId, Pose3>, graph: &SceneGraph, id: KeyframeId) -> Option<Pose3> {
    let map_pose = graph.keyframe(id)?.world_from_body;
    if let Some(pose) = own.get(&id) {
        return Some(*pose);
    }
    let before = own.range(..id).next_back().and_then(|(j, own_j)| {
        let map_j = graph.keyframe(*j)?.world_from_body;
        Some(own_j * map_j.inverse() * map_pose)
    });
    Some(before.unwrap_or(map_pose))
}

/// The mapper's view of a scan.
fn scan_input(scan: &LabelledScan) -> ScanInput<'_> {
    ScanInput {
        stamp: scan.stamp,
        odom_from_body: &scan.odom_from_body,
        points_in_body: &scan.points_in_body,
        labels: &scan.labels,
        candidates: &scan.candidates,
        motion_covariance: scan.motion_covariance.as_ref(),
    }
}

impl Actor for Tracker {
    type Context = Context<Self>;
}

impl Supervised for Tracker {
    fn restarting(&mut self, _: &mut Context<Self>) {
        tracing::warn!(robot = %self.robot, keyframes = self.map.graph.keyframe_count(), "tracker restarting with its map");
    }
}

impl Handler<LabelledScan> for Tracker {
    type Result = ();
    fn handle(&mut self, scan: LabelledScan, ctx: &mut Context<Self>) {
        contained(ctx, "tracker", || {
            self.map.note_scan(&scan.odom_from_body, scan.motion_covariance.as_ref());
            if self.map.wants(&scan.odom_from_body, &self.config) {
                match self.add_keyframe(&scan) {
                    Ok(_) => self.publish_map(),
                    Err(e) => tracing::warn!(robot = %self.robot, stamp = scan.stamp, "keyframe not added: {e}"),
                }
            } else {
                self.glimpse(&scan);
            }
            self.progress.handled(scan.stamp);
        });
    }
}

impl Handler<PosesOptimised> for Tracker {
    type Result = ();
    fn handle(&mut self, msg: PosesOptimised, ctx: &mut Context<Self>) {
        contained(ctx, "tracker", || {
            if let Err(e) = self.map.apply_poses(&msg.poses) {
                tracing::warn!(robot = %self.robot, "optimised poses not applied: {e}");
                return;
            }
            self.covariances.extend(msg.covariances.iter().map(|(k, m)| (*k, pack_covariance(m))));
            self.own_poses = msg.own_poses.into_iter().collect();
            self.publish_map();
        });
    }
}

impl Handler<Serve> for Tracker {
    type Result = ();
    fn handle(&mut self, msg: Serve, ctx: &mut Context<Self>) {
        contained(ctx, "tracker", || {
            let Some(links) = self.links.clone() else { return };
            match msg {
                Serve::ObjectClouds { robot, objects } => {
                    links
                        .comms_outgoing
                        .do_send(Outgoing { to: robot, message: self.serve_object_clouds(robot, &objects) });
                }
                Serve::Keyframes { robot, keyframes } => {
                    let mut unknown = Vec::new();
                    for id in keyframes {
                        match self.serve_keyframe(id) {
                            Some(message) => links.comms_outgoing.do_send(Outgoing { to: robot, message }),
                            None => unknown.push(id),
                        }
                    }
                    if !unknown.is_empty() {
                        let refusal = KeyframeRefusal { keyframes: unknown, reason: KeyframeRefusalReason::Unknown };
                        links
                            .comms_outgoing
                            .do_send(Outgoing { to: robot, message: WireMessage::KeyframeRefusal(refusal) });
                    }
                }
            }
        });
    }
}

impl Handler<Republish> for Tracker {
    type Result = ();
    fn handle(&mut self, _: Republish, ctx: &mut Context<Self>) {
        contained(ctx, "tracker", || {
            self.publish_map();
        });
    }
}

impl Handler<GetSceneGraph> for Tracker {
    type Result = MessageResult<GetSceneGraph>;
    fn handle(&mut self, _: GetSceneGraph, _: &mut Context<Self>) -> Self::Result {
        MessageResult(self.map.graph.clone())
    }
}

impl Handler<GetMapSummary> for Tracker {
    type Result = MessageResult<GetMapSummary>;
    fn handle(&mut self, _: GetMapSummary, _: &mut Context<Self>) -> Self::Result {
        let graph = &self.map.graph;
        let objects = graph
            .objects()
            .filter_map(|o| {
                Some(MapObject {
                    id: o.id,
                    label: o.label,
                    centroid: graph.centroid_in_world(o.id)?,
                    size: o.size,
                    anchor: o.anchor,
                    confirmed: self.map.is_confirmed(o.id, &self.config),
                })
            })
            .collect();
        MessageResult(MapSummary {
            keyframes: graph.keyframes().cloned().collect(),
            objects,
            clouds: graph.cloud_stats(),
            moving_objects: self.map.objects.moving_count(),
            merged_objects: self.map.objects.merged_count(),
            expired_objects: self.map.objects.expired_count(),
            glimpse_sightings: self.map.objects.glimpse_count(),
        })
    }
}

connects!(Tracker => TrackerLinks);
freezes!(Tracker => TrackerState);
stops_on_injected_failure!(Tracker => "tracker");

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use sgm_model::geometry::pose_from_yaw_translation;

    /// Keyframes 0–2 solved (our own estimates 0.2 m left of the map's and turned 1°), keyframe
    /// 3 made since: it carries keyframe 2's correction; without own poses, the map's; an
    /// unknown keyframe, none.
    #[test]
    fn a_keyframe_made_since_the_solve_carries_the_latest_correction() {
        let mut graph = SceneGraph::new();
        let map = |k: u32| pose_from_yaw_translation(0.1 * f64::from(k), Vector3::new(2.0 * f64::from(k), 0.0, 0.0));
        for k in 0..4u32 {
            graph.add_keyframe(Keyframe { id: KeyframeId(k), stamp: f64::from(k), world_from_body: map(k) }).unwrap();
        }
        let correction = pose_from_yaw_translation(1f64.to_radians(), Vector3::new(0.0, 0.2, 0.0));
        let own: BTreeMap<KeyframeId, Pose3> = (0..3u32).map(|k| (KeyframeId(k), correction * map(k))).collect();
        assert_eq!(told_pose(&own, &graph, KeyframeId(1)), Some(correction * map(1)));
        let told = told_pose(&own, &graph, KeyframeId(3)).unwrap();
        let expected = correction * map(3);
        assert!((told.translation.vector - expected.translation.vector).norm() < 1e-12);
        assert!(told.rotation.angle_to(&expected.rotation) < 1e-12);
        assert_eq!(told_pose(&BTreeMap::new(), &graph, KeyframeId(3)), Some(map(3)));
        assert_eq!(told_pose(&own, &graph, KeyframeId(9)), None);
    }

    /// A served keyframe thinned to 0.3 m voxels is the centroid of each occupied voxel (to the
    /// codec's quantum) and costs a fraction of the bytes; at 0 it is every return, as before.
    #[test]
    fn a_served_keyframe_is_thinned_to_its_voxels() {
        // A wall and a floor sampled every 5 cm: 20 × 20 returns each over 1 m × 1 m.
        let mut points: Vec<Point3<f32>> = Vec::new();
        for i in 0..20 {
            for j in 0..20 {
                let (a, b) = (0.025 + 0.05 * i as f32, 0.025 + 0.05 * j as f32);
                points.push(Point3::new(2.05, a, b));
                points.push(Point3::new(a + 1.0, b, 0.05));
            }
        }
        let whole = ServedClouds { resolution_m: 0.01, keyframe_voxel_m: 0.0 };
        let thinned = ServedClouds { keyframe_voxel_m: 0.3, ..whole };
        let all: Vec<Point3<f64>> = points.iter().map(|p| p.cast::<f64>()).collect();
        assert_eq!(whole.keyframe_cloud(&points).ok(), cloud_codec::encode(&all, 0.01).ok().map(|c| c.bytes));
        let (full, thin) = (whole.keyframe_cloud(&points).unwrap(), thinned.keyframe_cloud(&points).unwrap());
        let decoded = cloud_codec::decode(&thin).unwrap();
        // The centroids by hand: the mean of the returns in each occupied voxel.
        let mut sums: BTreeMap<[i64; 3], (Vector3<f64>, f64)> = BTreeMap::new();
        for p in &all {
            let voxel = [0, 1, 2].map(|a| (p[a] / 0.3).floor() as i64);
            let e = sums.entry(voxel).or_insert((Vector3::zeros(), 0.0));
            e.0 += p.coords;
            e.1 += 1.0;
        }
        assert_eq!(decoded.len(), sums.len());
        for (sum, n) in sums.values() {
            let centroid = sum / *n;
            assert!(decoded.iter().any(|p| (p.coords - centroid).abs().max() <= 0.005 + 1e-9), "{centroid} not served");
        }
        assert!(thin.len() * 4 < full.len(), "{} bytes thinned against {} whole", thin.len(), full.len());
    }
}
