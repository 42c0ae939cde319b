//! An object's sparse cloud (paper §IV-D, ObjectCloudResponse): the points of its class, from
//! the keyframes that observed it, inside its box grown by a margin, in the world frame, voxel
//! downsampled.

use crate::geometry::Pose3;
use crate::scene_graph::LabelId;
use crate::spatial::voxel::downsample;
use nalgebra::{Point3, Vector3};

/// Object clouds are built from at most this many keyframes that saw the object — the latest:
/// the cloud is a sparse sample for ICP (paper §IV-D), and an object seen for minutes would
/// otherwise cost a pass over every scan that saw it.
pub const MAX_VIEWS: usize = 8;

/// The label of points that belong to no class.
pub const UNLABELLED: LabelId = LabelId(u16::MAX);

/// Points of `label` within `margin_m` of the box (`centroid`, `size`) from `scans`
/// (world_from_body, points in body, labels), downsampled at `voxel_m`.
pub fn object_cloud<'a>(
    scans: impl IntoIterator<Item = (&'a Pose3, &'a [Point3<f32>], &'a [LabelId])>,
    label: LabelId,
    centroid: &Point3<f64>,
    size: &Vector3<f64>,
    margin_m: f64,
    voxel_m: f64,
) -> Vec<Point3<f64>> {
    let half = size / 2.0 + Vector3::repeat(margin_m);
    let mut out = Vec::new();
    for (world_from_body, points, labels) in scans {
        for (p, l) in points.iter().zip(labels) {
            if *l != label {
                continue;
            }
            let w = world_from_body * p.cast::<f64>();
            let d = w - centroid;
            if d.x.abs() <= half.x && d.y.abs() <= half.y && d.z.abs() <= half.z {
                out.push(w);
            }
        }
    }
    downsample(&out, voxel_m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_the_class_inside_the_grown_box() {
        let pose = Pose3::translation(10.0, 0.0, 0.0);
        let pts = [
            Point3::new(0.0f32, 0.0, 0.0),
            Point3::new(0.9, 0.0, 0.0),
            Point3::new(3.0, 0.0, 0.0),
            Point3::new(0.1, 0.0, 0.0),
        ];
        let labels = [LabelId(4), LabelId(4), LabelId(4), LabelId(5)];
        let cloud = object_cloud(
            [(&pose, &pts[..], &labels[..])],
            LabelId(4),
            &Point3::new(10.0, 0.0, 0.0),
            &Vector3::new(1.0, 1.0, 1.0),
            0.5,
            0.0,
        );
        assert_eq!(cloud, vec![Point3::new(10.0, 0.0, 0.0), Point3::new(10.899999976158142, 0.0, 0.0)]);
    }
}
