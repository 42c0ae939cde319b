//! The scene graph of one robot (paper §IV-A, Fig. 1).
//!
//! Three layers and the links between them:
//! * **keyframe layer**: keyframes (id, stamp, `world_from_body` pose) joined by odometry, intra-robot
//!   loop and inter-robot edges;
//! * **object layer**: objects (id, label, centroid, size) joined by edges weighted by centroid
//!   distance (a fully connected graph, computed from the current positions on demand);
//! * **semantic layer**: the labelled point cloud of each keyframe, held within a byte budget
//!   (`cloud_store`: old scans are compacted, then evicted).
//!
//! Cross-layer links: an object knows the keyframes that observed it; a keyframe knows the objects
//! it observed and owns its semantic scan. An object's centroid is stored in the body frame of the
//! *latest* keyframe that observed it, so when a loop closure moves keyframes, objects follow
//! (§IV-A: "object positions are also sequentially updated based on the latest keyframe that
//! observes each object").

pub mod cloud_store;
mod error;
mod graph;
mod ids;
mod keyframe;
mod object;
mod semantic;

pub use cloud_store::{CloudStoreConfig, CloudStoreStats, KeyframeCloudStore};
pub use error::SceneGraphError;
pub use graph::SceneGraph;
pub use ids::{KeyframeId, LabelId, ObjectId, RobotId};
pub use keyframe::{nanos_from_stamp, stamp_from_nanos, Keyframe, KeyframeEdge, KeyframeEdgeKind, KeyframeRef, Stamp};
pub use object::{Object, ObjectEdge};
pub use semantic::{LabelledVoxels, SemanticScan};
