//! Typed messages between the actors of one robot (DESIGN.md §3). Every message is a Rust type;
//! payloads that cross the radio are `sgm_model::wire` types inside `Comms` only.

use actix::Message;
use nalgebra::{Matrix6, Point3, UnitQuaternion};
use sgm_model::geometry::up::MeasuredUp;
use sgm_model::geometry::Pose3;
use sgm_model::matching::scan_context::ScanContext;
use sgm_model::perception::clustering::ObjectCandidate;
use sgm_model::perception::imu::ImuSample;
use sgm_model::perception::projection::{CameraModel, LabelImage};
use sgm_model::scene_graph::{Keyframe, KeyframeEdge, KeyframeId, LabelId, ObjectId, RobotId, Stamp};
use sgm_model::wire::messages::{KeyframeRefusalReason, ObjectCloud, ObjectData};
use sgm_model::wire::Message as WireMessage;

/// How the points of a frame get their classes.
#[derive(Clone, Debug)]
pub enum FrameLabels {
    /// One class per point (`None`: unlabelled), e.g. from a simulator or an upstream fuser.
    PerPoint(Vec<Option<LabelId>>),
    /// A segmented image: points are projected into it (paper §IV-A).
    Image {
        image: LabelImage,
        camera: CameraModel,
        /// The camera's mount: the camera from the body at the scan's stamp, once any motion
        /// between the image and the scan is compensated upstream.
        camera_from_body: Pose3,
        /// The image's stamp minus the scan's, s, for motion not compensated upstream: Fusion
        /// compensates it at the odometry's velocity (`model::perception::motion`). The ROS
        /// synchroniser compensates from the odometry at both stamps and sends 0.
        image_offset_s: f64,
    },
    /// No labels: a sweep between labelled frames (the LiDAR turns faster than the camera
    /// fires), for the internal odometry only. It registers the sweep and does not hand it on;
    /// with an external odometry, Sensor drops it (counted).
    Unlabelled,
}

/// One synchronised sensor frame: a LiDAR scan in the body frame, its labels, and the
/// odometry pose of the body (`odom_from_body`: the odometry's own estimate in the robot's
/// world frame, before any optimisation; a keyframe's optimised pose is `world_from_body`).
#[derive(Message, Clone, Debug)]
#[rtype(result = "()")]
pub struct SensorFrame {
    pub stamp: Stamp,
    pub odom_from_body: Pose3,
    pub points_in_body: Vec<Point3<f64>>,
    /// Each point's time after `stamp`, s, when the driver gives it (a sweep measured on the
    /// move): Fusion deskews the scan with it. `None`: the scan is used as it came.
    pub point_times: Option<Vec<f32>>,
    /// The points are already in the body at `stamp` (the internal odometry deskewed them):
    /// Fusion does not deskew them again, and counts them as deskewed upstream.
    pub points_deskewed: bool,
    pub labels: FrameLabels,
    /// The IMU's samples since the previous frame, up to the end of this one's sweep (empty
    /// without an IMU): Fusion deskews with the gyro's rotation where they cover the sweep.
    pub imu: Vec<ImuSample>,
    /// Cov of the odometry's motion since the previous frame handed on, (ω, v) in the body
    /// frame: set by the robot's own odometry (`odometry::clone`); `None`: the Tracker's
    /// odometry factors take the configured noise.
    pub motion_covariance: Option<Matrix6<f64>>,
    /// Up in the body and its σ, as an odometry that estimates them measured them (the robot's
    /// own sets it); `None`: the tilt is read from `odom_from_body`, taken as gravity-aligned.
    pub measured_up: Option<MeasuredUp>,
}

/// Fusion → Tracker: a labelled scan and its object candidates (body frame).
#[derive(Message, Clone, Debug)]
#[rtype(result = "()")]
pub struct LabelledScan {
    pub stamp: Stamp,
    /// The frame's odometry pose (see [`SensorFrame`]).
    pub odom_from_body: Pose3,
    pub points_in_body: Vec<Point3<f64>>,
    pub labels: Vec<Option<LabelId>>,
    pub candidates: Vec<ObjectCandidate>,
    /// The frame's [`SensorFrame::motion_covariance`].
    pub motion_covariance: Option<Matrix6<f64>>,
    /// The frame's [`SensorFrame::measured_up`].
    pub measured_up: Option<MeasuredUp>,
}

/// Tracker → Optimiser: a new keyframe and the edges it brings (odometry, loops).
#[derive(Message, Clone, Debug)]
#[rtype(result = "()")]
pub struct NewKeyframe {
    pub keyframe: Keyframe,
    pub edges: Vec<KeyframeEdge>,
    /// The body's attitude as its odometry measured it (odom_from_body's rotation): in a
    /// gravity-aligned odometry frame its tilt is the keyframe's against gravity.
    pub odom_from_body_rotation: UnitQuaternion<f64>,
    /// Up in the body with its σ, when the odometry measured them ([`SensorFrame::measured_up`]):
    /// the keyframe's gravity prior is then made from it, not from the attitude.
    pub measured_up: Option<MeasuredUp>,
}

