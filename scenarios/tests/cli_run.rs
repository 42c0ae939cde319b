//! `sgm run` on bad input: a clear message on stderr and exit 2, before any simulation.

use std::process::{Command, Output};

fn sgm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sgm")).args(args).output().expect("sgm runs")
}

#[test]
fn an_unknown_scenario_is_named_with_the_library() {
    let out = sgm(&["run", "no_such_scenario", "--quiet"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no_such_scenario") && err.contains("outdoor_two_robots"), "{err}");
}

#[test]
fn a_bad_scenario_file_names_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.toml");
    std::fs::write(&path, "[radio]\nloss = 2.0\n[[robots]]\nwaypoints = [[0.0, 0.0], [5.0, 0.0]]\n").unwrap();
    let out = sgm(&["run", path.to_str().unwrap(), "--quiet"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("radio.loss = 2") && err.contains("bad.toml"), "{err}");
}

#[test]
fn an_unwritable_report_directory_fails_before_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a_file");
    std::fs::write(&file, "").unwrap();
    let out = sgm(&["run", "--quiet", "--out", file.join("report").to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("cannot create the report directory"), "{err}");
}
