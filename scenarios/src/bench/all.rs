//! `sgm bench all`: every bench in one report, `report.md` (each table beside the paper's
//! figures and under the command that made it), `report.json` (the same, per bench) and the
//! sweeps' plots, in `--out`.

use super::{baselines, matching, messages, outliers, sweeps, Section};
use anyhow::Context;
use std::fmt::Write;
use std::path::PathBuf;

pub struct Options {
    pub out: PathBuf,
    /// Matching repetitions per cell (the paper: 20).
    pub reps: usize,
    /// Cut every mission to this many seconds (the test suite's reduced mode).
    pub duration: Option<f64>,
}

pub fn run_bench(options: Options) -> anyhow::Result<()> {
    let out = &options.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let matching_options = matching::Options {
        reps: options.reps,
        seed: 1,
        config: None,
        skip_dense: false,
        error_on: matching::ErrorOnArg::Both,
        hard_reps: None,
    };
    let sweeps_options = sweeps::Options { duration: options.duration, plots: Some(out.clone()) };
    let sections: Vec<(&str, Section)> = vec![
        ("matching", matching::run(matching_options)?),
        ("baselines", baselines::run_bench(options.duration)?),
        ("messages", messages::run_bench(options.duration)?),
        ("sweeps", sweeps::run_bench(&sweeps_options)?),
        ("outliers", outliers::run_bench("faults/clean", options.duration)?),
    ];
    let duration = super::duration_arg(options.duration);
    let mut md = String::new();
    let _ = writeln!(md, "# SGM evaluation\n");
    let _ = writeln!(
        md,
        "Made by `sgm bench all --reps {}{duration} --out {}`; every section names the command that",
        options.reps,
        out.display()
    );
    let _ = writeln!(md, "reproduces it alone. Paper: `../shared/paper/sgm-slam.tex`, §V.\n");
    let mut json = serde_json::Map::new();
    for (name, section) in sections {
        let _ = writeln!(md, "{}", section.markdown.replacen("# ", "## ", 1).replace("\n## ", "\n### "));
        json.insert(name.to_string(), section.json);
    }
    let md_path = out.join("report.md");
    std::fs::write(&md_path, &md).with_context(|| format!("writing {}", md_path.display()))?;
    let json_path = out.join("report.json");
    std::fs::write(&json_path, serde_json::to_string_pretty(&json)?)
        .with_context(|| format!("writing {}", json_path.display()))?;
    println!("{md}");
    eprintln!("wrote {} and {}", md_path.display(), json_path.display());
    Ok(())
}