/// Tracker → Matcher and Comms: the map changed (a keyframe added, scans compacted or evicted,
/// optimised poses applied, a restored map republished); the new snapshot, shared read-only.
#[derive(Message, Clone, Debug)]
#[rtype(result = "()")]
pub struct MapChanged(pub std::sync::Arc<crate::map_view::MapView>);

/// Optimiser → Tracker: optimised keyframe poses (world frame) and marginal
/// covariances over (ω, v), and what the robot's own measurements alone say of each keyframe
/// (`KeyframeGraph::own_poses`; empty unless `comms.pose_updates.own_estimates`): what
/// neighbours are then told.
#[derive(Message, Clone, Debug, Default)]
#[rtype(result = "()")]
pub struct PosesOptimised {
    pub poses: Vec<(KeyframeId, Pose3)>,
    pub covariances: Vec<(KeyframeId, Matrix6<f64>)>,
    pub own_poses: Vec<(KeyframeId, Pose3)>,
}

/// Comms → Matcher: a neighbour's object data arrived.
#[derive(Message, Clone, Debug)]
#[rtype(result = "()")]
pub struct NeighbourObjects {
    pub robot: RobotId,
    pub data: ObjectData,
}

/// Comms → Matcher: object clouds arrived.
#[derive(Message, Clone, Debug)]
#[rtype(result = "()")]
pub struct NeighbourObjectClouds {
    pub robot: RobotId,
    pub clouds: Vec<ObjectCloud>,
}

/// Comms → Matcher: a neighbour keyframe arrived (cloud decoded, body frame).
#[derive(Message, Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[rtype(result = "()")]
pub struct NeighbourKeyframe {
    pub robot: RobotId,
    pub id: KeyframeId,
    pub world_from_body: Pose3,
    pub covariance: Matrix6<f64>,
    pub points_in_body: Vec<Point3<f64>>,
    /// Bytes of its compressed cloud on the radio (what a closure budget counts).
    pub cloud_bytes: u64,
}

/// Comms → Optimiser: a neighbour's new estimates (its world) of keyframes it served us, valid
/// poses only: the priors of those we hold take them.
#[derive(Message, Clone, Debug, PartialEq)]
#[rtype(result = "()")]
pub struct NeighbourKeyframePoses {
    pub robot: RobotId,
    pub poses: Vec<(KeyframeId, Pose3)>,
}

/// Comms → Optimiser (`optimiser.share_factors`): a neighbour asks for our factor log from a
/// position on, or sends part of its own.
#[derive(Message, Clone, Debug, PartialEq)]
#[rtype(result = "()")]
pub enum NeighbourGraph {
    Request { robot: RobotId, from: u32 },
    Slice { robot: RobotId, slice: sgm_model::optim::shared_factors::LogSlice },
}

/// Optimiser → Matcher: each aligned neighbour's local_from_remote as the last solve of the
/// pose graph estimates it (its anchor), from every inter-robot factor so far, and the
/// withdrawals of that neighbour the graph had handled ([`NeighbourWithdrawn`]): an estimate
/// made before the last withdrawal reached the graph is of the withdrawn alignment.
#[derive(Message, Clone, Debug, PartialEq)]
#[rtype(result = "()")]
pub struct NeighbourTransforms(pub Vec<(RobotId, Pose3, u32)>);

/// Comms → Matcher: requested keyframes that will not come (unknown to the neighbour, or given
/// up after every retry).
#[derive(Message, Clone, Debug)]
#[rtype(result = "()")]
pub struct KeyframesUnavailable {
    pub robot: RobotId,
    pub keyframes: Vec<KeyframeId>,
    pub reason: KeyframeRefusalReason,
}

/// Comms → Matcher: a neighbour fell silent for `comms.link_timeout_s` (`up: false`), or was
/// heard again (`up: true`). While a link is down nothing is retried or given up towards it.
#[derive(Message, Clone, Copy, Debug, PartialEq, Eq)]
#[rtype(result = "()")]
pub struct LinkChanged {
    pub robot: RobotId,
    pub up: bool,
}

/// Comms → Matcher: Scan Context descriptors of a neighbour's keyframes arrived (association
/// `scan_context` only), each with the keyframe's pose in the neighbour's world.
#[derive(Message, Clone, Debug)]
#[rtype(result = "()")]
pub struct NeighbourDescriptors {
    pub robot: RobotId,
    pub descriptors: Vec<(KeyframeId, Pose3, ScanContext)>,
}

/// Matcher → Comms: a local keyframe's Scan Context descriptor, for the next broadcast
/// (association `scan_context` only).
#[derive(Message, Clone, Debug)]
#[rtype(result = "()")]
pub struct ShareDescriptor {
    pub keyframe: KeyframeId,
    pub world_from_body: Pose3,
    pub descriptor: ScanContext,
}

/// Matcher → Comms: every neighbour we are aligned with and its world in ours
/// (`local_from_remote`), for the next `Alignments` broadcast when it changed.
#[derive(Message, Clone, Debug)]
#[rtype(result = "()")]
pub struct ShareAlignments(pub Vec<(RobotId, Pose3)>);

