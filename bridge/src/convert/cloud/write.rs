//! Clouds out: ours (x y z float32, label uint16 and a packed `rgb` float32 that RViz colours
//! by), and the semantic map as one.

use super::datatypes::{FLOAT32, UINT16};
use super::NO_LABEL;
use crate::msg::{sensor_msgs, std_msgs};
use nalgebra::Point3;

pub(super) fn point_field(name: &str, offset: u32, datatype: u8) -> sensor_msgs::PointField {
    sensor_msgs::PointField { name: name.into(), offset, datatype, count: 1 }
}

/// Packs an RGB colour the way PCL and RViz read an `rgb` float32 field.
fn packed_rgb([r, g, b]: [u8; 3]) -> f32 {
    f32::from_bits((u32::from(r) << 16) | (u32::from(g) << 8) | u32::from(b))
}

/// `cloud` with each point's time appended as a float32 `time` field, seconds after the
/// header's stamp (velodyne_pointcloud's and LIO-SAM's convention, read back by `read_cloud`).
/// `times` shorter than the cloud leaves the rest at 0.
pub fn with_times(mut cloud: sensor_msgs::PointCloud2, times: &[f32]) -> sensor_msgs::PointCloud2 {
    let step = cloud.point_step as usize;
    let mut data = Vec::with_capacity(cloud.data.len() + 4 * times.len());
    for (k, point) in cloud.data.chunks_exact(step.max(1)).enumerate() {
        data.extend_from_slice(point);
        data.extend_from_slice(&times.get(k).copied().unwrap_or(0.0).to_le_bytes());
    }
    cloud.fields.push(point_field("time", cloud.point_step, FLOAT32));
    cloud.point_step += 4;
    cloud.row_step = cloud.point_step * cloud.width;
    cloud.data = data;
    cloud
}

/// An unorganised little-endian cloud: x y z float32, plus `label` uint16 and `rgb` (from
/// `colour_of(label)`) when labels are given.
pub fn cloud_msg(
    header: std_msgs::Header,
    points: &[Point3<f32>],
    labels: Option<&[u16]>,
    colour_of: impl Fn(u16) -> [u8; 3],
) -> sensor_msgs::PointCloud2 {
    let mut fields = vec![point_field("x", 0, FLOAT32), point_field("y", 4, FLOAT32), point_field("z", 8, FLOAT32)];
    let point_step = if labels.is_some() {
        fields.push(point_field("rgb", 12, FLOAT32));
        fields.push(point_field("label", 16, UINT16));
        20
    } else {
        12
    };
    let mut data = Vec::with_capacity(points.len() * point_step);
    for (k, p) in points.iter().enumerate() {
        for v in [p.x, p.y, p.z] {
            data.extend_from_slice(&v.to_le_bytes());
        }
        if let Some(labels) = labels {
            let label = labels.get(k).copied().unwrap_or(NO_LABEL);
            data.extend_from_slice(&packed_rgb(colour_of(label)).to_le_bytes());
            data.extend_from_slice(&label.to_le_bytes());
            data.extend_from_slice(&[0, 0]);
        }
    }
    sensor_msgs::PointCloud2 {
        header,
        height: 1,
        width: points.len() as u32,
        fields,
        is_bigendian: false,
        point_step: point_step as u32,
        row_step: (points.len() * point_step) as u32,
        data,
        is_dense: true,
    }
}

/// The semantic map: the keyframes' labelled points of `graphs`, each placed in the header's
/// frame by its `frame_from_graph` (the identity for the robot's own), one point per `voxel_m`
/// voxel (the first label), coloured by class.
pub fn semantic_map(
    header: &std_msgs::Header,
    graphs: &[(&sgm_model::scene_graph::SceneGraph, sgm_model::geometry::Pose3)],
    classes: &sgm_model::perception::classes::ClassTable,
    voxel_m: f64,
) -> sensor_msgs::PointCloud2 {
    let mut voxels = sgm_model::scene_graph::LabelledVoxels::new(voxel_m);
    for (graph, frame_from_graph) in graphs {
        voxels.insert_graph(graph, frame_from_graph);
    }
    voxels_msg(header, &voxels, classes)
}

/// Labelled voxels as a cloud in the header's frame, coloured by class.
pub fn voxels_msg(
    header: &std_msgs::Header,
    voxels: &sgm_model::scene_graph::LabelledVoxels,
    classes: &sgm_model::perception::classes::ClassTable,
) -> sensor_msgs::PointCloud2 {
    let (points, labels): (Vec<_>, Vec<_>) = voxels.points().map(|(p, l)| (p.cast::<f32>(), l.0)).unzip();
    let colour = |l: u16| classes.get(sgm_model::scene_graph::LabelId(l)).map_or([128, 128, 128], |c| c.colour);
    cloud_msg(header.clone(), &points, Some(&labels), colour)
}
