//! `Tracker`: the robot's map (paper §IV-A, §IV-E). Selects keyframes (LIO-SAM thresholds),
//! chains odometry increments onto the optimised poses, keeps the object layer (Hungarian LAP
//! with c_max against nearby map objects, `model::perception::tracker`), detects intra-robot loop
//! closures, and answers neighbours' requests for object clouds and keyframes. Owns the
//! `SceneGraph`; a restart keeps it (the keyframe database survives).

use crate::config::{OptimiserConfig, TrackerSection};
use crate::containment::contained;
use crate::messages::*;
use actix::{Actor, Context, Handler, Message, MessageResult, Recipient, Supervised};
use nalgebra::{Matrix6, Point3};
use sgm_model::geometry::Pose3;
use sgm_model::matching::GraphObject;
use sgm_model::perception::classes::ClassTable;
use sgm_model::perception::keyframes::is_keyframe;
use sgm_model::perception::loop_closure;
use sgm_model::perception::object_cloud::{object_cloud, MAX_VIEWS, UNLABELLED};
use sgm_model::perception::tracker::ObjectTracker;
use sgm_model::scene_graph::{
    CloudStoreStats, Keyframe, KeyframeEdge, KeyframeEdgeKind, KeyframeId, KeyframeRef, ObjectId, RobotId, SceneGraph,
    SemanticScan,
};
use sgm_model::wire::cloud_codec;
use sgm_model::wire::messages::{
    expand_covariance, pack_covariance, KeyframeRefusal, KeyframeRefusalReason, KeyframeResponse, ObjectCloud,
    ObjectCloudResponse, WirePose,
};
use sgm_model::wire::Message as WireMessage;
use std::collections::BTreeMap;

/// Where the Tracker sends what it produces.
#[derive(Clone)]
pub struct TrackerLinks {
    pub optimiser: Recipient<NewKeyframe>,
    pub matcher_keyframes: Recipient<LocalKeyframe>,
    pub matcher_scans: Recipient<LocalScansChanged>,
    pub matcher_objects: Recipient<LocalObjects>,
    pub comms_objects: Recipient<LocalObjects>,
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
}

/// A thawed robot numbers its next keyframe from the next multiple of this above the
/// snapshot's: keyframes made between the snapshot and a crash may be known to neighbours, and
/// their ids are never reused.
pub const KEYFRAME_ID_EPOCH: u32 = 1 << 16;

/// A keyframe's pose, points (body) and labels, borrowed from the map.
type ScanRef<'a> = (&'a Pose3, &'a [Point3<f32>], &'a [sgm_model::scene_graph::LabelId]);

pub struct Tracker {
    robot: RobotId,
    config: TrackerSection,
    classes: ClassTable,
    odometry_information: Matrix6<f64>,
    cloud_resolution_m: f64,
    links: Option<TrackerLinks>,
    graph: SceneGraph,
    objects: ObjectTracker,
    next_keyframe: u32,
    /// Odometry pose of the latest keyframe (for increments).
    last_odometry: Option<(KeyframeId, Pose3)>,
    /// The latest marginal covariance of each keyframe, as served: the wire's packed upper
    /// triangle (84 bytes, not a 288-byte `Matrix6<f64>`; one per keyframe, kept for hours).
    covariances: BTreeMap<KeyframeId, [f32; 21]>,
    /// Stamp of the latest loop-closure attempt.
    last_loop_attempt: Option<f64>,
    /// The newest frame handled, for latency measurement outside the robot.
    progress: crate::progress::FrameProgress,
}

impl Tracker {
    pub fn new(
        robot: RobotId,
        config: TrackerSection,
        classes: ClassTable,
        optimiser: &OptimiserConfig,
        cloud_resolution_m: f64,
    ) -> Self {
        let s = optimiser.odometry_sigmas;
        let odometry_information =
            Matrix6::from_diagonal(&nalgebra::Vector6::from_iterator(s.iter().map(|v| 1.0 / (v * v))));
        Self {
            robot,
            config,
            classes,
            odometry_information,
            cloud_resolution_m,
            links: None,
            graph: SceneGraph::new(),
            objects: ObjectTracker::default(),
            next_keyframe: 0,
            last_odometry: None,
            covariances: BTreeMap::new(),
            last_loop_attempt: None,
            progress: crate::progress::FrameProgress::default(),
        }
    }

    /// The state a snapshot keeps.
    pub fn freeze(&self) -> TrackerState {
        TrackerState {
            graph: self.graph.clone(),
            objects: self.objects.clone(),
            next_keyframe: self.next_keyframe,
            last_odometry: self.last_odometry,
            covariances: self.covariances.iter().map(|(k, p)| (*k, expand_covariance(p))).collect(),
            last_loop_attempt: self.last_loop_attempt,
        }
    }

    /// Continues from `state` (see [`KEYFRAME_ID_EPOCH`]).
    /// Reports each handled frame's stamp to `progress`.
    pub fn with_progress(mut self, progress: crate::progress::FrameProgress) -> Self {
        self.progress = progress;
        self
    }