/// Comms → Matcher: a neighbour's alignments (its world from each robot's it placed), valid
/// poses only: hints, checked by our own registration before they count.
#[derive(Message, Clone, Debug)]
#[rtype(result = "()")]
pub struct NeighbourAlignments {
    pub robot: RobotId,
    pub alignments: Vec<(RobotId, Pose3)>,
}

/// Matcher → Comms: ask a neighbour for object clouds.
#[derive(Message, Clone, Debug)]
#[rtype(result = "()")]
pub struct RequestObjectClouds {
    pub robot: RobotId,
    pub objects: Vec<ObjectId>,
}

/// Matcher → Comms: keyframes wanted from a neighbour (Comms coalesces, bounds and never asks
/// twice).
#[derive(Message, Clone, Debug)]
#[rtype(result = "()")]
pub struct RequestKeyframes {
    pub robot: RobotId,
    pub keyframes: Vec<KeyframeId>,
}

/// Matcher → Comms: neighbour keyframes the Matcher no longer holds (beyond
/// `matcher.max_held_keyframes`, or once aligned): asking for one of them again is not a
/// duplicate.
#[derive(Message, Clone, Debug)]
#[rtype(result = "()")]
pub struct KeyframesReleased {
    pub robot: RobotId,
    pub keyframes: Vec<KeyframeId>,
}

/// Comms → Tracker: a neighbour asked for data only the map holds.
#[derive(Message, Clone, Debug)]
#[rtype(result = "()")]
pub enum Serve {
    ObjectClouds { robot: RobotId, objects: Vec<ObjectId> },
    Keyframes { robot: RobotId, keyframes: Vec<KeyframeId> },
}

/// Tracker → Comms: a message for a neighbour.
#[derive(Message, Clone, Debug)]
#[rtype(result = "()")]
pub struct Outgoing {
    pub to: RobotId,
    pub message: WireMessage,
}

/// Matcher → Optimiser: inter-robot constraints with one neighbour (paper §IV-D, §IV-E):
/// the neighbour keyframes as variables with priors, and relative-pose factors from ICP.
#[derive(Message, Clone, Debug)]
#[rtype(result = "()")]
pub struct InterRobotConstraints {
    pub robot: RobotId,
    pub local_from_remote: Pose3,
    /// Neighbour keyframe → (pose in the neighbour's world, covariance over (ω, v)).
    pub neighbour_keyframes: Vec<(KeyframeId, Pose3, Matrix6<f64>)>,
    /// (local keyframe, neighbour keyframe, local_body_from_neighbour_body, information).
    pub factors: Vec<(KeyframeId, KeyframeId, Pose3, Matrix6<f64>)>,
}

/// Matcher → Optimiser: our alignment with `robot` was found wrong (a contradicted cycle
/// settled against it, `matcher.relay.settle`): its anchor, keyframes and inter-robot factors
/// leave the pose graph; a later alignment places it afresh.
#[derive(Message, Clone, Copy, Debug)]
#[rtype(result = "()")]
pub struct NeighbourWithdrawn {
    pub robot: RobotId,
}

/// Runner / bridge → supervisor → children: time moved on to `now` (the clock is already set).
#[derive(Message, Clone, Copy, Debug)]
#[rtype(result = "()")]
pub struct Tick {
    pub now: Stamp,
}

/// Supervisor → child, once at start: the addresses the child sends to (`L` is its links
/// struct). Mailboxes are FIFO, so it is handled before anything sent after it.
pub struct Connect<L>(pub L);

impl<L: 'static> Message for Connect<L> {
    type Result = ();
}

/// Tests and fault scenarios: make a child fail, as a crash would.
#[derive(Message, Clone, Copy, Debug, PartialEq, Eq)]
#[rtype(result = "()")]
pub enum InjectFailure {
    /// The child stops.
    Stop,
    /// A handler panics (contained: the child restarts, the process and the map survive).
    Panic,
}

/// Supervisor → child: the robot is going down (a simulated crash, or shutdown). The child drops
/// its links, so that the tree's actors stop once nothing addresses them.
#[derive(Message, Clone, Copy, Debug, PartialEq, Eq)]
#[rtype(result = "()")]
pub struct Halt;

/// → child: a copy of its state `S` for a snapshot (freeze). Sent along the pipeline (Tracker,
/// Matcher, Optimiser, Comms) so that what one child passed downstream before it was frozen is
/// in the next one's state when that is frozen.
pub struct Freeze<S>(pub std::marker::PhantomData<S>);

impl<S> Default for Freeze<S> {
    fn default() -> Self {
        Self(std::marker::PhantomData)
    }
}

impl<S: 'static> Message for Freeze<S> {
    type Result = S;
}

/// Supervisor → Tracker, after a thaw: hand the restored map to the Matcher (every keyframe's
/// scan, the objects) and to Comms (the objects), as if it had just been built.
#[derive(Message, Clone, Copy, Debug, PartialEq, Eq)]
#[rtype(result = "()")]
pub struct Republish;
