//! `sgm run [SCENARIO] [--out DIR] [--seed N] [--quiet] [--bag-out DIR] [--no-result-bag] [--threads N]`:
//! runs a scenario (a library name or a TOML file; default `quickstart`) on the virtual clock
//! and writes its report directory (default: a fresh folder under `runs/`), with the team's
//! result as `result.bag` for RViz. Prints a one-screen summary.

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use sgm_scenarios::record::Timing;
use sgm_scenarios::report::{self, Report};
use sgm_scenarios::runner::{run_with, RunOutputs};
use sgm_scenarios::scenario::Scenario;
use sgm_scenarios::threads::Threads;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

pub struct Options {
    pub scenario: Option<String>,
    pub out: Option<PathBuf>,
    pub seed: Option<u64>,
    pub quiet: bool,
    pub bag_out: Option<PathBuf>,
    /// Write `result.bag` into the report directory.
    pub result_bag: bool,
    /// `--threads N` (default: every core).
    pub threads: Option<usize>,
}

/// `--threads N`: 0 is refused, more than the cores is cut to them (with a warning).
pub fn threads(requested: Option<usize>) -> Result<Threads> {
    Ok(match requested {
        Some(n) => Threads::requested(n)?,
        None => Threads::all_cores(),
    })
}

/// The result bag's name in a report directory.
pub const RESULT_BAG: &str = "result.bag";

/// `runs/NAME`, or with `-2`, `-3`, … if taken.
pub fn fresh_run_dir(name: &str) -> PathBuf {
    let first = Path::new("runs").join(name);
    if !first.exists() {
        return first;
    }
    (2..).map(|k| Path::new("runs").join(format!("{name}-{k}"))).find(|p| !p.exists()).unwrap_or(first)
}

pub fn execute(options: Options) -> Result<()> {
    let threads = threads(options.threads)?;
    let name = options.scenario.as_deref().unwrap_or("quickstart");
    let mut scenario = Scenario::load(name)?;
    if let Some(seed) = options.seed {
        scenario = scenario.with_seed(seed);
    }
    let dir = options
        .out
        .unwrap_or_else(|| fresh_run_dir(&format!("{}-seed{}", scenario.scenario.name, scenario.scenario.seed)));
    // Fail before the run, not after it, when the report cannot be written.
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create the report directory {}", dir.display()))?;
    let bar = progress_bar(options.quiet, "{prefix} [{bar:40}] {pos}/{len} steps, {elapsed} wall, eta {eta}");
    bar.set_prefix(format!("{} (seed {})", scenario.scenario.name, scenario.scenario.seed));
    let system = actix_rt::System::new();
    let result_bag = options.result_bag.then(|| dir.join(RESULT_BAG));
    let outputs = RunOutputs { bag_out: options.bag_out.as_deref(), result_bag: result_bag.as_deref(), threads };
    let outcome = system.block_on(run_with(&scenario, Some(&bar), outputs)).context("the run failed")?;
    bar.finish_and_clear();
    let report = report::write(&outcome, &dir).context("writing the report")?;
    let mut text = summary(&report, &outcome.timing, &dir);
    if let Some(bags) = &options.bag_out {
        let _ = writeln!(text, "bags: {}", bags.display());
    }
    if let Some(path) = &result_bag {
        let _ = writeln!(text, "result bag (RViz: bridge/ros/sgm/rviz/team.rviz): {}", path.display());
    }
    if !super::stdout::emit_text("run", &text) {
        anyhow::bail!("the summary could not be written (the report is in {})", dir.display());
    }
    Ok(())
}

/// An indicatif bar with `template` (hidden when `quiet`).
pub fn progress_bar(quiet: bool, template: &str) -> ProgressBar {
    let bar = if quiet { ProgressBar::hidden() } else { ProgressBar::new(0) };
    bar.set_style(
        ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_bar()).progress_chars("=> "),
    );
    bar
}

pub fn summary(report: &Report, timing: &Timing, dir: &Path) -> String {
    let mut s = String::new();
    let m = |v: Option<f64>| v.map_or("—".to_string(), |v| format!("{v:.2} m"));
    let _ = writeln!(
        s,
        "{}: {:.0} s simulated in {:.1} s ({:.0}× real time)",
        report.scenario, report.sim_s, timing.wall_s, timing.realtime_factor
    );
    match report.team_ate_rmse_m {
        Some(ate) => {
            let _ = writeln!(s, "team ATE RMSE {ate:.2} m over {}", report.team_ate_robots.join(", "));
        }
        None => {
            let _ = writeln!(s, "team ATE RMSE — (no ground truth, or no robot aligned)");
        }
    }
    for r in &report.robots {
        let _ = writeln!(
            s,
            "  {:<10} ATE {:>8}  {:>4} keyframes  {:>3} objects{}  {:>5.0} m",
            r.name,
            m(r.ate_rmse_m),
            r.keyframes,
            r.confirmed_objects,
            match (r.objects_found, r.objects_spurious) {
                (Some(found), Some(spurious)) => format!(" ({found} found, {spurious} spurious)"),
                _ => String::new(),
            },
            r.distance_m
        );
    }
    for a in &report.alignments {
        let _ = writeln!(
            s,
            "  {} ← {}: {}{}{}{}{}",
            a.local,
            a.remote,
            a.state,
            match (a.first_aligned_s, &a.match_attempts.last_refusal) {
                (None, Some(why)) => format!(
                    " — {why}{}",
                    a.match_attempts.best_significance.map_or(String::new(), |b| format!(", best significance {b:.2}"))
                ),
                _ => String::new(),
            },
            match (a.first_aligned_s, a.translation_error_m, a.rotation_error_deg) {
                (Some(t), Some(e), Some(r)) => format!(" at {t:.0} s{}, error {e:.2} m / {r:.2}°", a.relayed_note()),
                _ => String::new(),
            },
            match (a.inter_robot_factors, a.inconsistent_factors) {
                (0, _) => String::new(),
                (n, 0) => format!(
                    ", {n} inter-robot factors ({} from {} closure rounds)",
                    a.closures.factors, a.closures.rounds
                ),
                (n, bad) => format!(", {n} inter-robot factors, {bad} INCONSISTENT (not used)"),
            },
            a.contradiction_note()
        );
        if !a.suspect.is_empty() {
            let _ = writeln!(s, "    SUSPECT: {}", a.suspect.join("; "));
        }
    }
    let total: u64 = report.messages.values().map(|m| m.bytes_total).sum();
    let _ = writeln!(
        s,
        "radio: {:.1} KiB sent, {:.3} % of raw point-cloud sharing ({:.1} MiB)",
        total as f64 / 1024.0,
        report.bytes_ratio_to_raw * 100.0,
        report.point_cloud_raw.bytes_total as f64 / 1024.0 / 1024.0
    );
    let _ = writeln!(s, "report: {}", dir.join("report.md").display());
    s
}
