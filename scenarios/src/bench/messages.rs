//! `sgm bench messages`: paper §V-C, Table 4. Every message type's mean, max and count over a
//! whole mission of `outdoor_two_robots` and `indoor_three_robots`, beside "Point-cloud Raw"
//! (every LiDAR frame sent as a raw PointCloud2 to a central server, the paper's bandwidth
//! upper bound) and the paper's own figures. Sizes are whole sealed envelopes (header, payload
//! and MAC), in KB of 1000 bytes as the paper's table appears to use.

use super::{duration_arg, load_cut, radio_bytes, run_report, Section, PAPER_SCENARIOS};
use serde::Serialize;
use sgm_scenarios::report::MessageRow;
use std::fmt::Write;

const PAPER_ORDER: [&str; 3] = ["ObjectData", "KeyframeRequest", "KeyframeResponse"];

/// The paper's Table 4 (KB mean, KB max, count) per message type and environment.
fn paper(kind: &str, env: &str) -> Option<[f64; 3]> {
    Some(match (kind, env) {
        ("PointCloudRaw", "Outdoor") => [508.2, 516.9, 3073.0],
        ("PointCloudRaw", "Indoor") => [508.1, 512.1, 3079.0],
        ("ObjectData", "Outdoor") => [7.76, 16.93, 701.0],
        ("ObjectData", "Indoor") => [18.40, 44.37, 845.0],
        ("KeyframeRequest", "Outdoor") => [0.02, 0.02, 61.0],
        ("KeyframeRequest", "Indoor") => [0.02, 0.02, 411.0],
        ("KeyframeResponse", "Outdoor") => [18.87, 22.95, 10.0],
        ("KeyframeResponse", "Indoor") => [6.90, 11.05, 72.0],
        _ => return None,
    })
}

#[derive(Serialize)]
struct Row {
    kind: String,
    env: &'static str,
    ours: MessageRow,
    /// KB mean, KB max, count.
    paper: Option<[f64; 3]>,
}

#[derive(Serialize)]
struct Environment {
    scenario: &'static str,
    env: &'static str,
    sim_s: f64,
    total_bytes: u64,
    raw_bytes: u64,
    /// Total SGM bytes ÷ raw point-cloud bytes (target ≤ 1 %).
    ratio_to_raw: f64,
    aligned_pairs: usize,
    pairs: usize,
}

#[derive(Serialize)]
struct Report {
    command: String,
    rows: Vec<Row>,
    environments: Vec<Environment>,
}

/// `duration`: cut each mission to this many seconds (the test suite's reduced mode).
pub fn run_bench(duration: Option<f64>) -> anyhow::Result<Section> {
    let (mut rows, mut environments) = (Vec::new(), Vec::new());
    for (name, env) in PAPER_SCENARIOS {
        let r = run_report(&load_cut(name, duration)?, name)?;
        rows.push(Row {
            kind: "PointCloudRaw".into(),
            env,
            ours: r.point_cloud_raw,
            paper: paper("PointCloudRaw", env),
        });
        // The paper's rows first, in its order; then the messages it does not list.
        let mut kinds: Vec<&String> = r.messages.keys().collect();
        kinds.sort_by_key(|k| (PAPER_ORDER.iter().position(|p| p == k).unwrap_or(PAPER_ORDER.len()), k.as_str()));
        for kind in kinds {
            rows.push(Row { kind: kind.clone(), env, ours: r.messages[kind], paper: paper(kind, env) });
        }
        environments.push(Environment {
            scenario: name,
            env,
            sim_s: r.sim_s,
            total_bytes: radio_bytes(&r),
            raw_bytes: r.point_cloud_raw.bytes_total,
            ratio_to_raw: r.bytes_ratio_to_raw,
            aligned_pairs: r.alignments.iter().filter(|a| a.first_aligned_s.is_some()).count(),
            pairs: r.alignments.len(),
        });
    }
    let command = format!("sgm bench messages{}", duration_arg(duration));
    let markdown = table(&command, &rows, &environments);
    Ok(Section { markdown, json: serde_json::to_value(Report { command, rows, environments })? })
}

fn kb(bytes: f64) -> String {
    format!("{:.2}", bytes / 1000.0)
}

fn table(command: &str, rows: &[Row], environments: &[Environment]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Message sizes, paper §V-C Table 4\n");
    let _ = writeln!(s, "Command: `{command}`. Sizes in KB (1000 bytes) of whole sealed envelopes; each cell is");
    let _ = writeln!(s, "paper / **ours**; \"–\" where the paper has no such message.\n");
    let _ = writeln!(s, "| message type | env. | mean KB | max KB | count |");
    let _ = writeln!(s, "|---|---|---|---|---|");
    for r in rows {
        let p = |k: usize, decimals: usize| r.paper.map_or("–".to_string(), |p| format!("{:.decimals$}", p[k]));
        let _ = writeln!(
            s,
            "| {} | {} | {} / **{}** | {} / **{}** | {} / **{}** |",
            r.kind,
            r.env,
            p(0, 2),
            kb(r.ours.bytes_mean),
            p(1, 2),
            kb(r.ours.bytes_max as f64),
            p(2, 0),
            r.ours.count
        );
    }
    let _ = writeln!(s, "\n| env. | simulated s | SGM total MB | raw total MB | SGM ÷ raw | aligned pairs |");
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for e in environments {
        let _ = writeln!(
            s,
            "| {} | {:.0} | {:.2} | {:.1} | {:.3} % | {} of {} |",
            e.env,
            e.sim_s,
            e.total_bytes as f64 / 1e6,
            e.raw_bytes as f64 / 1e6,
            e.ratio_to_raw * 100.0,
            e.aligned_pairs,
            e.pairs
        );
    }
    s
}
