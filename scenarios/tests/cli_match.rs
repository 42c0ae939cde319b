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
