//! A run's report: what the runner observed ([`RunRecord`]) turned into figures ([`Report`],
//! deterministic: nothing in it depends on the machine's speed) and written as `report.json`,
//! `report.md`, TUM trajectories, PNG plots and the merged semantic map.

pub mod back_end;
mod figures;
pub mod ledger;
mod map_cloud;
mod markdown;
pub mod plots;
mod truth;
mod tum;

pub(crate) use figures::reference_from;
pub use figures::{compute, series_point, AlignmentReport, MessageRow, Report, RobotReport, SeriesPoint};
pub use truth::TruthTrack;

use crate::runner::{RunOutcome, Timing};
use crate::sim::radio::RadioStats;
use sgm_actors::comms::CommsStatus;
use sgm_actors::matcher::NeighbourStatus;
use sgm_actors::tracker::MapSummary;
use sgm_model::geometry::Pose3;
use std::path::Path;

/// One robot's truth: its trajectory and where its world frame is.
#[derive(Clone, Debug)]
pub struct RobotTruth {
    pub name: String,
    pub truth: TruthTrack,
    /// p_true = truth_from_world · p_world.
    pub truth_from_world: Pose3,
    pub frames: u64,
    pub raw_bytes: u64,
    /// Largest single raw frame, bytes.
    pub raw_max_bytes: u64,
}

/// What every robot knew at one time (`None`: not switched on yet).
#[derive(Clone, Debug, Default)]
pub struct Observation {
    pub t: f64,
    pub maps: Vec<Option<(MapSummary, Vec<NeighbourStatus>, CommsStatus)>>,
}

/// Everything the runner recorded.
#[derive(Clone, Debug)]
pub struct RunRecord {
    pub scenario: String,
    pub seed: u64,
    pub sim_s: f64,
    pub robots: Vec<RobotTruth>,
    /// The series' points, one per observation (`report_interval_s`), in time order.
    pub series: Vec<SeriesPoint>,
    /// The last observation (at the end of the run), in full.
    pub last: Observation,
    pub radio: RadioStats,
    /// The world's objects: (class id, centre).
    pub world_objects: Vec<(u16, nalgebra::Point3<f64>)>,
    /// Crashes and restarts from snapshots.
    pub restarts: Vec<crate::team::Restart>,
    /// Each robot's keyframe ids at the end (to show that no restored keyframe was lost).
    pub final_keyframes: Vec<std::collections::BTreeSet<sgm_model::scene_graph::KeyframeId>>,
    /// False inter-robot factors injected (`[[false_factors]]`).
    pub false_factors: Vec<crate::sim::false_factors::InjectedFactor>,
    /// Each robot's pose graph at the end (`None`: not running).
    pub optimisers: Vec<Option<sgm_actors::optimiser::OptimiserStatus>>,
}

#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct WriteError {
    pub path: String,
    pub message: String,
}

fn write_file(dir: &Path, name: &str, bytes: &[u8]) -> Result<(), WriteError> {
    let path = dir.join(name);
    std::fs::write(&path, bytes).map_err(|e| WriteError { path: path.display().to_string(), message: e.to_string() })
}

/// Writes the report directory: `report.json`, `report.md`, `timing.json`, TUM files, plots and
/// `map.pcd`. Returns the report.
pub fn write(outcome: &RunOutcome, dir: &Path) -> Result<Report, WriteError> {
    std::fs::create_dir_all(dir).map_err(|e| WriteError { path: dir.display().to_string(), message: e.to_string() })?;
    let report = compute(&outcome.record);
    let json = serde_json::to_string_pretty(&report)
        .map_err(|e| WriteError { path: "report.json".into(), message: e.to_string() })?;
    write_file(dir, "report.json", json.as_bytes())?;
    write_file(dir, "report.md", markdown::render(&report, &outcome.timing).as_bytes())?;
    write_file(dir, "timing.json", timing_json(&outcome.timing).as_bytes())?;
    for (name, text) in tum::files(&outcome.record) {
        write_file(dir, &name, text.as_bytes())?;
    }
    plots::draw(outcome, &report, dir).map_err(|e| WriteError { path: dir.display().to_string(), message: e })?;
    write_file(dir, "map.pcd", &map_cloud::merged_map(outcome))?;
    Ok(report)
}

fn timing_json(timing: &Timing) -> String {
    serde_json::to_string_pretty(timing).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
}
