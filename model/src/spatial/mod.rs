//! Spatial helpers the layers above share: a kd-tree over points (`point_tree`, on kiddo) and the
//! k-nearest graph over it that answers ICP's repeated searches (`neighbour_graph`), the cells
//! within a radius of a cloud that let those searches skip far queries (`reach`), a
//! voxel-grid downsampler (`voxel`) and the linear assignment problem (`lap`, Jonker–Volgenant).
//! They know nothing of maps, robots or matching: `scene_graph`, `perception` and `matching`
//! use them, never the other way round.

pub mod lap;
pub mod neighbour_graph;
pub mod point_tree;
pub mod reach;
pub mod voxel;
