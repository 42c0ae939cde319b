//! End to end through one robot's actor tree: odometry whose heading drifts, a loop driven back
//! to the start, the Tracker's loop closure, the Optimiser's solve, and the object positions in
//! the map corrected by the optimised keyframe poses.

mod common;

use common::{position, scan, settle, world, WorldObject};
use nalgebra::{Point3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sgm_actors::clock::Clock;
use sgm_actors::config::RobotConfig;
use sgm_actors::messages::{FrameLabels, SensorFrame, Tick};
use sgm_actors::supervisor::start_robot;
use sgm_actors::tracker::GetSceneGraph;
use sgm_actors::transport::{InProcessRadio, PerfectLinks};
use sgm_model::geometry::{pose_from_yaw_translation, Pose3};
use sgm_model::scene_graph::{KeyframeEdgeKind, SceneGraph};

/// Heading drift of the odometry, rad per metre travelled (0.03 °/m).
const DRIFT_RAD_PER_M: f64 = 0.03 * std::f64::consts::PI / 180.0;
const SPEED: f64 = 1.5;

/// A 40 m square driven back to its first corner and on: 180 m.
fn waypoints() -> Vec<Point3<f64>> {
    let corners = [(-20.0, -20.0), (20.0, -20.0), (20.0, 20.0), (-20.0, 20.0), (-20.0, -20.0), (0.0, -20.0)];
    corners.iter().map(|(x, y)| Point3::new(*x, *y, 0.0)).collect()
}

/// Drives the loop with drifting odometry; returns the map.
async fn map_of_a_loop(loop_closure: bool) -> SceneGraph {
    let world = world(11);
    let radio = InProcessRadio::new(Box::new(PerfectLinks));
    let mut config = RobotConfig::default();
    config.robot.id = 1;
    if !loop_closure {
        config.tracker.loop_closure.time_gap_s = 1e9;
    }
    let robot = start_robot(&config, Clock::starting_at(0.0), &radio).expect("valid configuration");
    settle().await;
    let waypoints = waypoints();
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    for step in 1..=240 {
        let t = f64::from(step) * 0.5;
        let s = t * SPEED;
        robot.clock.advance_to(t);
        let (p, yaw) = position(&waypoints, s);
        let truth = pose_from_yaw_translation(yaw, p.coords);
        // The odometry's world turns away from the true one as the robot travels.
        let drift = Pose3::from_parts(
            Vector3::zeros().into(),
            UnitQuaternion::from_euler_angles(0.0, 0.0, DRIFT_RAD_PER_M * s),
        );
        let (points, labels) = scan(&world, &truth, &mut rng);
        robot.sensor.do_send(SensorFrame {
            stamp: t,
            odom_from_body: drift * truth,
            points_in_body: points,
            point_times: None,
            points_deskewed: false,
            labels: FrameLabels::PerPoint(labels),
            imu: Vec::new(),
            motion_covariance: None,
            measured_up: None,
        });
        settle().await;
        robot.supervisor.do_send(Tick { now: t });
        settle().await;
    }
    robot.tracker.send(GetSceneGraph).await.expect("tracker answers")
}

/// Mean distance from each mapped object to the nearest true object of its class, and the mean
/// keyframe position error (the robot's world starts on the true one).
fn errors(graph: &SceneGraph, world: &[WorldObject]) -> (f64, f64) {
    let objects: Vec<f64> = graph
        .objects()
        .filter_map(|o| {
            let c = graph.centroid_in_world(o.id)?;
            world.iter().filter(|w| w.label == o.label).map(|w| (w.centre - c).xy().norm()).min_by(f64::total_cmp)
        })
        .collect();
    let path = waypoints();
    let keyframes: Vec<f64> = graph
        .keyframes()
        .map(|k| (Point3::from(k.world_from_body.translation.vector) - position(&path, k.stamp * SPEED).0).norm())
        .collect();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    (mean(&objects), mean(&keyframes))
}

#[actix_rt::test]
async fn a_loop_closure_corrects_keyframes_and_object_positions() {
    let world = world(11);
    let drifted = map_of_a_loop(false).await;
    let corrected = map_of_a_loop(true).await;
    let (objects_drifted, keyframes_drifted) = errors(&drifted, &world);
    let (objects_corrected, keyframes_corrected) = errors(&corrected, &world);
    let loops = corrected.edges().iter().filter(|e| e.kind == KeyframeEdgeKind::Loop).count();
    assert!(loops >= 1, "the loop was closed");
    assert!(drifted.edges().iter().all(|e| e.kind != KeyframeEdgeKind::Loop));
    eprintln!(
        "objects {objects_drifted:.3} → {objects_corrected:.3} m, keyframes {keyframes_drifted:.3} → {keyframes_corrected:.3} m, {loops} loops"
    );
    assert!(keyframes_corrected < 0.5 * keyframes_drifted);
    assert!(objects_corrected < 0.5 * objects_drifted);
}
