//! `sgm encode-cloud` contract.

use serde_json::Value;
use std::path::PathBuf;
use std::process::Command;

fn sgm(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_sgm")).args(args).output().expect("sgm runs")
}

#[test]
fn reports_size_and_error_of_a_real_cloud() {
    let kinect = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/clouds/kinect_frame_20121214T142255.814212.pcd");
    let out = sgm(&["encode-cloud", kinect.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    let keys: Vec<&String> = v.as_object().unwrap().keys().collect();
    assert_eq!(keys, ["bytes", "bytes_per_point", "max_error", "points"]);
    assert_eq!(v["points"], 271_575);
    assert!(v["bytes_per_point"].as_f64().unwrap() <= 3.0);
    assert!(v["max_error"].as_f64().unwrap() <= 3f64.sqrt() * 0.005 + 1e-9);
}

#[test]
fn bad_files_and_resolutions_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.pcd");
    std::fs::write(&bad, "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F X\n").unwrap();
    let out = sgm(&["encode-cloud", bad.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("bad.pcd") && stderr.contains("header line 4"), "{stderr}");
    let ok = dir.path().join("ok.pcd");
    std::fs::write(&ok, "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nHEIGHT 1\nDATA ascii\n1 2 3\n").unwrap();
    let out = sgm(&["encode-cloud", ok.to_str().unwrap(), "--resolution", "-1"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("resolution"));
    assert_eq!(sgm(&["encode-cloud", dir.path().join("none.pcd").to_str().unwrap()]).status.code(), Some(2));
}
