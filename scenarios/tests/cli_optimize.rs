//! `sgm optimize` CLI contract: JSON shape, output file, multi-robot input, exit codes.

use serde_json::Value;
use std::path::PathBuf;
use std::process::{Command, Output};

fn sgm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sgm")).args(args).output().expect("sgm runs")
}

fn shared(path: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data").join(path).display().to_string()
}

#[test]
fn json_has_exactly_the_contract_keys_and_output_reloads_at_the_optimum() {
    let dir = tempfile::tempdir().unwrap();
    let out_path = dir.path().join("opt.g2o");
    let input = shared("posegraph/2d/intel.g2o");
    let out = sgm(&["optimize", &input, "--json", "-o", out_path.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let v: Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    let keys: Vec<&String> = v.as_object().unwrap().keys().collect();
    assert_eq!(keys, ["final_error", "initial_error", "iterations", "rejected", "time_ms"]);
    assert!((v["final_error"].as_f64().unwrap() - 22.502117).abs() < 1e-5);
    assert_eq!(v["iterations"], 3);
    assert_eq!(v["rejected"], serde_json::json!([]));
    // Re-optimising the written graph starts at the optimum.
    let again = sgm(&["optimize", out_path.to_str().unwrap(), "--json"]);
    let w: Value = serde_json::from_slice(&again.stdout).unwrap();
    assert!((w["initial_error"].as_f64().unwrap() - 22.502117).abs() < 1e-4, "{w}");
}

#[test]
fn several_files_are_one_multi_robot_graph_and_kernels_run() {
    let a = shared("multirobot/example_2robots/0.g2o");
    let b = shared("multirobot/example_2robots/1.g2o");
    for robust in ["none", "huber", "cauchy", "gnc"] {
        let out = sgm(&["optimize", &a, &b, "--robust", robust, "--json"]);
        assert_eq!(out.status.code(), Some(0), "{robust}");
        let v: Value = serde_json::from_slice(&out.stdout).unwrap();
        assert!(v["final_error"].as_f64().unwrap() < v["initial_error"].as_f64().unwrap(), "{robust}: {v}");
    }
    let text = sgm(&["optimize", &a, &b]);
    let stdout = String::from_utf8_lossy(&text.stdout);
    assert!(stdout.contains("initial error") && stdout.contains("final error"), "{stdout}");
}

#[test]
fn malformed_or_missing_files_exit_2_with_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.g2o");
    std::fs::write(&bad, "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0\n").unwrap();
    let out = sgm(&["optimize", bad.to_str().unwrap(), "--json"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(out.stdout.is_empty());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("bad.g2o") && stderr.contains("line 3") && stderr.contains("needs 9 numbers"), "{stderr}");
    let out = sgm(&["optimize", dir.path().join("missing.g2o").to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.g2o"));
}
