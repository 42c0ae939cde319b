//! `sgm-model`: the science of SGM, a distributed multi-robot SLAM framework built on scene-graph
//! matching (Huang et al., *SGM-SLAM*, `paper/sgm-slam.tex`).
//!
//! Everything here is pure, synchronous and deterministic: no actors, no ROS, no I/O beyond parsing
//! byte buffers. The crate layering and naming follow `DESIGN.md`: transforms are `a_from_b`, the
//! paper's α is `local`, β is `remote`.
//!
//! - [`geometry`]: rigid transforms and weighted rigid fits (planar and 3D).
//! - [`scene_graph`]: keyframe, object and semantic layers with their cross-layer links (§IV-A).
//! - [`matching`]: object-graph matching and transform estimation (§IV-B, §IV-C, eqs. 5–8).
//! - [`eval`]: metrics and the paper's synthetic matching protocol (§V-A).
//! - [`snapshot`]: the versioned, checksummed frame of map snapshots on disk.

pub mod eval;
pub mod geometry;
pub mod matching;
pub mod optim;
pub mod pcd;
pub mod perception;
pub mod scene_graph;
pub mod snapshot;
pub mod wire;
