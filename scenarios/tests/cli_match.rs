//! `sgm match` CLI contract: output shape and exit codes on good and bad input.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn sgm(args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_sgm"));
    cmd.args(args);
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.output().expect("sgm runs")
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// A local graph and the same objects seen by a robot whose frame is yawed 90° and shifted.
fn good_pair(dir: &Path) -> (PathBuf, PathBuf) {
    let points = [
        (0.0, 0.0, "chair"),
        (12.0, 3.0, "bench"),
        (5.0, 17.0, "chair"),
        (-8.0, 9.0, "trash_can"),
        (20.0, 14.0, "lamp_post"),
        (-3.0, -12.0, "bench"),
    ];
    let object = |id: usize, x: f64, y: f64, label: &str| {
        format!(r#"{{"id": {id}, "label": "{label}", "centroid": [{x}, {y}, 0.5], "size": [0.6, 0.6, 1.0]}}"#)
    };
    let local: Vec<String> = points.iter().enumerate().map(|(k, &(x, y, l))| object(k, x, y, l)).collect();
    // remote = R(-90°)·(p − (10, 5)): then p = R(90°)·remote + (10, 5).
    let remote: Vec<String> =
        points.iter().enumerate().map(|(k, &(x, y, l))| object(100 + k, y - 5.0, -(x - 10.0), l)).collect();
    let a = write(dir, "a.json", &format!(r#"{{"robot": "a", "objects": [{}]}}"#, local.join(",")));
    let b = write(dir, "b.json", &format!(r#"{{"robot": "b", "objects": [{}], "extra": 1}}"#, remote.join(",")));
    (a, b)
}

#[test]
fn good_input_prints_transform_and_matches() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = good_pair(dir.path());
    let out = sgm(&["match", a.to_str().unwrap(), b.to_str().unwrap()], &[]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let v: Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(v["success"], true);
    let t: Vec<Vec<f64>> = serde_json::from_value(v["T"].clone()).unwrap();
    let expected = [[0.0, -1.0, 0.0, 10.0], [1.0, 0.0, 0.0, 5.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
    for r in 0..4 {
        for c in 0..4 {
            assert!((t[r][c] - expected[r][c]).abs() < 1e-9, "T = {t:?}");
        }
    }
    let matches: Vec<[u32; 2]> = serde_json::from_value(v["matches"].clone()).unwrap();
    assert_eq!(matches, (0..6).map(|k| [k, 100 + k]).collect::<Vec<_>>());
    assert!(v["score"].as_f64().unwrap() > 0.0);
    assert!(v["time_ms"].as_f64().unwrap() >= 0.0);
}

/// A reader that closes the pipe before the answer is written (`sgm match a b | head -c 0`):
/// the rest is dropped quietly, with success, not a panic.
#[test]
fn a_closed_pipe_is_not_a_crash() {
    use std::process::Stdio;
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = good_pair(dir.path());
    let mut child = Command::new(env!("CARGO_BIN_EXE_sgm"))
        .args(["match", a.to_str().unwrap(), b.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(out.status.code(), Some(0), "{stderr}");
}

#[test]
fn weak_evidence_is_refused_with_a_reason() {
    let dir = tempfile::tempdir().unwrap();
    let a = write(
        dir.path(),
        "a.json",
        r#"{"robot": "a", "objects": [{"id": 1, "label": "chair", "centroid": [0, 0, 0]}, {"id": 2, "label": "chair", "centroid": [5, 0, 0]}]}"#,
    );
    let out = sgm(&["match", a.to_str().unwrap(), a.to_str().unwrap()], &[]);
    assert_eq!(out.status.code(), Some(0));
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["success"], false);
    assert!(v.get("T").is_none());
    assert!(v["reason"].as_str().unwrap().contains("too few objects"));
}

#[test]
fn config_file_and_environment_are_applied_and_validated() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = good_pair(dir.path());
    let (a, b) = (a.to_str().unwrap(), b.to_str().unwrap());
    let config = write(dir.path(), "sgm.toml", "[matcher]\nmin_matches = 7\n");
    let out = sgm(&["match", a, b, "--config", config.to_str().unwrap()], &[]);
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["success"], false, "6 matches < min_matches 7");
    let out = sgm(&["match", a, b, "--config", config.to_str().unwrap()], &[("SGM__MATCHER__MIN_MATCHES", "3")]);
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["success"], true, "the environment overrides the file");
    let out = sgm(&["match", a, b], &[("SGM__MATCHER__INLIER_DISTANCE_M", "-2")]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("matcher.inlier_distance_m"));
    let bad = write(dir.path(), "bad.toml", "[matcher]\nno_such_key = 1\n");
    let out = sgm(&["match", a, b, "--config", bad.to_str().unwrap()], &[]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no_such_key"));
}

#[test]
fn bad_input_exits_2_naming_the_file_with_nothing_on_stdout() {
    let dir = tempfile::tempdir().unwrap();
    let (good, _) = good_pair(dir.path());
    let cases = [
        ("unreadable", None, "cannot read"),
        ("bad_json.json", Some(r#"{"robot": "a", "objects": [}"#), "invalid object file"),
        (
            "wrong_type.json",
            Some(r#"{"robot": "a", "objects": [{"id": "x", "label": "chair", "centroid": [0, 0, 0]}]}"#),
            "invalid object file",
        ),
        (
            "short_centroid.json",
            Some(r#"{"robot": "a", "objects": [{"id": 1, "label": "chair", "centroid": [0, 0]}]}"#),
            "invalid object file",
        ),
        (
            "inf.json",
            Some(r#"{"robot": "a", "objects": [{"id": 1, "label": "chair", "centroid": [0, 1e999, 0]}]}"#),
            "number out of range",
        ),
        (
            "nan.json",
            Some(r#"{"robot": "a", "objects": [{"id": 1, "label": "chair", "centroid": [NaN, 0, 0]}]}"#),
            "invalid object file",
        ),
        (
            "duplicate.json",
            Some(
                r#"{"robot": "a", "objects": [{"id": 1, "label": "chair", "centroid": [0, 0, 0]}, {"id": 1, "label": "bench", "centroid": [1, 0, 0]}]}"#,
            ),
            "duplicate id 1",
        ),
        (
            "negative_id.json",
            Some(r#"{"robot": "a", "objects": [{"id": -1, "label": "chair", "centroid": [0, 0, 0]}]}"#),
            "invalid object file",
        ),
        ("no_robot.json", Some(r#"{"objects": []}"#), "robot"),
        (
            "bad_size.json",
            Some(
                r#"{"robot": "a", "objects": [{"id": 1, "label": "chair", "centroid": [0, 0, 0], "size": [1, -1, 1]}]}"#,
            ),
            "size",
        ),
    ];
    for (name, text, expected) in cases {
        let path = match text {
            Some(t) => write(dir.path(), name, t),
            None => dir.path().join(name),
        };
        let out = sgm(&["match", good.to_str().unwrap(), path.to_str().unwrap()], &[]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{name}: {stderr}");
        assert!(out.stdout.is_empty(), "{name}: stdout must be empty");
        assert_eq!(stderr.trim().lines().count(), 1, "{name}: one line: {stderr}");
        assert!(stderr.contains(name), "{name}: names the file: {stderr}");
        assert!(stderr.contains(expected), "{name}: says what is wrong ({expected}): {stderr}");
    }
}

/// Ten objects over 40 m seen by a robot whose frame is yawed, shifted and tilted by 3° (roll and
/// pitch drift without an IMU); returns the files and the true local_from_remote.
fn tilted_pair(dir: &Path) -> (PathBuf, PathBuf, nalgebra::Isometry3<f64>) {
    use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
    let points = [
        (0.0, 0.0, 0.5, "chair"),
        (18.0, 3.0, 0.4, "bench"),
        (5.0, 27.0, 0.6, "chair"),
        (-14.0, 9.0, 0.3, "trash_can"),
        (24.0, 21.0, 2.5, "lamp_post"),
        (-6.0, -15.0, 0.4, "bench"),
        (11.0, -9.0, 0.5, "trash_can"),
        (-19.0, 24.0, 2.4, "lamp_post"),
        (30.0, -4.0, 0.6, "chair"),
        (2.0, 12.0, 0.4, "bench"),
    ];
    let axis = Unit::new_normalize(Vector3::new(0.6, 0.8, 0.0));
    let rotation = UnitQuaternion::from_axis_angle(&axis, 3f64.to_radians())
        * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.9);
    let local_from_remote = Isometry3::from_parts(Translation3::new(7.0, -4.0, 0.3), rotation);
    let object = |id: usize, p: Point3<f64>, label: &str| {
        format!(r#"{{"id": {id}, "label": "{label}", "centroid": [{}, {}, {}]}}"#, p.x, p.y, p.z)
    };
    let local: Vec<String> =
        points.iter().enumerate().map(|(k, &(x, y, z, l))| object(k, Point3::new(x, y, z), l)).collect();
    let remote: Vec<String> = points
        .iter()
        .enumerate()
        .map(|(k, &(x, y, z, l))| object(100 + k, local_from_remote.inverse() * Point3::new(x, y, z), l))
        .collect();
    let a = write(dir, "level.json", &format!(r#"{{"robot": "a", "objects": [{}]}}"#, local.join(",")));
    let b = write(dir, "tilted.json", &format!(r#"{{"robot": "b", "objects": [{}]}}"#, remote.join(",")));
    (a, b, local_from_remote)
}

#[test]
fn tilted_frames_match_with_the_tilt_in_the_transform() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b, truth) = tilted_pair(dir.path());
    let (a, b) = (a.to_str().unwrap(), b.to_str().unwrap());
    let out = sgm(&["match", a, b], &[]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let v: Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(v["success"], true, "{v}");
    let t: Vec<Vec<f64>> = serde_json::from_value(v["T"].clone()).unwrap();
    let expected = truth.to_homogeneous();
    for r in 0..4 {
        for c in 0..4 {
            assert!((t[r][c] - expected[(r, c)]).abs() < 1e-6, "T = {t:?}, truth {expected}");
        }
    }
    let matches: Vec<[u32; 2]> = serde_json::from_value(v["matches"].clone()).unwrap();
    assert_eq!(matches, (0..10).map(|k| [k, 100 + k]).collect::<Vec<_>>());
    // Gravity-aligned frames declared (an IMU): the transform stays x, y, z, yaw.
    let out = sgm(&["match", a, b], &[("SGM__MATCHER__MAX_TILT_DEG", "0")]);
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["success"], true, "{v}");
    let t: Vec<Vec<f64>> = serde_json::from_value(v["T"].clone()).unwrap();
    assert_eq!((t[2][0], t[2][1], t[0][2], t[1][2], t[2][2]), (0.0, 0.0, 0.0, 0.0, 1.0), "T = {t:?}");
}
