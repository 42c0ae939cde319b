//! Semantic fusion + clustering of a 20k-point scan (issue [perception] target ≤ 5 ms): a
//! synthetic scene of 40 objects of 6 classes on a ground plane, seen by a 640 × 480 camera
//! looking along the LiDAR's x axis. And ICP on a 20k + 20k room, as `sgm icp` runs it, and its
//! registration on one thread and split over two (`icp_room_20k_registration_*`).

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sgm_model::geometry::Pose3;
use sgm_model::perception::clustering::{cluster, ClusterConfig};
use sgm_model::perception::icp::{register, register_to, Freedom, IcpConfig, IcpMethod, IcpTarget};
use sgm_model::perception::label_vote::{vote, LabelVote};
use sgm_model::perception::projection::{label_points, CameraModel, LabelImage};
use sgm_model::perception::synthetic_room::box_room as room;
use sgm_model::scene_graph::LabelId;
use sgm_model::workers::Workers;
use std::hint::black_box;

fn scene() -> (Vec<Point3<f64>>, CameraModel, LabelImage, Pose3) {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut points = Vec::with_capacity(20_000);
    for k in 0..20_000 {
        if k % 2 == 0 {
            points.push(Point3::new(rng.random_range(1.0..30.0), rng.random_range(-15.0..15.0), -1.5));
        } else {
            let o = (k / 2) % 40;
            let centre = Vector3::new(3.0 + (o % 8) as f64 * 3.0, -10.0 + (o / 8) as f64 * 5.0, -1.0);
            points.push(Point3::from(
                centre
                    + Vector3::new(
                        rng.random_range(-0.3..0.3),
                        rng.random_range(-0.3..0.3),
                        rng.random_range(-0.5..0.5),
                    ),
            ));
        }
    }
    let camera = CameraModel {
        width: 640,
        height: 480,
        fx: 300.0,
        fy: 300.0,
        cx: 320.0,
        cy: 240.0,
        distortion: [0.05, -0.01, 0.0, 0.0, 0.0],
    };
    let labels: Vec<u16> = (0..640 * 480).map(|i| ((i % 640) / 107) as u16 + 1).collect();
    let image = LabelImage::new(640, 480, labels).unwrap_or_else(|_| unreachable!());
    let r = Matrix3::new(0.0, -1.0, 0.0, 0.0, 0.0, -1.0, 1.0, 0.0, 0.0);
    let camera_from_lidar = Pose3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
    );
    (points, camera, image, camera_from_lidar)
}

fn fusion_and_clustering(c: &mut Criterion) {
    let (points, camera, image, camera_from_lidar) = scene();
    let config = ClusterConfig::default();
    let level = UnitQuaternion::identity();
    c.bench_function("fusion_20k", |b| {
        b.iter(|| label_points(black_box(&points), &camera_from_lidar, &camera, &image))
    });
    let labels = label_points(&points, &camera_from_lidar, &camera, &image).unwrap_or_default();
    let objects_only: Vec<_> = labels.iter().enumerate().map(|(k, l)| if k % 2 == 1 { *l } else { None }).collect();
    c.bench_function("clustering_20k_objects_only", |b| {
        b.iter(|| cluster(black_box(&points), &objects_only, &config, &level))
    });
    c.bench_function("fusion_and_clustering_20k", |b| {
        b.iter(|| {
            let labels = label_points(black_box(&points), &camera_from_lidar, &camera, &image).unwrap_or_default();
            cluster(&points, &labels, &config, &level)
        })
    });
    // The label vote as Fusion runs it: every labelled return votes (ground as class 0), object
    // returns are re-voted.
    let with_ground: Vec<_> =
        labels.iter().enumerate().map(|(k, l)| if k % 2 == 0 { l.map(|_| LabelId(0)) } else { *l }).collect();
    c.bench_function("label_vote_20k", |b| {
        b.iter(|| vote(black_box(&points), &with_ground, &LabelVote::default(), |l| l.0 != 0))
    });
}

/// The 20k-point room (target) and an independent 20k sampling of it seen from a 5° / 0.37 m
/// offset (source, in its own frame).
fn room_pair() -> (Vec<Point3<f64>>, Vec<Point3<f64>>) {
    let truth = Pose3::from_parts(
        Translation3::new(0.3, -0.2, 0.1),
        UnitQuaternion::from_euler_angles(2f64.to_radians(), -1.5f64.to_radians(), 5f64.to_radians()),
    );
    let source = room(20_000, 2).iter().map(|q| truth.inverse() * q).collect();
    (source, room(20_000, 1))
}

/// ICP as `sgm icp` runs it on a 20k + 20k room (issue [odometry]: ≤ 0.8× small_gicp's time,
/// measured against it by `benches/compare_small_gicp.sh`): 0.1 m voxels, 1 m correspondences,
/// small_gicp's convergence (0.1°, 1 mm), from identity to a 5° / 0.37 m offset.
fn icp_room(c: &mut Criterion) {
    let (source, target) = room_pair();
    for method in [IcpMethod::PointToPlane, IcpMethod::PointToPoint] {
        let config = IcpConfig {
            method,
            voxel_m: 0.1,
            max_correspondence_distance_m: 1.0,
            convergence_rotation_rad: 0.1f64.to_radians(),
            convergence_translation_m: 1e-3,
            ..IcpConfig::default()
        };
        let name = format!(
            "icp_room_20k_{}",
            if method == IcpMethod::PointToPlane { "point_to_plane" } else { "point_to_point" }
        );
        c.bench_function(&name, |b| b.iter(|| register(black_box(&source), &target, &Pose3::identity(), &config)));
    }
}

/// The registration alone (onto a fresh target, made outside the clock) on one thread and split
/// over two: the same answer, and the split's speed-up.
fn icp_split(c: &mut Criterion) {
    let (source, target) = room_pair();
    let config = IcpConfig { voxel_m: 0.1, ..IcpConfig::default() };
    let two = rayon::ThreadPoolBuilder::new().num_threads(2).build().expect("a pool of two threads");
    for (name, workers) in [("1", Workers::sequential()), ("2", Workers::on(std::sync::Arc::new(two)))] {
        c.bench_function(&format!("icp_room_20k_registration_{name}_threads"), |b| {
            b.iter_batched(
                || IcpTarget::new(&target, &config).expect("a room"),
                |mut ready| {
                    register_to(black_box(&source), &mut ready, &Pose3::identity(), &config, &workers, Freedom::Full)
                },
                criterion::BatchSize::LargeInput,
            )
        });
    }
}

criterion_group!(benches, fusion_and_clustering, icp_room, icp_split);
criterion_main!(benches);
