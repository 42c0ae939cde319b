//! `sgm odometry --bag`: the odometry on a ROS 1 bag gives what it gave on the simulated
//! sensors directly. `sgm_scenarios::front_end` runs it on `indoor_three_robots`' first robot for
//! 10 s and records the sweeps (with their points' times) and the IMU as a bag; the bag's
//! replay through the bag reader, its input checks and `bag_odometry` must give the same poses.
//! A bag without the IMU, or no bag, is refused with what is wrong.

use sgm_bridge::node::NodeConfig;
use sgm_model::odometry::config::OdometryConfig;
use sgm_scenarios::bag_odometry::{odometry_on_bag, BagOdometryError};
use sgm_scenarios::front_end::{imu_noise, run_front_end_recording};
use sgm_scenarios::scenario::Scenario;

fn scenario() -> Scenario {
    let mut scenario = Scenario::load("indoor_three_robots").expect("in the library");
    scenario.scenario.duration_s = 10.0;
    scenario
}

fn node_config(scenario: &Scenario) -> NodeConfig {
    NodeConfig { robot: scenario.robot_config(0), ros: scenario.ros.clone() }
}

#[test]
fn the_odometry_on_a_bag_gives_the_poses_it_gave_on_the_sensors() {
    let scenario = scenario();
    let dir = tempfile::tempdir().expect("a temporary directory");
    let config = OdometryConfig { imu: imu_noise(&scenario), ..OdometryConfig::default() };
    let direct = run_front_end_recording(&scenario, 0, &config, None, Some(0.1), Some(dir.path())).expect("runs");
    let bag = dir.path().join(format!("{}.bag", scenario.robot_name(0)));
    let from_bag = odometry_on_bag(&bag, &node_config(&scenario)).expect("reads the bag");
    let expected: Vec<_> = direct.frames.iter().filter_map(|f| f.estimate.map(|e| (f.t, e))).collect();
    assert!(expected.len() >= 80, "{} poses", expected.len());
    assert_eq!(from_bag.poses.len(), expected.len());
    for (pose, (t, estimate)) in from_bag.poses.iter().zip(&expected) {
        assert!((pose.stamp - t).abs() < 1e-6, "stamps {} and {t}", pose.stamp);
        let error = sgm_model::geometry::pose_error(&pose.odom_from_body, estimate);
        assert!(error.translation_m < 1e-6 && error.max_axis_rotation_deg() < 1e-6, "at {t}: {error:?}");
    }
    assert_eq!(from_bag.counts.resets, 0);
    assert_eq!(from_bag.registered_early, 0, "every sweep registered once the IMU covered it");
}

#[test]
fn a_bag_without_the_imu_or_no_bag_is_refused_by_what_is_wrong() {
    let mut scenario = scenario();
    scenario.scenario.duration_s = 3.0;
    let dir = tempfile::tempdir().expect("a temporary directory");
    let config = OdometryConfig { imu: imu_noise(&scenario), ..OdometryConfig::default() };
    run_front_end_recording(&scenario, 0, &config, None, Some(0.1), Some(dir.path())).expect("runs");
    let bag = dir.path().join(format!("{}.bag", scenario.robot_name(0)));
    let mut elsewhere = node_config(&scenario);
    elsewhere.ros.topics.imu = "/nowhere/imu".into();
    match odometry_on_bag(&bag, &elsewhere) {
        Err(e @ BagOdometryError::NoImu { .. }) => assert!(e.to_string().contains("/nowhere/imu"), "{e}"),
        other => panic!("{other:?}"),
    }
    let missing = dir.path().join("missing.bag");
    match odometry_on_bag(&missing, &node_config(&scenario)) {
        Err(e @ BagOdometryError::Bag(_)) => assert!(e.to_string().contains("missing.bag"), "{e}"),
        other => panic!("{other:?}"),
    }
}
