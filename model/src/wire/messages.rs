//! The inter-robot messages (paper §IV-B..F, Table 4), as compact serde types for postcard.
//!
//! | message | when | content |
//! |---|---|---|
//! | `ObjectData` | scene-graph change, rate-limited | objects: id, label, quantised centroid, size |
//! | `ObjectCloudRequest` / `Response` | after a match | sparse object clouds + observing keyframe ids |
//! | `KeyframeRequest` / `Response` | for keyframes not yet held | compressed cloud, pose, covariance |
//! | `KeyframeRefusal` | a request the sender cannot serve now | the keyframe ids and why |
//! | `KeyframeDescriptors` | new keyframes, with `matcher.association = "scan_context"` only | Scan Context descriptors and poses (the evaluation's Swarm-SC baseline) |
//! | `Alignments` | an alignment made or moved, rate-limited | the sender's transform to each neighbour it is aligned with (hints, checked by the receiver) |
//! | `KeyframePoses` | keyframes served earlier moved in the sender's solves, rate-limited | their new poses (the receiver's priors take them) |
//! | `GraphFactorRequest` | with `optimiser.share_factors`, every `share_period_s` while aligned | the position in the sender's factor log to read from |
//! | `GraphFactors` | in reply | that part of the sender's factor log: its keyframes and the factors of its own measurements |
//!
//! Centroids travel as integers in units of `resolution_mm` (zigzag varints under postcard: two
//! bytes per axis within ±163 m at 2 cm), sizes as bytes in 5 cm steps: an object costs 9–13
//! bytes. Clouds are [`super::cloud_codec`] streams.

use crate::geometry::Pose3;
use crate::matching::scan_context::ScanContext;
use crate::scene_graph::{KeyframeId, LabelId, ObjectId, RobotId};
use nalgebra::{Matrix6, Point3, Quaternion, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// Message type, for accounting and limits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum MessageKind {
    ObjectData,
    ObjectCloudRequest,
    ObjectCloudResponse,
    KeyframeRequest,
    KeyframeResponse,
    KeyframeRefusal,
    KeyframeDescriptors,
    Alignments,
    KeyframePoses,
    GraphFactorRequest,
    GraphFactors,
}

impl MessageKind {
    pub const ALL: [MessageKind; 11] = [
        MessageKind::ObjectData,
        MessageKind::ObjectCloudRequest,
        MessageKind::ObjectCloudResponse,
        MessageKind::KeyframeRequest,
        MessageKind::KeyframeResponse,
        MessageKind::KeyframeRefusal,
        MessageKind::KeyframeDescriptors,
        MessageKind::Alignments,
        MessageKind::KeyframePoses,
        MessageKind::GraphFactorRequest,
        MessageKind::GraphFactors,
    ];

    pub fn name(self) -> &'static str {
        match self {
            MessageKind::ObjectData => "ObjectData",
            MessageKind::ObjectCloudRequest => "ObjectCloudRequest",
            MessageKind::ObjectCloudResponse => "ObjectCloudResponse",
            MessageKind::KeyframeRequest => "KeyframeRequest",
            MessageKind::KeyframeResponse => "KeyframeResponse",
            MessageKind::KeyframeRefusal => "KeyframeRefusal",
            MessageKind::KeyframeDescriptors => "KeyframeDescriptors",
            MessageKind::Alignments => "Alignments",
            MessageKind::KeyframePoses => "KeyframePoses",
            MessageKind::GraphFactorRequest => "GraphFactorRequest",
            MessageKind::GraphFactors => "GraphFactors",
        }
    }
}

/// Every message that crosses the radio.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Message {
    ObjectData(ObjectData),
    ObjectCloudRequest(ObjectCloudRequest),
    ObjectCloudResponse(ObjectCloudResponse),
    KeyframeRequest(KeyframeRequest),
    KeyframeResponse(KeyframeResponse),
    KeyframeRefusal(KeyframeRefusal),
    KeyframeDescriptors(KeyframeDescriptors),
    Alignments(Alignments),
    KeyframePoses(KeyframePoses),
    GraphFactorRequest(GraphFactorRequest),
    GraphFactors(GraphFactors),
}

