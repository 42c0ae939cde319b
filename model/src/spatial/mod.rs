//! Spatial helpers the layers above share: a kd-tree over points (`point_tree`, on kiddo), a
//! voxel-grid downsampler (`voxel`) and the linear assignment problem (`lap`, Jonker–Volgenant).
//! They know nothing of maps, robots or matching: `scene_graph`, `perception` and `matching`
//! use them, never the other way round.

pub mod lap;
pub mod point_tree;
pub mod voxel;
