//! `sensor_msgs/PointCloud2` ↔ points. In: any field layout with `x`, `y`, `z` as float32 (or
//! float64) — Velodyne's (x y z intensity ring time), Livox's (x y z intensity tag line
//! timestamp), Ouster's — either byte order, organised or not; points with a non-finite
//! coordinate are dropped (organised clouds mark missing returns with NaN). An optional integer
//! label field gives per-point classes ([`NO_LABEL`] or any value outside the class table:
//! unlabelled). Out: x y z float32, label uint16, and a packed `rgb` float32 that RViz colours by.
//!
//! `read.rs` reads a cloud into a [`Scan`], `write.rs` builds clouds (ours, and the semantic
//! map), `datatypes.rs` holds PointField's datatypes.

mod datatypes;
mod read;
mod write;

/// The label value meaning "no class" in our clouds and label images.
pub const NO_LABEL: u16 = u16::MAX;

pub use read::{read_cloud, Scan};
pub use write::{cloud_msg, semantic_map, voxels_msg, with_times};
