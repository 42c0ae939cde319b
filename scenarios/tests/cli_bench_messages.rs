//! `sgm bench messages` in reduced mode: both environments, every message type, the paper's
//! figures beside ours, and the raw point-cloud row consistent with the missions.

use std::process::Command;

#[test]
fn the_table_4_bench_has_every_row() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("messages.json");
    let out = Command::new(env!("CARGO_BIN_EXE_sgm"))
        .args(["bench", "messages", "--duration", "20", "--json"])
        .arg(&json)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("| ObjectData | Outdoor | 7.76 / **"), "{stdout}");
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(report["command"], "sgm bench messages --duration 20");
    let rows = report["rows"].as_array().unwrap();
    let kinds = ["PointCloudRaw", "ObjectData", "KeyframeRequest", "KeyframeResponse", "ObjectCloudRequest"];
    for env in ["Outdoor", "Indoor"] {
        let of_env: Vec<&serde_json::Value> = rows.iter().filter(|r| r["env"] == env).collect();
        assert_eq!(of_env.len(), 1 + sgm_model::wire::MessageKind::ALL.len(), "raw + every message type in {env}");
        assert_eq!(of_env[0]["kind"], "PointCloudRaw");
        assert_eq!(of_env[1]["kind"], "ObjectData", "the paper's order");
        for kind in kinds {
            let row = of_env.iter().find(|r| r["kind"] == kind).unwrap_or_else(|| panic!("{kind} in {env}"));
            let ours = &row["ours"];
            let count = ours["count"].as_u64().unwrap();
            let (total, max) = (ours["bytes_total"].as_u64().unwrap(), ours["bytes_max"].as_u64().unwrap());
            assert!(max * count >= total && (count == 0) == (total == 0), "{env} {kind}: {ours}");
        }
        assert!(of_env.iter().filter(|r| !r["paper"].is_null()).count() == 4, "{env}: the paper's four rows");
    }
    for e in report["environments"].as_array().unwrap() {
        assert_eq!(e["sim_s"].as_f64(), Some(20.0), "{e}");
        let ratio = e["total_bytes"].as_f64().unwrap() / e["raw_bytes"].as_f64().unwrap();
        assert!((ratio - e["ratio_to_raw"].as_f64().unwrap()).abs() < 1e-12 && ratio < 0.05, "{e}");
    }
}
