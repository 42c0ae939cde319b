//! `sgm bench outliers`: how much wrong inter-robot closures cost the team. A mission is run
//! clean; then, for each fraction f of wrong closures, every aligned pair gets
//! ⌈N·f/(1−f)⌉ false factors (`[[false_factors]]`, `sim::false_factors`: each exactly as wrong
//! as the row says about a random axis, claimed as confident as an ICP registration), N being
//! the inter-robot factors that pair held at the end of the clean run; so f of all its
//! inter-robot factors are wrong. They come at once, 5 s after the pair first aligned, when
//! the pair holds only its first round's factors: early on the wrong ones are even more of
//! them. The table gives the team ATE against the clean run's, how many of the false factors
//! the back end rejected (PCM, then GNC-TLS), how many honest factors it rejected with them,
//! the directions whose robot holds its neighbour suspect, and the pairs still aligned right.

use super::{aligned_right, duration_arg, load_cut, or_dash, run_all, Job, Section};
use serde::Serialize;
use sgm_scenarios::report::Report;
use sgm_scenarios::scenario::{FalseFactorSpec, Scenario};
use std::fmt::Write;

/// Fractions of wrong inter-robot factors measured.
const FRACTIONS: [f64; 8] = [0.0, 0.1, 0.3, 0.5, 0.6, 0.7, 0.8, 0.9];

/// How wrong the false factors are: (name, translation m, rotation °).
const KINDS: [(&str, f64, f64); 2] = [("gross", 5.0, 30.0), ("subtle", 1.0, 5.0)];

#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub kind: String,
    pub fraction: f64,
    pub false_injected: usize,
    pub false_rejected: usize,
    /// Honest factors rejected (intra-robot loop closures and true inter-robot factors): what
    /// the defence cost.
    pub honest_rejected: usize,
    /// Inter-robot factors outside the largest consistent sets (PCM), all pairs.
    pub inconsistent: usize,
    /// Directions whose local robot holds the remote suspect at the end
    /// (`alignments[].suspect`): the attacked ones should be.
    pub suspect: usize,
    pub pairs: usize,
    pub aligned_right: usize,
    pub team_ate_m: Option<f64>,
    /// Team ATE over the clean run's, −1: 0.1 is 10 % worse.
    pub vs_clean: Option<f64>,
}

/// The false factors that make `fraction` of each aligned pair's inter-robot factors wrong.
fn injections(
    clean: &Report,
    scenario: &Scenario,
    fraction: f64,
    translation_m: f64,
    rotation_deg: f64,
) -> Vec<FalseFactorSpec> {
    if fraction <= 0.0 {
        return Vec::new();
    }
    clean
        .alignments
        .iter()
        .filter_map(|a| {
            let at_s = a.first_aligned_s? + 5.0;
            let count = (a.inter_robot_factors as f64 * fraction / (1.0 - fraction)).ceil() as usize;
            (count > 0 && at_s < scenario.scenario.duration_s).then(|| FalseFactorSpec {
                robot: a.local.clone(),
                neighbour: a.remote.clone(),
                at_s,
                count,
                translation_m,
                rotation_deg,
            })
        })
        .collect()
}

fn row(kind: &str, fraction: f64, report: &Report, clean_ate: Option<f64>) -> Row {
    let team_ate_m = report.team_ate_rmse_m;
    Row {
        kind: kind.into(),
        fraction,
        false_injected: report.back_end.false_factors_injected,
        false_rejected: report.back_end.false_factors_rejected,
        honest_rejected: report.back_end.rejected_factors.saturating_sub(report.back_end.false_factors_rejected),
        inconsistent: report.alignments.iter().map(|a| a.inconsistent_factors).sum(),
        suspect: report.alignments.iter().filter(|a| !a.suspect.is_empty()).count(),
        pairs: report.alignments.len(),
        aligned_right: report.alignments.iter().filter(|a| aligned_right(a)).count(),
        team_ate_m,
        vs_clean: team_ate_m.zip(clean_ate).map(|(a, c)| a / c - 1.0),
    }
}

/// Runs the clean mission, then every kind and fraction (on every core).
pub fn run_bench(scenario_name: &str, duration: Option<f64>) -> anyhow::Result<Section> {
    let base = load_cut(scenario_name, duration)?;
    let label = |what: &str| format!("outliers: {scenario_name}, {what}");
    let clean = run_all(vec![Job { row: 0, seed: base.scenario.seed, scenario: base.clone(), label: label("clean") }])?
        .pop()
        .map(|(_, _, r)| r)
        .ok_or_else(|| anyhow::anyhow!("the clean run gave no report"))?;
    let mut jobs = Vec::new();
    let mut rows = Vec::new();
    for (kind, translation_m, rotation_deg) in KINDS {
        for fraction in FRACTIONS.iter().copied().filter(|f| *f > 0.0) {
            let mut scenario = base.clone();
            scenario.false_factors = injections(&clean, &scenario, fraction, translation_m, rotation_deg);
            let what = format!("{kind}, {:.0} % wrong", fraction * 100.0);
            jobs.push(Job { row: rows.len(), seed: scenario.scenario.seed, scenario, label: label(&what) });
            rows.push((kind, fraction));
        }
    }
    let clean_ate = clean.team_ate_rmse_m;
    let mut out = vec![row("none", 0.0, &clean, clean_ate)];
    for (k, _, report) in run_all(jobs)? {
        let (kind, fraction) = rows[k];
        out.push(row(kind, fraction, &report, clean_ate));
    }
    let command = format!("sgm bench outliers --scenario {scenario_name}{}", duration_arg(duration));
    let mut md = format!("# Wrong inter-robot closures\n\nCommand: `{command}`.\n\n");
    md.push_str("| False factors | Wrong | Injected | Rejected | Inconsistent (PCM) | Honest rejected | Held suspect | Pairs aligned | Team ATE | vs clean |\n|---|---|---|---|---|---|---|---|---|---|\n");
    for r in &out {
        let how = KINDS
            .iter()
            .find(|k| k.0 == r.kind)
            .map_or("—".to_string(), |k| format!("{} ({} m, {}°)", k.0, k.1, k.2));
        let _ = writeln!(
            md,
            "| {how} | {:.0} % | {} | {} | {} | {} | {}/{} | {}/{} | {} m | {} |",
            r.fraction * 100.0,
            r.false_injected,
            r.false_rejected,
            r.inconsistent,
            r.honest_rejected,
            r.suspect,
            r.pairs,
            r.aligned_right,
            r.pairs,
            or_dash(r.team_ate_m, 3),
            r.vs_clean.map_or("—".into(), |v| format!("{:+.1} %", v * 100.0)),
        );
    }
    Ok(Section { markdown: md, json: serde_json::json!({ "command": command, "rows": out }) })
}
