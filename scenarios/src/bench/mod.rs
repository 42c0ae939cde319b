//! `sgm bench …`: the paper's experiments. Each bench returns a [`Section`] (a markdown table
//! that names the command which made it, and the same figures as JSON); `sgm bench all`
//! gathers every section into one report.

pub mod all;
pub mod baselines;
pub mod matching;
pub mod matching_hard;
pub mod messages;
pub mod odometry;
pub mod outliers;
pub mod realism;
pub mod sweeps;

use anyhow::Context;
use sgm_scenarios::report::{self, Report};
use sgm_scenarios::runner::run;
use sgm_scenarios::scenario::Scenario;
use std::path::Path;

/// One bench's output.
pub struct Section {
    pub markdown: String,
    pub json: serde_json::Value,
}

impl Section {
    /// Prints the markdown; writes the JSON to `json` if given.
    pub fn emit(&self, json: Option<&Path>) -> anyhow::Result<()> {
        println!("{}", self.markdown);
        if let Some(path) = json {
            let text = serde_json::to_string_pretty(&self.json)?;
            std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?;
        }
        Ok(())
    }
}

/// The paper's two real-world environments as library scenarios.
pub const PAPER_SCENARIOS: [(&str, &str); 2] = [("outdoor_two_robots", "Outdoor"), ("indoor_three_robots", "Indoor")];

/// A library scenario, its mission cut to `duration` s when given (the test suite's reduced
/// mode).
pub fn load_cut(name: &str, duration: Option<f64>) -> anyhow::Result<Scenario> {
    let mut scenario = Scenario::load(name)?;
    if let Some(d) = duration {
        anyhow::ensure!(d.is_finite() && d > 0.0, "--duration must be positive, not {d}");
        scenario.scenario.duration_s = scenario.scenario.duration_s.min(d);
    }
    Ok(scenario)
}

/// Runs `scenario` to its end in a fresh actix system and computes its report; `label` names
/// the run in the progress line on stderr.
pub fn run_report(scenario: &Scenario, label: &str) -> anyhow::Result<Report> {
    let system = actix_rt::System::new();
    let outcome = system.block_on(run(scenario, None)).with_context(|| format!("running {label}"))?;
    let r = report::compute(&outcome.record);
    eprintln!("{label}: {:.0} s simulated in {:.1} s", r.sim_s, outcome.timing.wall_s);
    Ok(r)
}

/// One mission to run: a row's index, the seed, the scenario.
pub struct Job {
    pub row: usize,
    pub seed: u64,
    pub scenario: Scenario,
    pub label: String,
}

/// Runs the jobs on every core (each run is its own deterministic actix system, so the figures
/// do not depend on the thread count), in the jobs' order.
pub fn run_all(jobs: Vec<Job>) -> anyhow::Result<Vec<(usize, u64, Report)>> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).min(jobs.len().max(1));
    let next = AtomicUsize::new(0);
    let results: Vec<Mutex<Option<anyhow::Result<Report>>>> = jobs.iter().map(|_| Mutex::new(None)).collect();
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| loop {
                let k = next.fetch_add(1, Ordering::Relaxed);
                let Some(job) = jobs.get(k) else { break };
                let outcome = run_report(&job.scenario, &job.label);
                if let Ok(mut slot) = results[k].lock() {
                    *slot = Some(outcome);
                }
            });
        }
    });
    jobs.iter()
        .zip(results)
        .map(|(job, slot)| {
            let outcome = slot.into_inner().ok().flatten();
            let report = outcome.unwrap_or_else(|| Err(anyhow::anyhow!("{}: the run's thread died", job.label)))?;
            Ok((job.row, job.seed, report))
        })
        .collect()
}

/// An alignment farther than this from the truth counts as wrong, m.
pub const WRONG_M: f64 = 2.0;

/// Whether an alignment report is aligned and within [`WRONG_M`] of the truth.
pub fn aligned_right(a: &sgm_scenarios::report::AlignmentReport) -> bool {
    a.state == "Aligned" && a.translation_error_m.is_some_and(|e| e <= WRONG_M)
}

/// Bytes the whole team sent over the radio.
pub fn radio_bytes(r: &Report) -> u64 {
    r.messages.values().map(|m| m.bytes_total).sum()
}

/// `v` with `decimals` for a table cell, "–" when there is none.
pub fn or_dash(v: Option<f64>, decimals: usize) -> String {
    v.map_or("–".into(), |v| format!("{v:.decimals$}"))
}

/// `--duration D` as it appears in a command line, or nothing.
pub fn duration_arg(duration: Option<f64>) -> String {
    duration.map(|d| format!(" --duration {d}")).unwrap_or_default()
}