impl Message {
    pub fn kind(&self) -> MessageKind {
        match self {
            Message::ObjectData(_) => MessageKind::ObjectData,
            Message::ObjectCloudRequest(_) => MessageKind::ObjectCloudRequest,
            Message::ObjectCloudResponse(_) => MessageKind::ObjectCloudResponse,
            Message::KeyframeRequest(_) => MessageKind::KeyframeRequest,
            Message::KeyframeResponse(_) => MessageKind::KeyframeResponse,
            Message::KeyframeRefusal(_) => MessageKind::KeyframeRefusal,
            Message::KeyframeDescriptors(_) => MessageKind::KeyframeDescriptors,
            Message::Alignments(_) => MessageKind::Alignments,
            Message::KeyframePoses(_) => MessageKind::KeyframePoses,
            Message::GraphFactorRequest(_) => MessageKind::GraphFactorRequest,
            Message::GraphFactors(_) => MessageKind::GraphFactors,
        }
    }
}

/// Step of the size field, m.
pub const SIZE_STEP_M: f64 = 0.05;

/// The sender's object layer, confirmed objects only, in the sender's world frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectData {
    /// Increases with every broadcast of this sender: a receiver ignores older ones.
    pub revision: u32,
    /// Centroid quantum, millimetres (≥ 1).
    pub resolution_mm: u16,
    pub objects: Vec<WireObject>,
}

/// One object of `ObjectData`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct WireObject {
    pub id: ObjectId,
    pub label: LabelId,
    /// Centroid in units of the message's `resolution_mm`.
    pub centroid: [i32; 3],
    /// Extent per world axis in steps of [`SIZE_STEP_M`], saturating at 255 (12.75 m).
    pub size: [u8; 3],
}

impl ObjectData {
    /// Quantises `(id, label, centroid_in_world, size)` at `resolution_mm`. Centroids beyond
    /// ±2³¹ quanta (±21 000 km at 1 cm) saturate.
    pub fn quantise<'a>(
        revision: u32,
        resolution_mm: u16,
        objects: impl IntoIterator<Item = (ObjectId, LabelId, Point3<f64>, Vector3<f64>)> + 'a,
    ) -> Self {
        let resolution_mm = resolution_mm.max(1);
        let r = f64::from(resolution_mm) * 1e-3;
        let objects = objects
            .into_iter()
            .map(|(id, label, c, s)| WireObject {
                id,
                label,
                centroid: [c.x, c.y, c.z].map(|v| (v / r).round().clamp(i32::MIN as f64, i32::MAX as f64) as i32),
                size: [s.x, s.y, s.z].map(|v| (v / SIZE_STEP_M).round().clamp(0.0, 255.0) as u8),
            })
            .collect();
        Self { revision, resolution_mm, objects }
    }
}

impl WireObject {
    pub fn centroid_m(&self, resolution_mm: u16) -> Point3<f64> {
        let r = f64::from(resolution_mm.max(1)) * 1e-3;
        Point3::new(f64::from(self.centroid[0]) * r, f64::from(self.centroid[1]) * r, f64::from(self.centroid[2]) * r)
    }

    pub fn size_m(&self) -> Vector3<f64> {
        Vector3::new(f64::from(self.size[0]), f64::from(self.size[1]), f64::from(self.size[2])) * SIZE_STEP_M
    }
}

/// Ask for the sparse clouds of matched objects.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ObjectCloudRequest {
    pub objects: Vec<ObjectId>,
}

/// The requested objects' clouds (sender's world frame) and the keyframes that observed them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectCloudResponse {
    pub objects: Vec<ObjectCloud>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectCloud {
    pub id: ObjectId,
    pub keyframes: Vec<KeyframeId>,
    /// A [`super::cloud_codec`] stream; empty when the object has no stored points.
    #[serde(with = "serde_bytes")]
    pub cloud: Vec<u8>,
}

/// Ask for keyframes not yet held.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct KeyframeRequest {
    pub keyframes: Vec<KeyframeId>,
}

