//! `sgm-model`: the science of SGM, a distributed multi-robot SLAM framework built on scene-graph
//! matching (Huang et al., *SGM-SLAM*, `paper/sgm-slam.tex`).
//!
//! Everything here is pure, synchronous and deterministic: no actors, no ROS, no I/O beyond parsing
//! byte buffers. The crate layering and naming follow `DESIGN.md`: transforms are `a_from_b`, the
//! paper's α is `local`, β is `remote`.
//!
//! The modules, lowest first; each uses only those above it in this list (the book's
//! architecture chapter draws it):
//! - [`geometry`]: rigid transforms, weighted rigid fits (planar and 3D), and SE(2)/SE(3) as Lie
//!   groups (`geometry::lie`); beside it [`workers`]: threads a function may split independent
//!   work over, with the same answer for any number.
//! - [`spatial`]: kd-tree, voxel grid and linear assignment, for the layers below.
//! - [`scene_graph`]: keyframe, object and semantic layers with their cross-layer links (§IV-A).
//! - [`perception`]: segmentation to objects, keyframes, the object tracker, ICP (§IV-A, §IV-E).
//! - [`matching`]: object-graph matching and transform estimation (§IV-B, §IV-C, eqs. 5–8), and
//!   the keyframe alignment that confirms it (§IV-D).
//! - [`odometry`]: the LiDAR-inertial front end's parts (local map, adaptive threshold,
//!   scan-to-map registration with a prior and degeneracy, IMU propagation).
//! - [`optim`]: the pose-graph solver on faer (§IV-F); [`wire`]: the radio protocol;
//!   [`eval`]: metrics and the paper's synthetic matching protocol (§V-A); [`pcd`], [`snapshot`]:
//!   file formats.
//!

pub mod eval;
pub mod geometry;
pub mod matching;
pub mod odometry;
pub mod optim;
pub mod pcd;
pub mod perception;
pub mod scene_graph;
pub mod snapshot;
pub mod spatial;
pub mod wire;
pub mod workers;
