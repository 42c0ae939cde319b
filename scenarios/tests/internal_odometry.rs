//! `odometry.source = "internal"` in a scenario: every robot's Odometry actor estimates its pose
//! from the simulated 10 Hz timed sweeps and 200 Hz IMU, and the map is built on that estimate.
//! Quickstart cut to 30 s (the robots stand still for 2 s, then set off and turn corners).

use sgm_scenarios::report::compute;
use sgm_scenarios::runner::run;
use sgm_scenarios::scenario::Scenario;

fn scenario(extra: &str) -> Result<Scenario, String> {
    let text = sgm_scenarios::scenario::library::get("quickstart").ok_or("quickstart is in the library")?;
    let text = text.replace("duration_s = 90.0", "duration_s = 30.0");
    let text = format!("{text}\n{extra}");
    Scenario::from_toml(&text, "internal.toml", "SGM_INTERNAL_ODOMETRY_TEST").map_err(|e| e.to_string())
}

const INTERNAL: &str = "[odometry]\nsource = \"internal\"\n[imu]\nenabled = true\n[lidar]\nsweep_s = 0.1\n";

#[test]
fn the_map_is_built_on_the_robots_own_odometry() {
    let scenario = scenario(INTERNAL).expect("loads");
    let outcome = actix_rt::System::new().block_on(run(&scenario, None)).expect("runs");
    let report = compute(&outcome.record);
    for (robot, status) in report.robots.iter().zip(&outcome.record.odometry) {
        let status = status.expect("an internal odometry's status");
        let c = status.counts;
        // 10 sweeps a second for 30 s; the first second waits for gravity.
        assert!(c.scans >= 280 && c.refused <= 10, "{}: {c:?}", robot.name);
        assert_eq!((c.coasted, c.resets), (0, 0), "{}: {c:?}", robot.name);
        assert!(c.registered + 1 == c.scans, "{}: every scan after the first registered: {c:?}", robot.name);
        // Two labelled frames a second go on to the map.
        assert!(status.handed_on >= 55, "{}: {} handed on", robot.name, status.handed_on);
        assert_eq!(robot.deskew.upstream, status.handed_on, "{}: deskewed by the odometry", robot.name);
        let ate = robot.ate_rmse_m.expect("an ATE");
        assert!(ate < 0.1, "{}: ATE {ate} m", robot.name);
    }
    let text = sgm_scenarios::report::markdown::render(&report, &outcome.timing);
    let line = text.lines().find(|l| l.starts_with("Deskew:")).expect("a Deskew line");
    assert!(line.contains("alpha: by its odometry (") && !line.contains("used as they came"), "{line}");
    // Same scenario and seed, same report.
    let again = actix_rt::System::new().block_on(run(&scenario, None)).expect("runs again");
    let json = |r| serde_json::to_string(&compute(r)).expect("serialises");
    assert_eq!(json(&outcome.record), json(&again.record));
}

#[test]
fn internal_odometry_without_what_it_needs_is_refused_by_key() {
    let no_imu = scenario("[odometry]\nsource = \"internal\"\n").expect_err("refused");
    assert!(no_imu.contains("imu.enabled"), "{no_imu}");
    let with = |key: &str| INTERNAL.replace("[odometry]\n", &format!("[odometry]\n{key}\n"));
    let uneven = scenario(&with("sweep_interval_s = 0.3")).expect_err("refused");
    assert!(uneven.contains("odometry.sweep_interval_s") && uneven.contains("0.3"), "{uneven}");
    let slow_sweeps = INTERNAL.replace("sweep_s = 0.1", "sweep_s = 0.2");
    let slow =
        scenario(&slow_sweeps.replace("[odometry]\n", "[odometry]\nsweep_interval_s = 0.1\n")).expect_err("refused");
    assert!(slow.contains("lidar.sweep_s"), "{slow}");
    let crash = scenario(&format!("{INTERNAL}[[robots]]\nname = \"charlie\"\ncrash_s = 10.0\n")).expect_err("refused");
    assert!(crash.contains("crash_s"), "{crash}");
}