/// One keyframe: its cloud (body frame), optimised pose and marginal covariance.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KeyframeResponse {
    pub keyframe: KeyframeId,
    pub stamp: f64,
    pub world_from_body: WirePose,
    /// Upper triangle, row-major, of the 6 × 6 marginal covariance over (ω, v).
    pub covariance: [f32; 21],
    #[serde(with = "serde_bytes")]
    pub cloud: Vec<u8>,
}

/// Requested keyframes the sender will not serve now.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct KeyframeRefusal {
    pub keyframes: Vec<KeyframeId>,
    pub reason: KeyframeRefusalReason,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum KeyframeRefusalReason {
    /// No such keyframe, or its cloud was evicted.
    Unknown,
    /// The sender's outgoing budget is spent: ask again later.
    Busy,
}

/// Step of a descriptor's heights, m (a byte each: up to 25.5 m).
pub const DESCRIPTOR_HEIGHT_STEP_M: f32 = 0.1;

/// Scan Context descriptors of the sender's keyframes (the Swarm-SC baseline's association).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KeyframeDescriptors {
    pub descriptors: Vec<WireDescriptor>,
}

/// One keyframe's descriptor: its pose in the sender's world, and rings × sectors heights in
/// steps of [`DESCRIPTOR_HEIGHT_STEP_M`], ring-major.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireDescriptor {
    pub keyframe: KeyframeId,
    pub world_from_body: WirePose,
    pub rings: u8,
    pub sectors: u8,
    #[serde(with = "serde_bytes")]
    pub cells: Vec<u8>,
}

impl WireDescriptor {
    /// Quantises `descriptor` (heights saturate at 25.5 m; shapes beyond 255 rings or sectors
    /// are cut to 255).
    pub fn quantise(keyframe: KeyframeId, world_from_body: &Pose3, descriptor: &ScanContext) -> Self {
        let (rings, sectors) = (descriptor.rings.min(255), descriptor.sectors.min(255));
        let cells = (0..rings)
            .flat_map(|r| (0..sectors).map(move |j| (r, j)))
            .map(|(r, j)| (descriptor.cell(r, j) / DESCRIPTOR_HEIGHT_STEP_M).round().clamp(0.0, 255.0) as u8)
            .collect();
        Self { keyframe, world_from_body: world_from_body.into(), rings: rings as u8, sectors: sectors as u8, cells }
    }

    /// The descriptor back; `None` when the cells do not fill rings × sectors.
    pub fn descriptor(&self) -> Option<ScanContext> {
        let (rings, sectors) = (usize::from(self.rings), usize::from(self.sectors));
        (self.cells.len() == rings * sectors).then(|| ScanContext {
            rings,
            sectors,
            cells: self.cells.iter().map(|&c| f32::from(c) * DESCRIPTOR_HEIGHT_STEP_M).collect(),
        })
    }
}

/// The sender's alignments: for each neighbour whose map it has placed in its own by its own
/// registration, the transform from that neighbour's world into the sender's. A receiver takes
/// them as hints only — inverted (the sender placed the receiver) or chained through its own
/// alignment with the sender (the sender placed a third robot) — and registers before anything
/// counts (`actors::matcher::relay`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Alignments {
    pub alignments: Vec<WireAlignment>,
}

/// One of the sender's alignments.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireAlignment {
    /// The neighbour placed.
    pub robot: RobotId,
    /// Its world in the sender's.
    pub sender_from_robot: WirePose,
}

/// The sender's current estimates of keyframes it served to the receiver earlier, which its own
/// solves have since moved (`actors::comms::served`). The receiver's pose graph ties each
/// neighbour keyframe to the neighbour's anchor by the neighbour's estimate of it: a stale one
/// would pull the anchor by the neighbour's later corrections. The receiver replaces the mean
/// of the prior of each keyframe it holds and ignores the others.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KeyframePoses {
    pub poses: Vec<WireKeyframePose>,
}

