//! The merged semantic map as a PCD file (x, y, z, label): every keyframe cloud of every robot
//! merged into the team ATE (so aligned with the reference robot), placed by its optimised pose in
//! the reference robot's world, voxel-downsampled to 10 cm (one label per voxel: the first).

use super::figures::reference_from;
use crate::runner::RunOutcome;
use sgm_model::pcd::{write_pcd, DataFormat, FieldKind, PcdField, PointCloud};
use std::collections::BTreeMap;

const VOXEL_M: f64 = 0.1;

pub fn merged_map(outcome: &RunOutcome) -> Vec<u8> {
    let last = outcome.record.observations.last().cloned().unwrap_or_default();
    let mut voxels: BTreeMap<(i64, i64, i64), ([f64; 3], u16)> = BTreeMap::new();
    for (k, map) in outcome.maps.iter().enumerate() {
        let Some(reference_from_robot) = reference_from(&last, k) else { continue };
        for keyframe in map.keyframes() {
            let Some(scan) = map.semantic_scan(keyframe.id) else { continue };
            let pose = reference_from_robot * keyframe.world_from_body;
            for (p, label) in scan.points_in_body.iter().zip(&scan.labels) {
                let w = pose * p.cast::<f64>();
                let key =
                    ((w.x / VOXEL_M).floor() as i64, (w.y / VOXEL_M).floor() as i64, (w.z / VOXEL_M).floor() as i64);
                voxels.entry(key).or_insert(([w.x, w.y, w.z], label.0));
            }
        }
    }
    let float = |name: &str| PcdField { name: name.into(), size: 4, kind: FieldKind::Float, count: 1 };
    let mut columns: Vec<Vec<f64>> = (0..4).map(|_| Vec::with_capacity(voxels.len())).collect();
    for (p, label) in voxels.values() {
        for (c, v) in p.iter().enumerate() {
            columns[c].push(*v);
        }
        columns[3].push(f64::from(*label));
    }
    let cloud = PointCloud {
        fields: vec![
            float("x"),
            float("y"),
            float("z"),
            PcdField { name: "label".into(), size: 2, kind: FieldKind::Unsigned, count: 1 },
        ],
        width: voxels.len(),
        height: 1,
        viewpoint: [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
        columns,
    };
    write_pcd(&cloud, DataFormat::BinaryCompressed)
}