    pub fn thawed(mut self, state: TrackerState) -> Self {
        let epoch = state.next_keyframe.div_ceil(KEYFRAME_ID_EPOCH).saturating_add(1);
        self.next_keyframe = epoch.saturating_mul(KEYFRAME_ID_EPOCH);
        self.graph = state.graph;
        self.objects = state.objects;
        self.last_odometry = state.last_odometry;
        self.covariances = state.covariances.iter().map(|(k, m)| (*k, pack_covariance(m))).collect();
        self.last_loop_attempt = state.last_loop_attempt;
        self
    }

    fn local_objects(&self) -> LocalObjects {
        let mut out = LocalObjects::default();
        for o in self.graph.objects() {
            if !self.classes.is_matchable(o.label) || !self.objects.is_confirmed(o.id, &self.config.tracking) {
                continue;
            }
            let Some(centroid) = self.graph.centroid_in_world(o.id) else { continue };
            out.objects.push(GraphObject { id: o.id, label: o.label, centroid, size: Some(o.size) });
            out.observed_in.insert(o.id, o.observed_in.iter().copied().collect());
        }
        out
    }

    fn add_keyframe(&mut self, scan: &LabelledScan) -> Result<KeyframeId, String> {
        let id = KeyframeId(self.next_keyframe);
        let (world_from_body, odometry_edge) = match self.last_odometry {
            None => (scan.odom_from_body, None),
            Some((previous, odometry)) => {
                let increment = odometry.inverse() * scan.odom_from_body;
                let optimised = self.graph.keyframe(previous).map(|k| k.world_from_body).unwrap_or(odometry);
                let edge = KeyframeEdge {
                    kind: KeyframeEdgeKind::Odometry,
                    from: previous,
                    to: KeyframeRef::Local(id),
                    from_from_to: increment,
                    information: self.odometry_information,
                };
                (optimised * increment, Some(edge))
            }
        };
        self.graph.add_keyframe(Keyframe { id, stamp: scan.stamp, world_from_body }).map_err(|e| e.to_string())?;
        self.next_keyframe += 1;
        self.last_odometry = Some((id, scan.odom_from_body));
        let semantic = SemanticScan {
            points_in_body: scan.points_in_body.iter().map(|p| p.cast::<f32>()).collect(),
            labels: scan.labels.iter().map(|l| l.unwrap_or(UNLABELLED)).collect(),
        };
        self.graph.set_semantic_scan(id, semantic).map_err(|e| e.to_string())?;
        let mut edges = Vec::new();
        if let Some(edge) = odometry_edge {
            self.graph.add_edge(edge.clone()).map_err(|e| e.to_string())?;
            edges.push(edge);
        }
        self.objects.update(&mut self.graph, id, &scan.candidates, &self.config.tracking).map_err(|e| e.to_string())?;
        let due = self.last_loop_attempt.is_none_or(|t| scan.stamp - t >= self.config.loop_closure.min_interval_s);
        if due {
            self.last_loop_attempt = Some(scan.stamp);
        }
        if let Some(edge) = due.then(|| loop_closure::detect(&self.graph, id, &self.config.loop_closure)).flatten() {
            if self.graph.add_edge(edge.clone()).is_ok() {
                edges.push(edge);
            }
        }
        if let Some(links) = &self.links {
            links
                .optimiser
                .do_send(NewKeyframe { keyframe: Keyframe { id, stamp: scan.stamp, world_from_body }, edges });
            if let Some(scan) = self.graph.semantic_scan_shared(id) {
                links.matcher_keyframes.do_send(LocalKeyframe { id, world_from_body, scan });
            }
        }
        self.fit_clouds();
        Ok(id)
    }

    /// Keeps the map's clouds within `tracker.cloud_store`; the Matcher follows the changes.
    fn fit_clouds(&mut self) {
        let classes = &self.classes;
        let changes = self.graph.fit_clouds(&self.config.cloud_store, |l| classes.object_label(l.0).is_some());
        if changes.is_empty() {
            return;
        }
        let stats = self.graph.cloud_stats();
        tracing::debug!(robot = %self.robot, changed = changes.len(), scans = stats.scans, bytes = stats.bytes,
            "cloud store fitted to its budget");
        if let Some(links) = &self.links {
            links.matcher_scans.do_send(LocalScansChanged { changes });
        }
    }

    fn publish_objects(&self) {
        if let Some(links) = &self.links {
            let objects = self.local_objects();
            links.matcher_objects.do_send(objects.clone());
            links.comms_objects.do_send(objects);
        }
    }