/// A keyframe's pose in the sender's world, in single precision: translation (m) and rotation
/// vector (rad, the logarithm of the rotation). 24 bytes and the id's varint: within 0.1 mm and
/// about 0.1 µrad per axis within 1 km of the origin.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireKeyframePose {
    pub keyframe: KeyframeId,
    pub translation: [f32; 3],
    pub rotation: [f32; 3],
}

impl WireKeyframePose {
    pub fn new(keyframe: KeyframeId, world_from_body: &Pose3) -> Self {
        let t = world_from_body.translation.vector;
        let r = world_from_body.rotation.scaled_axis();
        Self {
            keyframe,
            translation: [t.x as f32, t.y as f32, t.z as f32],
            rotation: [r.x as f32, r.y as f32, r.z as f32],
        }
    }

    /// `None` unless every component is finite.
    pub fn to_pose(&self) -> Option<Pose3> {
        if !self.translation.iter().chain(&self.rotation).all(|v| v.is_finite()) {
            return None;
        }
        let [tx, ty, tz] = self.translation.map(f64::from);
        let [rx, ry, rz] = self.rotation.map(f64::from);
        Some(Pose3::from_parts(
            Translation3::new(tx, ty, tz),
            UnitQuaternion::from_scaled_axis(Vector3::new(rx, ry, rz)),
        ))
    }
}

/// Ask a neighbour for the factors of its own pose graph from position `from` of its factor
/// log on (`optim::shared_factors`). The receiver of the reply asks again from the reply's
/// `next`: a request or reply lost on the radio is asked again at the next period, so nothing
/// is missed and nothing is sent twice but for a retry.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct GraphFactorRequest {
    pub from: u32,
}

/// Part of the sender's factor log, from position `from` up to `next` (where to ask next;
/// `next == from`: nothing new): the sender's keyframes that entered its graph there, with
/// their poses in its world now, and the factors of its own measurements — odometry, loop
/// closures, and its inter-robot factors to the receiver (factors to third robots are not
/// sent). The receiver's pose graph holds them as the sender's own chain of keyframes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GraphFactors {
    pub from: u32,
    pub next: u32,
    pub keyframes: Vec<WireGraphKeyframe>,
    pub factors: Vec<WireFactor>,
}

/// A keyframe of the sender's pose graph: its pose in the sender's world now, and, in
/// gravity-aligned worlds, the world's up in its body as the sender's odometry measured it
/// (unit vector; what the sender's gravity prior holds it to).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireGraphKeyframe {
    pub pose: WireKeyframePose,
    pub up: Option<[f32; 3]>,
}

/// What a shared factor measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum WireFactorKind {
    Odometry,
    Loop,
    /// To a keyframe of the receiver.
    InterRobot,
}

/// One between factor of the sender's graph: `measured` = from_body_from_to_body, with its
/// information matrix Ω. `from` is the sender's keyframe; `to` the sender's too, or the
/// receiver's for an inter-robot factor. 1 + two id varints + 24 bytes + the information's
/// 1, 25 or 85.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireFactor {
    pub kind: WireFactorKind,
    pub from: KeyframeId,
    pub to: KeyframeId,
    pub translation: [f32; 3],
    pub rotation: [f32; 3],
    pub information: WireInformation,
}

/// An information matrix Ω over (ω, v): odometry's is mostly the same diagonal from factor to
/// factor, and costs a byte then.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum WireInformation {
    /// The previous factor's of the same message.
    Previous,
    /// Diagonal.
    Diagonal([f32; 6]),
    /// Upper triangle, row-major, as [`pack_covariance`] packs.
    Full([f32; 21]),
}

impl WireInformation {
    /// Ω as compactly as it goes, given the previous factor's in the message.
    pub fn pack(information: &Matrix6<f64>, previous: Option<&Matrix6<f64>>) -> Self {
        if previous.is_some_and(|p| pack_covariance(p) == pack_covariance(information)) {
            return Self::Previous;
        }
        if (0..6).all(|i| (0..6).all(|j| i == j || information[(i, j)] == 0.0)) {
            return Self::Diagonal(std::array::from_fn(|i| information[(i, i)] as f32));
        }
        Self::Full(pack_covariance(information))
    }

