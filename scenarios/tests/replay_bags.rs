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

/// `scenario` run and recorded as bags into a fresh temporary directory (kept alive by the
/// returned handle): the run's outcome and alpha's and bravo's bags.
fn recorded(
    system: &actix_rt::SystemRunner,
    scenario: &Scenario,
) -> (sgm_scenarios::record::RunOutcome, tempfile::TempDir, Vec<std::path::PathBuf>) {
    let dir = tempfile::tempdir().unwrap();
    let outcome = system.block_on(run_recording(scenario, None, Some(dir.path()))).unwrap();
    let bags = vec![dir.path().join("alpha.bag"), dir.path().join("bravo.bag")];
    (outcome, dir, bags)
}

#[test]
fn a_scenario_replayed_from_its_bags_gives_the_same_run() {
    let scenario = Scenario::load_with_env("quickstart", "SGM_REPLAY_TEST").unwrap();
    let system = actix_rt::System::new();
    let (outcome, _dir, bags) = recorded(&system, &scenario);
    let ran = report::compute(&outcome.record);
    assert!(ran.alignments.iter().all(|a| a.first_aligned_s.is_some()), "the scenario aligns");
    for r in &ran.robots {
        // Scans without per-point time are used as they came, and the report says so.
        let d = &r.deskew;
        assert_eq!((d.deskewed, d.no_times), (0, r.frames), "{}: {d:?}", r.name);
    }

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
    let mut scenario = Scenario::load_with_env("quickstart", "SGM_REPLAY_SWEEP_TEST").unwrap();
    scenario.scenario.duration_s = 70.0;
    scenario.lidar.sweep_s = 0.1;
    let system = actix_rt::System::new();
    let (outcome, _dir, bags) = recorded(&system, &scenario);
    let ran = report::compute(&outcome.record);
    for r in &ran.robots {
        // Every scan but the first (no motion known yet) deskewed, and counted in the report.
        let d = &r.deskew;
        assert_eq!((d.deskewed, d.no_motion, d.no_times, d.refused), (r.frames - 1, 1, 0, 0), "{}: {d:?}", r.name);
    }
    let ran = serde_json::to_value(ran).unwrap();
    let replayed = system.block_on(replay(&scenario, &bags, None)).unwrap();
    let again = serde_json::to_value(report::compute(&replayed.run.record)).unwrap();
    assert_eq!(without_world(ran.clone()), without_world(again));
    let mut straight_off = scenario.clone();
    straight_off.fusion.deskew = false;
    let replayed = system.block_on(replay(&straight_off, &bags, None)).unwrap();
    let skewed = report::compute(&replayed.run.record);
    assert!(skewed.robots.iter().all(|r| r.deskew == Default::default()), "deskew off counts nothing");
    let skewed = serde_json::to_value(skewed).unwrap();
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

/// A camera off the LiDAR and turned, firing 30 ms after each scan: its images go into the bags
/// at their own stamps and its mount on tf. The replay (the offset within
/// `ros.sync.image_tolerance_s`, left to Fusion as in the run) ends with the run's alignments and
/// trajectories to the last bit; only its timeline lags (a frame waits for its image, 30 ms
/// later, so some frames are handled a step later).
#[test]
fn a_camera_off_the_lidar_firing_late_replays_to_the_runs_result() {
    let mut scenario = Scenario::load_with_env("quickstart", "SGM_REPLAY_CAMERA_TEST").unwrap();
    scenario.scenario.duration_s = 70.0;
    scenario.camera.mount_xyz_m = [0.12, -0.03, 0.08];
    scenario.camera.mount_rpy_deg = [0.0, 4.0, -6.0];
    scenario.camera.exposure_offset_s = 0.03;
    let system = actix_rt::System::new();
    let (outcome, _dir, bags) = recorded(&system, &scenario);
    let ran = report::compute(&outcome.record);
    assert!(ran.alignments.iter().all(|a| a.first_aligned_s.is_some()), "the scenario aligns");
    let replayed = system.block_on(replay(&scenario, &bags, None)).unwrap();
    for b in &replayed.bags {
        assert!(b.health.is_empty(), "a healthy bag: {:?}", b.health);
    }
    let again = report::compute(&replayed.run.record);
    let figures = |r: &report::Report| {
        let pairs: Vec<_> = r.alignments.iter().map(|a| (a.translation_error_m, a.rotation_error_deg)).collect();
        let robots: Vec<_> = r.robots.iter().map(|x| (x.keyframes, x.ate_rmse_m)).collect();
        (pairs, robots, r.team_ate_rmse_m)
    };
    assert_eq!(figures(&ran), figures(&again));
}

/// A scenario with an IMU (`[imu]`) writes its samples into the bags as `sensor_msgs/Imu` at
/// `imu.rate_hz`, each at its own stamp in the body frame: read back through the bag's records
/// (the same bounded decoding as every input) they are as many as the rate says, and at rest
/// on flat ground their specific force is gravity up.
#[test]
fn imu_samples_go_into_the_bags_at_their_rate() {
    use rosrust::{Message, RosMsg};
    use sgm_bridge::bag::records::{BagLimits, ChunkRecord, ChunkSection};
    use sgm_bridge::bounded::check_within;
    use sgm_bridge::convert::imu::reading_from_msg;
    use sgm_bridge::msg::sensor_msgs::Imu;

    let dir = tempfile::tempdir().unwrap();
    let mut scenario = Scenario::load_with_env("quickstart", "SGM_REPLAY_IMU_TEST").unwrap();
    scenario.scenario.duration_s = 10.0;
    scenario.imu.enabled = true;
    scenario.imu.rate_hz = 200.0;
    let system = actix_rt::System::new();
    system.block_on(run_recording(&scenario, None, Some(dir.path()))).unwrap();
    let path = dir.path().join("alpha.bag");
    let len = std::fs::metadata(&path).unwrap().len();
    let file = std::io::BufReader::new(std::fs::File::open(&path).unwrap());
    let mut section = ChunkSection::open(file, len, BagLimits::for_messages(1 << 26)).unwrap();
    let (mut imu_connection, mut stamps, mut forces) = (None, Vec::new(), Vec::new());
    while let Some(chunk) = section.next_chunk().unwrap() {
        for record in chunk.records() {
            match record.unwrap() {
                ChunkRecord::Connection { id, topic, msg_type, md5sum } if topic == "/alpha/imu" => {
                    assert_eq!((msg_type, md5sum), (Imu::msg_type(), Imu::md5sum()));
                    imu_connection = Some(id);
                }
                ChunkRecord::Message { conn, data, .. } if Some(conn) == imu_connection => {
                    check_within::<Imu>(data, 1 << 20).unwrap();
                    let msg = Imu::decode(data).unwrap();
                    assert_eq!(msg.header.frame_id, "alpha/base_link");
                    stamps.push(msg.header.stamp.nanos());
                    forces.push(reading_from_msg(&msg).unwrap().linear_acceleration);
                }
                _ => {}
            }
        }
    }
    stamps.sort_unstable();
    // Samples from the first tick whose neighbours the route knows up to the last frame.
    assert!((1990..=2001).contains(&stamps.len()), "{} samples in 10 s at 200 Hz", stamps.len());
    assert!(stamps.windows(2).all(|w| w[1] - w[0] == 5_000_000), "every 5 ms");
    let mean_up = forces.iter().map(|f| f.z).sum::<f64>() / forces.len() as f64;
    assert!((mean_up - scenario.imu.gravity_mps2).abs() < 0.05, "mean specific force up {mean_up}");
}

/// A scenario on the robots' own odometry (`odometry.source = "internal"`) written as bags:
/// 10 Hz sweeps with their points' times, label images with every fifth (twice a second),
/// 200 Hz IMU, no odometry read. With `ros.sync` labelling only a cloud that has its own image
/// (`max_label_skew_s` = `image_tolerance_s`) and handing the others to the odometry alone
/// (`unlabelled = "drop"`), the replay gives each robot's Odometry actor every sweep and its
/// IMU samples as the run did: the same scans registered, the same frames mapped, and the run's
/// trajectories and alignments.
#[test]
fn a_run_on_its_own_odometry_replays_from_its_sweeps_and_imu() {
    let text = sgm_scenarios::scenario::library::get("quickstart").unwrap();
    let text = format!(
        "{text}\n[odometry]\nsource = \"internal\"\n[imu]\nenabled = true\n[lidar]\nsweep_s = 0.1\n\
         [ros.sync]\nmax_label_skew_s = 0.05\nunlabelled = \"drop\"\n"
    );
    let scenario = Scenario::from_toml(&text, "internal.toml", "SGM_REPLAY_INTERNAL_TEST").unwrap();
    let system = actix_rt::System::new();
    let (outcome, _dir, bags) = recorded(&system, &scenario);
    let ran = report::compute(&outcome.record);
    let replayed = system.block_on(replay(&scenario, &bags, None)).unwrap();
    for b in &replayed.bags {
        assert!(b.refused.is_empty(), "{b:?}");
        assert!(b.health.is_empty(), "a healthy bag: {:?}", b.health);
        assert_eq!((b.sync.imu_short, b.sync.no_imu_mount, b.sync.no_odometry), (0, 0, 0), "{:?}", b.sync);
        assert_eq!(b.sync.frames, outcome.record.robots[0].frames, "{:?}", b.sync);
        assert!(b.sync.sweeps >= 4 * b.sync.frames - 4, "four sweeps between frames: {:?}", b.sync);
    }
    for (ran, again) in outcome.record.odometry.iter().zip(&replayed.run.record.odometry) {
        let (mut ran, again) = (ran.unwrap(), again.unwrap());
        // The run hands the last frame the samples to its stamp + lidar.sweep_s, the replay to
        // its latest point's time: the sample at the very end of the mission is not handed on.
        assert!(ran.counts.imu.kept - again.counts.imu.kept <= 1, "{:?} {:?}", ran.counts, again.counts);
        ran.counts.imu.kept = again.counts.imu.kept;
        assert_eq!(ran.counts, again.counts, "the same scans and IMU samples");
        assert_eq!((ran.handed_on, ran.origin_stamp), (again.handed_on, again.origin_stamp));
    }
    // The bags hold the points as f32 (the run's are f64; at 30 m, f32 rounds by 2 µm), and the
    // robots' own odometry carries that through every scan: the figures agree to 1e-5 (m, °).
    // A frame waits for the IMU samples recorded after it (to its sweep's end), so the replay
    // handles it a step later and may align one step later.
    let again = report::compute(&replayed.run.record);
    let near = |a: Option<f64>, b: Option<f64>| match (a, b) {
        (Some(a), Some(b)) => (a - b).abs() < 1e-5,
        (a, b) => a.is_none() && b.is_none(),
    };
    assert!(ran.alignments.iter().all(|a| a.first_aligned_s.is_some()), "the scenario aligns");
    for (a, b) in ran.alignments.iter().zip(&again.alignments) {
        let lag = b.first_aligned_s.zip(a.first_aligned_s).map(|(b, a)| b - a);
        assert!(lag.is_some_and(|lag| (0.0..=scenario.scenario.frame_interval_s).contains(&lag)), "{a:?} {b:?}");
        assert!(
            near(a.translation_error_m, b.translation_error_m) && near(a.rotation_error_deg, b.rotation_error_deg),
            "{a:?}\n{b:?}"
        );
    }
    for (a, b) in ran.robots.iter().zip(&again.robots) {
        assert_eq!((a.keyframes, a.frames), (b.keyframes, b.frames), "{}", a.name);
        assert!(near(a.ate_rmse_m, b.ate_rmse_m), "{}: {:?} {:?}", a.name, a.ate_rmse_m, b.ate_rmse_m);
    }
    assert!(near(ran.team_ate_rmse_m, again.team_ate_rmse_m));
}
