//! `sgm bench baselines`: paper §V-B, Table 3. Team ATE of SGM on `outdoor_two_robots` and
//! `indoor_three_robots` against three baselines run inside the same framework, same worlds,
//! same seeds:
//!
//! - **Swarm-SC (ours)**: `matcher.association = "scan_context"`, Scan Context descriptors of
//!   every keyframe instead of object data, then keyframe ICP (the paper's Swarm-SC).
//! - **no association**: `matcher.association = "none"`; every map stays in its own frame.
//! - **raw sharing, oracle join**: every LiDAR frame sent raw to a central server (the bytes
//!   of Table 4's "Point-cloud Raw"); its team ATE is that of the independent maps (the
//!   no-association run) joined by the true transforms, the best a central optimiser that
//!   keeps the robots' maps can do.
//!
//! The team ATE merges every robot (`Report::team_ate_all_start_guess_m`): a robot the
//! reference has not aligned sits at the reference's start frame, the only guess left without
//! association. A method that aligns wrongly or not at all pays for it.

use super::{
    aligned_right, duration_arg, load_cut, or_dash, radio_bytes, run_report, Section, PAPER_SCENARIOS, WRONG_M,
};
use serde::Serialize;
use sgm_actors::config::Association;
use sgm_scenarios::report::Report;
use std::fmt::Write;

/// The paper's Table 3: (Swarm-SC, Swarm-CP, SGM) team ATE, m.
fn paper(env: &str) -> [f64; 3] {
    match env {
        "Outdoor" => [20.29, 3.92, 1.32],
        _ => [3.36, 5.70, 0.81],
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct MethodRow {
    pub env: &'static str,
    pub method: &'static str,
    /// Team ATE of every robot (unaligned ones at the start-frame guess), m.
    pub team_ate_m: Option<f64>,
    /// Directed pairs aligned at the end, and of those farther than 2 m from the truth.
    pub aligned_pairs: usize,
    pub wrong_pairs: usize,
    pub pairs: usize,
    /// First alignment of any pair, s of mission.
    pub first_aligned_s: Option<f64>,
    /// Bytes the team sent over the radio.
    pub bytes_total: u64,
}

#[derive(Serialize)]
struct Environment {
    scenario: &'static str,
    env: &'static str,
    sim_s: f64,
    /// Swarm-SC's team ATE ÷ SGM's (target ≥ 3 outdoors).
    sc_over_sgm: Option<f64>,
    /// The paper's Swarm-SC, Swarm-CP and SGM team ATE, m.
    paper: [f64; 3],
}

#[derive(Serialize)]
struct Json {
    command: String,
    rows: Vec<MethodRow>,
    environments: Vec<Environment>,
}

fn method_row(env: &'static str, method: &'static str, r: &Report) -> MethodRow {
    let aligned: Vec<_> = r.alignments.iter().filter(|a| a.state == "Aligned").collect();
    let wrong = aligned.iter().filter(|a| !aligned_right(a)).count();
    MethodRow {
        env,
        method,
        team_ate_m: r.team_ate_all_start_guess_m,
        aligned_pairs: aligned.len(),
        wrong_pairs: wrong,
        pairs: r.alignments.len(),
        first_aligned_s: r.alignments.iter().filter_map(|a| a.first_aligned_s).min_by(f64::total_cmp),
        bytes_total: radio_bytes(r),
    }
}

/// `duration`: cut each mission to this many seconds (the test suite's reduced mode).
pub fn run_bench(duration: Option<f64>) -> anyhow::Result<Section> {
    let (mut rows, mut environments) = (Vec::new(), Vec::new());
    for (name, env) in PAPER_SCENARIOS {
        let mut by_method = Vec::new();
        let mut sim_s = 0.0;
        for (association, method) in [
            (Association::Objects, "SGM"),
            (Association::ScanContext, "Swarm-SC (ours)"),
            (Association::None, "no association"),
        ] {
            let mut scenario = load_cut(name, duration)?;
            scenario.matcher.association = association;
            let r = run_report(&scenario, &format!("{name}, {method}"))?;
            sim_s = r.sim_s;
            by_method.push(method_row(env, method, &r));
            if association == Association::None {
                // The central server gets every frame raw; it joins the independent maps.
                let pairs = r.robots.len() * r.robots.len().saturating_sub(1);
                let raw = MethodRow {
                    env,
                    method: "raw sharing, oracle join",
                    team_ate_m: r.team_ate_oracle_join_m,
                    aligned_pairs: pairs,
                    wrong_pairs: 0,
                    pairs,
                    first_aligned_s: None,
                    bytes_total: r.point_cloud_raw.bytes_total,
                };
                by_method.push(raw);
            }
        }
        let ate = |method: &str| by_method.iter().find(|r| r.method == method).and_then(|r| r.team_ate_m);
        let sc_over_sgm = match (ate("Swarm-SC (ours)"), ate("SGM")) {
            (Some(sc), Some(sgm)) if sgm > 0.0 => Some(sc / sgm),
            _ => None,
        };
        environments.push(Environment { scenario: name, env, sim_s, sc_over_sgm, paper: paper(env) });
        rows.extend(by_method);
    }
    let command = format!("sgm bench baselines{}", duration_arg(duration));
    let markdown = table(&command, &rows, &environments);
    Ok(Section { markdown, json: serde_json::to_value(Json { command, rows, environments })? })
}

fn table(command: &str, rows: &[MethodRow], environments: &[Environment]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Team ATE against baselines, paper §V-B Table 3\n");
    let _ = writeln!(s, "Command: `{command}`. Team ATE RMSE of every robot's keyframes, one SE(3) alignment;");
    let _ = writeln!(s, "a robot not aligned to the reference sits at the reference's start frame. Wrong: an");
    let _ = writeln!(s, "alignment more than {WRONG_M} m from the truth.\n");
    let _ = writeln!(s, "| env. | method | team ATE m | aligned pairs (wrong) | first alignment s | radio MB |");
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} of {} ({}) | {} | {:.2} |",
            r.env,
            r.method,
            or_dash(r.team_ate_m, 2),
            r.aligned_pairs,
            r.pairs,
            r.wrong_pairs,
            or_dash(r.first_aligned_s, 0),
            r.bytes_total as f64 / 1e6
        );
    }
    let _ = writeln!(
        s,
        "\n| env. | simulated s | Swarm-SC ÷ SGM (target ≥ 3 outdoors) | paper: Swarm-SC / Swarm-CP / SGM m |"
    );
    let _ = writeln!(s, "|---|---|---|---|");
    for e in environments {
        let _ = writeln!(
            s,
            "| {} | {:.0} | {} | {:.2} / {:.2} / {:.2} |",
            e.env,
            e.sim_s,
            e.sc_over_sgm.map_or("–".into(), |r| format!("{r:.1}×")),
            e.paper[0],
            e.paper[1],
            e.paper[2]
        );
    }
    s
}