    /// Ω (the previous factor's for `Previous`); `None` unless finite and symmetric positive
    /// definite, or for `Previous` without a previous factor.
    pub fn unpack(&self, previous: Option<&Matrix6<f64>>) -> Option<Matrix6<f64>> {
        match self {
            Self::Previous => previous.copied(),
            Self::Diagonal(d) => {
                let mut packed = [0f32; 21];
                let mut k = 0;
                for (i, v) in d.iter().enumerate() {
                    packed[k] = *v;
                    k += 6 - i;
                }
                unpack_covariance(&packed)
            }
            Self::Full(packed) => unpack_covariance(packed),
        }
    }
}

impl WireFactor {
    pub fn new(
        kind: WireFactorKind,
        from: KeyframeId,
        to: KeyframeId,
        measured: &Pose3,
        information: WireInformation,
    ) -> Self {
        let p = WireKeyframePose::new(to, measured);
        Self { kind, from, to, translation: p.translation, rotation: p.rotation, information }
    }

    /// The measured pose; `None` unless finite.
    pub fn measured(&self) -> Option<Pose3> {
        WireKeyframePose { keyframe: self.to, translation: self.translation, rotation: self.rotation }.to_pose()
    }
}

/// A pose as translation and unit quaternion (x, y, z, w).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WirePose {
    pub translation: [f64; 3],
    pub rotation: [f64; 4],
}

impl From<&Pose3> for WirePose {
    fn from(p: &Pose3) -> Self {
        let q = p.rotation.quaternion();
        Self { translation: [p.translation.x, p.translation.y, p.translation.z], rotation: [q.i, q.j, q.k, q.w] }
    }
}

impl WirePose {
    /// `None` unless finite with a quaternion of norm 1 ± 1e-6.
    pub fn to_pose(&self) -> Option<Pose3> {
        let [x, y, z, w] = self.rotation;
        let q = Quaternion::new(w, x, y, z);
        let finite = self.translation.iter().chain(&self.rotation).all(|v| v.is_finite());
        if !finite || (q.norm() - 1.0).abs() > 1e-6 {
            return None;
        }
        let [tx, ty, tz] = self.translation;
        Some(Pose3::from_parts(Translation3::new(tx, ty, tz), UnitQuaternion::from_quaternion(q)))
    }
}

/// Packs the upper triangle of a symmetric 6 × 6 matrix.
pub fn pack_covariance(m: &Matrix6<f64>) -> [f32; 21] {
    let mut out = [0f32; 21];
    let mut k = 0;
    for i in 0..6 {
        for j in i..6 {
            out[k] = m[(i, j)] as f32;
            k += 1;
        }
    }
    out
}

/// The symmetric matrix whose upper triangle [`pack_covariance`] packed, unchecked: for data
/// this process packed itself (`pack_covariance(&expand_covariance(&p)) == p`).
pub fn expand_covariance(packed: &[f32; 21]) -> Matrix6<f64> {
    let mut m = Matrix6::zeros();
    let mut k = 0;
    for i in 0..6 {
        for j in i..6 {
            m[(i, j)] = f64::from(packed[k]);
            m[(j, i)] = f64::from(packed[k]);
            k += 1;
        }
    }
    m
}