    /// The scans the map still holds of `keyframes`, in their order (evicted ones skipped).
    fn scans_of<'a>(
        &'a self,
        keyframes: impl IntoIterator<Item = KeyframeId> + 'a,
    ) -> impl Iterator<Item = ScanRef<'a>> {
        keyframes.into_iter().filter_map(|k| {
            let kf = self.graph.keyframe(k)?;
            let scan = self.graph.semantic_scan(k)?;
            Some((&kf.world_from_body, &scan.points_in_body[..], &scan.labels[..]))
        })
    }

    fn serve_object_clouds(&self, robot: RobotId, ids: &[ObjectId]) -> WireMessage {
        let objects = ids
            .iter()
            .filter_map(|id| {
                let o = self.graph.object(*id)?;
                let centroid = self.graph.centroid_in_world(*id)?;
                // The latest views that still hold a scan (older ones may have been evicted).
                let views = self.scans_of(o.observed_in.iter().rev().copied()).take(MAX_VIEWS);
                let points = object_cloud(views, o.label, &centroid, &o.size, 0.3, 0.1);
                let cloud = cloud_codec::encode(&points, self.cloud_resolution_m).map(|c| c.bytes).unwrap_or_default();
                Some(ObjectCloud { id: *id, keyframes: o.observed_in.iter().copied().collect(), cloud })
            })
            .collect();
        tracing::debug!(robot = %self.robot, to = %robot, "serving object clouds");
        WireMessage::ObjectCloudResponse(ObjectCloudResponse { objects })
    }

    fn serve_keyframe(&self, id: KeyframeId) -> Option<WireMessage> {
        let kf = self.graph.keyframe(id)?;
        let scan = self.graph.semantic_scan(id)?;
        let points: Vec<Point3<f64>> = scan.points_in_body.iter().map(|p| p.cast::<f64>()).collect();
        let cloud = cloud_codec::encode(&points, self.cloud_resolution_m).ok()?.bytes;
        let covariance = self.covariances.get(&id).copied().unwrap_or_else(|| {
            pack_covariance(&self.odometry_information.try_inverse().unwrap_or_else(Matrix6::identity))
        });
        Some(WireMessage::KeyframeResponse(KeyframeResponse {
            keyframe: id,
            stamp: kf.stamp,
            world_from_body: WirePose::from(&kf.world_from_body),
            covariance,
            cloud,
        }))
    }
}

impl Actor for Tracker {
    type Context = Context<Self>;
}

impl Supervised for Tracker {
    fn restarting(&mut self, _: &mut Context<Self>) {
        tracing::warn!(robot = %self.robot, keyframes = self.graph.keyframe_count(), "tracker restarting with its map");
    }
}

impl Handler<LabelledScan> for Tracker {
    type Result = ();
    fn handle(&mut self, scan: LabelledScan, ctx: &mut Context<Self>) {
        contained(ctx, "tracker", || {
            let last = self.last_odometry.map(|(_, p)| p);
            if is_keyframe(last.as_ref(), &scan.odom_from_body, &self.config.keyframes) {
                match self.add_keyframe(&scan) {
                    Ok(_) => self.publish_objects(),
                    Err(e) => tracing::warn!(robot = %self.robot, stamp = scan.stamp, "keyframe not added: {e}"),
                }
            }
            self.progress.handled(scan.stamp);
        });
    }
}

impl Handler<PosesOptimised> for Tracker {
    type Result = ();
    fn handle(&mut self, msg: PosesOptimised, ctx: &mut Context<Self>) {
        contained(ctx, "tracker", || {
            let known: Vec<(KeyframeId, Pose3)> =
                msg.poses.into_iter().filter(|(k, _)| self.graph.keyframe(*k).is_some()).collect();
            if let Err(e) = self.graph.update_keyframe_poses(known.iter().map(|(k, p)| (*k, p))) {
                tracing::warn!(robot = %self.robot, "optimised poses not applied: {e}");
                return;
            }
            self.covariances.extend(msg.covariances.iter().map(|(k, m)| (*k, pack_covariance(m))));
            self.publish_objects();
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
            let Some(links) = &self.links else { return };
            for keyframe in self.graph.keyframes() {
                let Some(scan) = self.graph.semantic_scan_shared(keyframe.id) else { continue };
                links.matcher_keyframes.do_send(LocalKeyframe {
                    id: keyframe.id,
                    world_from_body: keyframe.world_from_body,
                    scan,
                });
            }
            self.publish_objects();
        });
    }
}

impl Handler<GetSceneGraph> for Tracker {
    type Result = MessageResult<GetSceneGraph>;
    fn handle(&mut self, _: GetSceneGraph, _: &mut Context<Self>) -> Self::Result {
        MessageResult(self.graph.clone())
    }
}

impl Handler<GetMapSummary> for Tracker {
    type Result = MessageResult<GetMapSummary>;
    fn handle(&mut self, _: GetMapSummary, _: &mut Context<Self>) -> Self::Result {
        let objects = self
            .graph
            .objects()
            .filter_map(|o| {
                Some(MapObject {
                    id: o.id,
                    label: o.label,
                    centroid: self.graph.centroid_in_world(o.id)?,
                    size: o.size,
                    anchor: o.anchor,
                    confirmed: self.objects.is_confirmed(o.id, &self.config.tracking),
                })
            })
            .collect();
        MessageResult(MapSummary {
            keyframes: self.graph.keyframes().cloned().collect(),
            objects,
            clouds: self.graph.cloud_stats(),
        })
    }
}

connects!(Tracker => TrackerLinks);
freezes!(Tracker => TrackerState);
stops_on_injected_failure!(Tracker => "tracker");
