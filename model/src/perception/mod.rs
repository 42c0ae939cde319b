//! Perception (paper §IV-A, §IV-D): what a robot does to its own scans — voxel downsampling,
//! kd-tree, normals, ICP, camera projection (semantic fusion), class table, segmenter tables and
//! the map from their pixel values to classes, clustering, keyframe selection, object tracking,
//! intra-robot loop closure.

pub mod ceiling;
pub mod classes;
pub mod clustering;
pub mod colour_ids;
pub mod deskew;
pub mod ground;
pub mod icp;
pub mod imu;
pub mod keyframes;
pub mod label_map;
pub mod label_vote;
pub mod level_icp;
pub mod loop_closure;
pub mod mapper;
pub mod motion;
pub mod normals;
pub mod object_cloud;
pub mod palettes;
pub mod projection;
pub mod scan_fusion;
pub mod segmenters;
pub mod structure_check;
pub mod synthetic_room;
pub mod tracker;