/// Unpacks [`pack_covariance`] from outside; `None` unless finite, symmetric positive definite
/// (also an information matrix, which [`WireFactor`] packs the same way).
pub fn unpack_covariance(packed: &[f32; 21]) -> Option<Matrix6<f64>> {
    let m = expand_covariance(packed);
    (m.iter().all(|v| v.is_finite()) && m.cholesky().is_some()).then_some(m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_rpy_translation;

    #[test]
    fn quantised_objects_round_trip_within_half_a_quantum() {
        let objects = [
            (ObjectId(3), LabelId(2), Point3::new(12.345, -70.011, 0.4), Vector3::new(0.5, 0.6, 1.2)),
            (ObjectId(400), LabelId(7), Point3::new(-150.0, 149.99, -2.0), Vector3::new(20.0, 0.01, 0.0)),
        ];
        let data = ObjectData::quantise(1, 20, objects);
        for ((_, _, c, s), w) in objects.iter().zip(&data.objects) {
            assert!((w.centroid_m(20) - c).abs().max() <= 0.01 + 1e-12);
            assert!((w.size_m() - s).abs().max() <= 0.025 + 1e-12 || s.max() > 12.75);
        }
        assert_eq!(data.objects[1].size, [255, 0, 0]);
    }

    #[test]
    fn descriptors_round_trip_within_half_a_step() {
        let points: Vec<Point3<f64>> = (0..400)
            .map(|k| Point3::new((k % 37) as f64 - 18.0, (k % 23) as f64 - 11.0, (k % 7) as f64 * 0.37))
            .collect();
        let descriptor = ScanContext::new(&points, &Default::default());
        let pose = pose_from_rpy_translation(0.0, 0.0, 1.0, Vector3::new(3.0, 4.0, 0.0));
        let wire = WireDescriptor::quantise(KeyframeId(9), &pose, &descriptor);
        assert_eq!(wire.cells.len(), 20 * 60);
        let back = wire.descriptor().unwrap();
        assert!(back.cells.iter().zip(&descriptor.cells).all(|(a, b)| (a - b).abs() <= 0.05 + 1e-6));
        assert!(back.compare(&descriptor).distance < 1e-3);
        let mut short = wire.clone();
        short.cells.pop();
        assert_eq!(short.descriptor(), None, "cells that do not fill the shape are refused");
    }

    #[test]
    fn poses_and_covariances_round_trip() {
        let pose = pose_from_rpy_translation(0.1, -0.2, 2.5, Vector3::new(1.0, -2.0, 0.3));
        let back = WirePose::from(&pose).to_pose().unwrap();
        assert!((back.to_homogeneous() - pose.to_homogeneous()).abs().max() < 1e-12);
        let bad = WirePose { translation: [0.0; 3], rotation: [0.0, 0.0, 0.0, 2.0] };
        assert_eq!(bad.to_pose(), None);
        let a = Matrix6::<f64>::from_fn(|i, j| ((i * 7 + j * 3) % 5) as f64 * 0.1);
        let cov = a * a.transpose() + Matrix6::identity() * 0.01;
        let unpacked = unpack_covariance(&pack_covariance(&cov)).unwrap();
        assert!((unpacked - cov).abs().max() < 1e-6);
        assert_eq!(unpack_covariance(&[0.0; 21]), None);
        let packed = pack_covariance(&cov);
        assert_eq!(pack_covariance(&expand_covariance(&packed)), packed);
        assert_eq!(expand_covariance(&packed).transpose(), expand_covariance(&packed));
    }

    #[test]
    fn keyframe_poses_round_trip_in_single_precision() {
        for (roll, pitch, yaw) in [(0.0, 0.0, 0.0), (0.1, -0.2, 2.5), (0.0, 0.0, std::f64::consts::PI - 1e-9)] {
            let pose = pose_from_rpy_translation(roll, pitch, yaw, Vector3::new(812.3, -640.25, 31.7));
            let wire = WireKeyframePose::new(KeyframeId(7), &pose);
            let back = wire.to_pose().unwrap();
            let dt = (pose.translation.vector - back.translation.vector).norm();
            let dr = (pose.rotation.inverse() * back.rotation).angle();
            assert!(dt < 1e-4 && dr < 1e-6, "{dt} m, {dr} rad");
        }
        let bad = WireKeyframePose { keyframe: KeyframeId(1), translation: [f32::NAN, 0.0, 0.0], rotation: [0.0; 3] };
        assert_eq!(bad.to_pose(), None);
        let bytes = postcard::to_allocvec(&KeyframePoses {
            poses: vec![WireKeyframePose::new(KeyframeId(300), &Pose3::identity())],
        })
        .unwrap();
        assert_eq!(bytes.len(), 1 + 2 + 24, "count, id varint, six f32");
    }
}
