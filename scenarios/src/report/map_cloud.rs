//! The merged semantic map as a PCD file (x, y, z, label): every keyframe cloud of every robot
//! merged into the team ATE (so aligned with the reference robot), placed by its optimised pose in
//! the reference robot's world, voxel-downsampled to 10 cm (one label per voxel: the first).
//! Each robot's map is voxelised on its own (on the run's `--threads`) and the maps are merged
//! in robot order, which keeps the first point of every voxel as one pass over all would.

use super::figures::reference_from;
use crate::record::RunOutcome;
use rayon::prelude::*;
use sgm_model::pcd::{write_pcd, DataFormat, FieldKind, PcdField, PointCloud};
use sgm_model::scene_graph::{LabelledVoxels, SceneGraph};

const VOXEL_M: f64 = 0.1;

pub fn merged_map(outcome: &RunOutcome) -> Vec<u8> {
    let last = &outcome.record.last;
    let robot_voxels = |(k, map): (usize, &SceneGraph)| {
        reference_from(last, k).map(|reference_from_robot| {
            let mut voxels = LabelledVoxels::new(VOXEL_M);
            voxels.insert_graph(map, &reference_from_robot);
            voxels
        })
    };
    let per_robot: Vec<Option<LabelledVoxels>> = match outcome.threads.pool() {
        Ok(Some(pool)) => pool.install(|| outcome.maps.par_iter().enumerate().map(robot_voxels).collect()),
        Ok(None) => outcome.maps.iter().enumerate().map(robot_voxels).collect(),
        Err(e) => {
            tracing::warn!(
                threads = outcome.threads.get(),
                "map.pcd built on one thread: no pool of {} threads ({e})",
                outcome.threads
            );
            outcome.maps.iter().enumerate().map(robot_voxels).collect()
        }
    };
    let mut voxels = LabelledVoxels::new(VOXEL_M);
    for robot in per_robot.iter().flatten() {
        voxels.merge(robot);
    }
    let float = |name: &str| PcdField { name: name.into(), size: 4, kind: FieldKind::Float, count: 1 };
    let mut columns: Vec<Vec<f64>> = (0..4).map(|_| Vec::with_capacity(voxels.len())).collect();
    for (p, label) in voxels.points() {
        for (c, v) in p.iter().enumerate() {
            columns[c].push(*v);
        }
        columns[3].push(f64::from(label.0));
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
