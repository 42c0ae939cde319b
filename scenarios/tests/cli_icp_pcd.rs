//! `sgm icp` and `sgm pcd-convert` contracts.

use serde_json::Value;
use std::path::PathBuf;
use std::process::Command;

fn sgm(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_sgm")).args(args).output().expect("sgm runs")
}

fn cloud(name: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/clouds").join(name).display().to_string()
}

#[test]
fn icp_prints_the_contract_and_aligns_the_kinect_frames() {
    let (a, b) = (cloud("kinect_frame_20121214T142256.068683.pcd"), cloud("kinect_frame_20121214T142255.814212.pcd"));
    let out = sgm(&["icp", &a, &b, "--voxel", "0.02", "--max-distance", "0.1"]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    let keys: Vec<&String> = v.as_object().unwrap().keys().collect();
    assert_eq!(keys, ["T", "converged", "fitness", "iterations", "rmse", "time_ms"]);
    assert_eq!(v["converged"], true);
    assert!(v["fitness"].as_f64().unwrap() > 0.9 && v["rmse"].as_f64().unwrap() < 0.02);
    // Consecutive frames 0.25 s apart: a small motion.
    let t: Vec<Vec<f64>> = serde_json::from_value(v["T"].clone()).unwrap();
    assert!(t[0][3].abs() < 0.1 && t[1][3].abs() < 0.1 && t[2][3].abs() < 0.1 && t[3] == [0.0, 0.0, 0.0, 1.0]);
    // Point-to-point with an explicit initial guess also runs.
    let out = sgm(&["icp", &a, &b, "--method", "point-to-point", "--voxel", "0.02", "--init", "0,0,0,0,0,0"]);
    assert_eq!(out.status.code(), Some(0));
}

#[test]
fn icp_bad_input_exits_2() {
    let b = cloud("bun0.pcd");
    for args in [
        vec!["icp", "/nonexistent.pcd", b.as_str()],
        vec!["icp", b.as_str(), b.as_str(), "--init", "1,2,3"],
        vec!["icp", b.as_str(), b.as_str(), "--max-distance", "-1"],
        vec!["icp", b.as_str(), b.as_str(), "--voxel", "nan"],
    ] {
        let out = sgm(&args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(out.stdout.is_empty());
        assert!(!out.stderr.is_empty());
    }
}

#[test]
fn pcd_convert_round_trips_every_format() {
    let dir = tempfile::tempdir().unwrap();
    let source = cloud("bun0.pcd");
    let mut previous = None;
    for format in ["binary-compressed", "binary", "ascii"] {
        let out_path = dir.path().join(format!("{format}.pcd"));
        let input = previous.clone().unwrap_or(source.clone());
        let out = sgm(&["pcd-convert", &input, out_path.to_str().unwrap(), "--format", format]);
        assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
        previous = Some(out_path.display().to_string());
    }
    let original = std::fs::read_to_string(&source).unwrap();
    let back = std::fs::read_to_string(previous.unwrap()).unwrap();
    let data =
        |t: &str| t.lines().skip_while(|l| !l.starts_with("DATA")).skip(1).map(str::to_owned).collect::<Vec<_>>();
    assert_eq!(data(&original).len(), 397);
    for (a, b) in data(&original).iter().zip(data(&back)) {
        let x: Vec<f32> = a.split_whitespace().map(|v| v.parse().unwrap()).collect();
        let y: Vec<f32> = b.split_whitespace().map(|v| v.parse().unwrap()).collect();
        assert_eq!(x, y);
    }
    let bad = dir.path().join("bad.pcd");
    std::fs::write(&bad, "FIELDS x\n").unwrap();
    assert_eq!(
        sgm(&["pcd-convert", bad.to_str().unwrap(), dir.path().join("o.pcd").to_str().unwrap()]).status.code(),
        Some(2)
    );
}
