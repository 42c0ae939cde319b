//! A run's report: what the runner observed ([`RunRecord`]) turned into figures ([`Report`],
//! deterministic: nothing in it depends on the machine's speed) and written as `report.json`,
//! `report.md`, TUM trajectories, PNG plots and the merged semantic map.

pub mod back_end;
mod figures;
pub mod ledger;
mod map_cloud;
pub mod markdown;
pub mod plots;
pub mod team_graph;
pub mod tum;

pub(crate) use figures::reference_from;
pub use figures::{compute, series_point, AlignmentReport, MessageRow, Report, RobotReport};

use crate::output_error::OutputError;
use crate::record::{RunOutcome, Timing};
use std::path::Path;

/// A report that could not be written, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    #[error(transparent)]
    File(#[from] OutputError),
    #[error("report.json not encoded: {0}")]
    Json(#[source] serde_json::Error),
    #[error(transparent)]
    Plot(#[from] plots::PlotError),
}

fn write_file(dir: &Path, name: &str, bytes: &[u8]) -> Result<(), WriteError> {
    let path = dir.join(name);
    Ok(std::fs::write(&path, bytes).map_err(OutputError::at(&path))?)
}

/// Writes the report directory: `report.json`, `report.md`, `timing.json`, TUM files, plots and
/// `map.pcd`. Returns the report.
pub fn write(outcome: &RunOutcome, dir: &Path) -> Result<Report, WriteError> {
    std::fs::create_dir_all(dir).map_err(OutputError::at(dir))?;
    let report = compute(&outcome.record);
    let json = serde_json::to_string_pretty(&report).map_err(WriteError::Json)?;
    write_file(dir, "report.json", json.as_bytes())?;
    write_file(dir, "report.md", markdown::render(&report, &outcome.timing).as_bytes())?;
    write_file(dir, "timing.json", timing_json(&outcome.timing).as_bytes())?;
    for (name, text) in tum::files(&outcome.record) {
        write_file(dir, &name, text.as_bytes())?;
    }
    plots::draw(outcome, &report, dir)?;
    write_file(dir, "map.pcd", &map_cloud::merged_map(outcome))?;
    Ok(report)
}

fn timing_json(timing: &Timing) -> String {
    serde_json::to_string_pretty(timing).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
}
