//! `sgm doctor --bag`: a verdict per input of a robot's bag. Quickstart's own bags pass (exit 0);
//! the mistakes of a first deployment are named on the input they concern and fail (exit 1):
//! odometry in another world frame, a camera mount tf cannot give; a mount written the wrong way
//! round warns (exit 0, tf contradicts it); a missing bag is an error (exit 2).

use sgm_scenarios::runner::run_recording;
use sgm_scenarios::scenario::Scenario;
use std::path::Path;
use std::process::{Command, Output};

fn doctor(args: &[&str]) -> (Option<i32>, String) {
    let out: Output = Command::new(env!("CARGO_BIN_EXE_sgm")).arg("doctor").args(args).output().expect("sgm runs");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    (out.status.code(), text)
}

fn line<'a>(text: &'a str, input: &str) -> &'a str {
    text.lines().find(|l| l.trim_start().starts_with(input)).unwrap_or_else(|| panic!("no {input} line:\n{text}"))
}

#[test]
fn the_doctor_passes_good_bags_and_names_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let mut scenario = Scenario::load("quickstart").unwrap();
    scenario.scenario.duration_s = 30.0;
    actix_rt::System::new().block_on(run_recording(&scenario, None, Some(dir.path()))).unwrap();
    let bag = dir.path().join("alpha.bag");
    let bag = bag.to_str().unwrap();

    let (code, text) = doctor(&["--robot", "alpha", "--scenario", "quickstart", "--bag", bag]);
    assert_eq!(code, Some(0), "{text}");
    assert!(text.ends_with("verdict: OK (0 failed, 0 with warnings, 7 ok)\n"), "{text}");
    assert!(line(&text, "tf").contains("camera from tf (alpha/base_link ← alpha/camera)"), "{text}");
    assert!(line(&text, "frames").contains("60 of 60 clouds assembled"), "{text}");

    let config = |name: &str, toml: &str| {
        let path = dir.path().join(name);
        std::fs::write(&path, toml).unwrap();
        path
    };
    let wrong =
        config("wrong.toml", "[ros.frames]\nworld = \"camera_init\"\n[ros.tf]\nstatic_topic = \"/nobody/tf_static\"\n");
    let (code, text) = doctor(&["--robot", "alpha", "--config", wrong.to_str().unwrap(), "--bag", bag]);
    assert_eq!(code, Some(1), "{text}");
    assert!(line(&text, "odometry").contains("FAIL"), "{text}");
    assert!(
        text.contains("all 60 messages on odometry refused (last: frame `alpha/odom`, `camera_init` expected)"),
        "{text}"
    );
    assert!(line(&text, "tf").contains("FAIL"), "{text}");
    assert!(text.contains("the camera mount alpha/base_link ← alpha/camera is unknown"), "{text}");
    assert!(line(&text, "frames").contains("FAIL"), "{text}");

    let inverted = config("inverted.toml", "[ros]\ncamera_from_body = [0.0, 0.0, 0.0, -0.5, 0.5, -0.5, 0.5]\n");
    let (code, text) = doctor(&["--robot", "alpha", "--config", inverted.to_str().unwrap(), "--bag", bag, "--json"]);
    assert_eq!(code, Some(0), "{text}");
    let report: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(report["verdict"], "WARN");
    let tf = report["inputs"].as_array().unwrap().iter().find(|v| v["input"] == "tf").unwrap();
    assert!(tf["problems"][0].as_str().unwrap().contains("by 0.000 m and 120.00°"), "{tf}");

    let (code, text) =
        doctor(&["--robot", "alpha", "--bag", &Path::new(bag).with_extension("missing").display().to_string()]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("alpha.missing"), "{text}");
}

/// A robot on its own odometry: the doctor reads the IMU (not an odometry topic) and judges it
/// as the odometry would take it. A run's own bags pass; an `imu_limits.max_gap_s` below the
/// IMU's interval makes every interval a gap the odometry would coast across, named on `imu`.
#[test]
fn the_doctor_checks_the_imu_of_a_robot_on_its_own_odometry() {
    let dir = tempfile::tempdir().unwrap();
    let text = sgm_scenarios::scenario::library::get("quickstart").unwrap();
    let text = format!("{text}\n[odometry]\nsource = \"internal\"\n[imu]\nenabled = true\n[lidar]\nsweep_s = 0.1\n");
    let mut scenario = Scenario::from_toml(&text, "internal.toml", "SGM_DOCTOR_INTERNAL_TEST").unwrap();
    scenario.scenario.duration_s = 20.0;
    actix_rt::System::new().block_on(run_recording(&scenario, None, Some(dir.path()))).unwrap();
    let bag = dir.path().join("alpha.bag");
    let bag = bag.to_str().unwrap();
    let good = "[odometry]\nsource = \"internal\"\n[ros.sync]\nmax_label_skew_s = 0.05\nunlabelled = \"drop\"\n";
    let config = |name: &str, toml: &str| {
        let path = dir.path().join(name);
        std::fs::write(&path, toml).unwrap();
        path.to_str().unwrap().to_string()
    };

    let (code, text) = doctor(&["--robot", "alpha", "--config", &config("good.toml", good), "--bag", bag]);
    assert_eq!(code, Some(0), "{text}");
    assert!(text.contains("verdict: OK"), "{text}");
    assert!(!text.lines().any(|l| l.trim_start().starts_with("odometry")), "no odometry topic is read:\n{text}");
    assert!(line(&text, "imu").contains("samples on imu, 200.0 Hz"), "{text}");
    assert!(line(&text, "frames").contains("of them sweeps for the odometry alone"), "{text}");

    let tight = format!("{good}[odometry.estimator.imu_limits]\nmax_gap_s = 0.004\n");
    let (code, text) = doctor(&["--robot", "alpha", "--config", &config("tight.toml", &tight), "--bag", bag]);
    assert_eq!(code, Some(0), "a warning, not a failure:\n{text}");
    assert!(line(&text, "imu").contains("WARN"), "{text}");
    assert!(text.contains("intervals longer than 0.004 s (the longest 0.005 s): the odometry coasts"), "{text}");
}
