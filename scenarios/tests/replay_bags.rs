//! A scenario written as ROS 1 bags (`sgm run --bag-out`) replays through `sgm replay` to the
//! scenario's own result: the same keyframes, trajectories, alignments, times and radio bytes.
//! Only what needs the simulated world differs (object quality, the world's object count, the
//! start-frame error, which a bag can only estimate from its first poses).

use sgm_bridge::health::Check;
use sgm_scenarios::replay::replay;
use sgm_scenarios::report;
use sgm_scenarios::runner::run_recording;
use sgm_scenarios::scenario::Scenario;

/// Keys that need the simulated world.
const WORLD_ONLY: &[&str] = &[
    "scenario",
    "objects_found",
    "objects_spurious",
    "object_error_m",
    "start_frame_translation_error_m",
    "world_objects",
];

fn without_world(mut value: serde_json::Value) -> serde_json::Value {
    match &mut value {
        serde_json::Value::Object(map) => {
            for key in WORLD_ONLY {
                map.remove(*key);
            }
            for v in map.values_mut() {
                *v = without_world(v.take());
            }
        }
        serde_json::Value::Array(items) => {
            for v in items.iter_mut() {
                *v = without_world(v.take());
            }
        }
        _ => {}
    }
    value
}

#[test]
fn a_scenario_replayed_from_its_bags_gives_the_same_run() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = Scenario::load_with_env("quickstart", "SGM_REPLAY_TEST").unwrap();
    let system = actix_rt::System::new();
    let outcome = system.block_on(run_recording(&scenario, None, Some(dir.path()))).unwrap();
    let ran = report::compute(&outcome.record);
    assert!(ran.alignments.iter().all(|a| a.first_aligned_s.is_some()), "the scenario aligns");

    let bags = vec![dir.path().join("alpha.bag"), dir.path().join("bravo.bag")];
    let replayed = system.block_on(replay(&scenario, &bags, None)).unwrap();
    for b in &replayed.bags {
        assert!(b.refused.is_empty(), "{b:?}");
        assert_eq!(b.sync.frames, outcome.record.robots[0].frames, "{b:?}");
        assert!(b.health.is_empty(), "a healthy bag: {:?}", b.health);
    }
    let again = report::compute(&replayed.run.record);
    let (ran, again) = (serde_json::to_value(&ran).unwrap(), serde_json::to_value(&again).unwrap());
    assert_eq!(without_world(ran), without_world(again));

    // The camera mounting written the wrong way round (the pose tf gives, as camera_from_body):
    // the same bags map geometry but never confirm an object. With the bags' /tf_static the
    // replay names the contradiction (120°); without tf it still says no object was found,
    // naming the extrinsic, where it used to be silent.
    let mut inverted = scenario.clone();
    inverted.ros.camera_from_body = Some([0.0, 0.0, 0.0, -0.5, 0.5, -0.5, 0.5]);
    let replayed = system.block_on(replay(&inverted, &bags, None)).unwrap();
    for b in &replayed.bags {
        let checks: Vec<_> = b.health.iter().map(|f| f.check).collect();
        assert_eq!(checks, vec![Check::MountDisagrees, Check::NoObjects], "{b:?}");
        assert!(b.health[0].detail.contains("by 0.000 m and 120.00°"), "{:?}", b.health);
        assert!(b.health[1].likely_cause.contains("camera_from_body"), "{:?}", b.health);
    }
    inverted.ros.tf.listen = false;
    let replayed = system.block_on(replay(&inverted, &bags, None)).unwrap();
    for b in &replayed.bags {
        let checks: Vec<_> = b.health.iter().map(|f| f.check).collect();
        assert_eq!(checks, vec![Check::NoObjects], "{b:?}");
    }

    // Nothing pins the camera and tf never gives it (tf read from a topic nobody publishes):
    // every cloud is kept without labels, and the replay names the frames tf lacks.
    let mut no_tf = scenario.clone();
    no_tf.ros.tf.static_topic = "/nobody/tf_static".into();
    let replayed = system.block_on(replay(&no_tf, &bags, None)).unwrap();
    for b in &replayed.bags {
        let checks: Vec<_> = b.health.iter().map(|f| f.check).collect();
        assert_eq!(checks, vec![Check::NoMount, Check::NoObjects], "{b:?}");
        assert_eq!(b.sync.unlabelled, b.sync.frames, "{b:?}");
        let robot = &b.robot;
        assert!(
            b.health[0].detail.contains(&format!(
                "the camera mount `{robot}/base_link` ← `{robot}/camera` is unknown: no frame `{robot}/camera` in tf"
            )),
            "{:?}",
            b.health
        );
        assert!(b.health[0].detail.contains("pin ros.body_from_camera"), "{:?}", b.health);
    }
}

/// Sweeps measured on the move (`lidar.sweep_s`) go into the bags with each point's time (a
/// `time` field); the replay reads them back and deskews exactly as the run did, and turning
/// deskewing off changes the result.
#[test]
fn point_times_survive_the_bags_and_deskew_the_replay_as_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let mut scenario = Scenario::load_with_env("quickstart", "SGM_REPLAY_SWEEP_TEST").unwrap();
    scenario.scenario.duration_s = 70.0;
    scenario.lidar.sweep_s = 0.1;
    let system = actix_rt::System::new();
    let outcome = system.block_on(run_recording(&scenario, None, Some(dir.path()))).unwrap();
    let ran = serde_json::to_value(report::compute(&outcome.record)).unwrap();
    let bags = vec![dir.path().join("alpha.bag"), dir.path().join("bravo.bag")];
    let replayed = system.block_on(replay(&scenario, &bags, None)).unwrap();
    let again = serde_json::to_value(report::compute(&replayed.run.record)).unwrap();
    assert_eq!(without_world(ran.clone()), without_world(again));
    let mut straight_off = scenario.clone();
    straight_off.fusion.deskew = false;
    let replayed = system.block_on(replay(&straight_off, &bags, None)).unwrap();
    let skewed = serde_json::to_value(report::compute(&replayed.run.record)).unwrap();
    assert_ne!(without_world(ran), without_world(skewed), "deskewing changed nothing");
}

#[test]
fn bad_bag_lists_are_named() {
    let scenario = Scenario::load_with_env("quickstart", "SGM_REPLAY_TEST").unwrap();
    let system = actix_rt::System::new();
    let dir = tempfile::tempdir().unwrap();
    let one = vec![dir.path().join("alpha.bag")];
    let err = system.block_on(replay(&scenario, &one, None)).err().unwrap().to_string();
    assert!(err.contains("1 bags but the configuration has 2 robots"), "{err}");
    let two = vec![dir.path().join("missing.bag"), dir.path().join("alpha.bag")];
    let err = system.block_on(replay(&scenario, &two, None)).err().unwrap().to_string();
    assert!(err.contains("missing.bag"), "{err}");
}
