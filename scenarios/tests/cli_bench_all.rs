//! `sgm bench all` in reduced mode (1 matching repetition, missions cut to 20 s, fewer sweep
//! values): one report with every bench's tables and rows, the JSON beside it, and the plots.

use std::process::Command;

#[test]
fn bench_all_writes_every_table_with_its_rows() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("report");
    let run = Command::new(env!("CARGO_BIN_EXE_sgm"))
        .args(["bench", "all", "--reps", "1", "--duration", "20", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    for heading in [
        "## Object-graph matching, paper §V-A",
        "### Table 1",
        "### Table 2",
        "### Frames tilted by 3°",
        "## Team ATE against baselines, paper §V-B Table 3",
        "## Message sizes, paper §V-C Table 4",
        "## Sweeps",
        "### Mislabel rate",
        "### Trajectory overlap",
        "### Trajectory overlap, Swarm-SC (ours)",
        "### Centroid noise",
        "### Team size",
        "## Wrong inter-robot closures",
    ] {
        assert!(md.contains(heading), "{heading} missing from\n{md}");
    }
    // Every section names the command that reproduces it.
    for command in [
        "`sgm bench matching --reps 1 --seed 1`",
        "`sgm bench baselines --duration 20`",
        "`sgm bench messages --duration 20`",
        "`sgm bench sweeps --duration 20`",
        "`sgm bench outliers --scenario faults/clean --duration 20`",
    ] {
        assert!(md.contains(command), "{command} missing");
    }
    assert!(md.contains("| Outdoor | 20 | ") && md.contains("20.29 / 3.92 / 1.32"), "the paper's Table 3 beside ours");

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let len = |v: &serde_json::Value| v.as_array().map_or(0, Vec::len);
    assert_eq!((len(&json["matching"]["table1"]), len(&json["matching"]["table2"])), (3, 4));
    assert_eq!(len(&json["matching"]["false_claims"]), 3);
    assert_eq!(len(&json["matching"]["tilted"]), 2);

    let rows = json["baselines"]["rows"].as_array().unwrap();
    let methods = ["SGM", "Swarm-SC (ours)", "no association", "raw sharing, oracle join"];
    for env in ["Outdoor", "Indoor"] {
        let of_env: Vec<&serde_json::Value> = rows.iter().filter(|r| r["env"] == env).collect();
        let names: Vec<&str> = of_env.iter().map(|r| r["method"].as_str().unwrap()).collect();
        assert_eq!(names, methods, "{env}");
        let bytes = |m: &str| of_env.iter().find(|r| r["method"] == m).unwrap()["bytes_total"].as_u64().unwrap();
        assert!(bytes("Swarm-SC (ours)") > 0, "{env}: descriptors went out");
        assert!(bytes("raw sharing, oracle join") > 100 * bytes("SGM").max(1), "{env}: raw dwarfs SGM");
        let none = of_env.iter().find(|r| r["method"] == "no association").unwrap();
        assert_eq!(none["aligned_pairs"], 0, "{env}: nothing aligns without association");
        let oracle = of_env.iter().find(|r| r["method"] == "raw sharing, oracle join").unwrap();
        assert!(oracle["team_ate_m"].as_f64().unwrap() < 1.0, "{env}: {oracle}");
    }
    assert_eq!(len(&json["messages"]["environments"]), 2);

    // The clean run, then gross and subtle false factors at seven fractions each.
    let outliers = json["outliers"]["rows"].as_array().unwrap();
    assert_eq!(outliers.len(), 15);
    assert_eq!((outliers[0]["kind"].as_str(), outliers[0]["false_injected"].as_u64()), (Some("none"), Some(0)));
    assert_eq!(outliers[0]["honest_rejected"].as_u64(), Some(0), "the clean run rejected a correct factor");
    for r in &outliers[1..] {
        assert!(r["false_rejected"].as_u64() <= r["false_injected"].as_u64(), "{r}");
    }

    let sweeps = &json["sweeps"];
    for key in ["mislabel_rate", "overlap", "overlap_scan_context", "centroid_noise", "team_size"] {
        assert_eq!(len(&sweeps[key]), 2, "{key}: two values in reduced mode");
    }
    let overlap: Vec<f64> = sweeps["overlap"].as_array().unwrap().iter().map(|p| p["x"].as_f64().unwrap()).collect();
    assert!(overlap[0] > 0.9 && overlap[1] < overlap[0], "moving bravo away lowers the overlap: {overlap:?}");
    let sc: Vec<f64> =
        sweeps["overlap_scan_context"].as_array().unwrap().iter().map(|p| p["x"].as_f64().unwrap()).collect();
    assert_eq!(sc, overlap, "Swarm-SC runs the same missions");
    let team: Vec<f64> =
        sweeps["team_size"].as_array().unwrap().iter().map(|p| p["raw_bytes"].as_f64().unwrap()).collect();
    assert!(team[1] > 1.5 * team[0], "twice the robots, about twice the raw bytes: {team:?}");
    for plot in [
        "sweep_mislabel_success.png",
        "sweep_mislabel_error.png",
        "sweep_overlap_success.png",
        "sweep_overlap_error.png",
        "sweep_centroid_noise_success.png",
        "sweep_centroid_noise_error.png",
        "sweep_team_size_bytes.png",
    ] {
        let bytes = std::fs::read(out.join(plot)).unwrap_or_else(|e| panic!("{plot}: {e}"));
        assert!(bytes.starts_with(b"\x89PNG"), "{plot}");
    }
}
