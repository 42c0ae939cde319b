//! The record of a run: what the runner (or the replay) observed, as plain data. The team
//! fills it, `report` turns it into figures; neither reaches into the other.
//!
//! - [`RunRecord`]: truth, the series of observations, the last observation in full, radio
//!   counts, restarts and injected factors; [`RunOutcome`]: the record with the world, the
//!   final maps and the wall-clock [`Timing`].
//! - [`TruthTrack`]: a robot's true trajectory (simulated route or a bag's ground truth).

mod timing;
mod truth;

pub use timing::Timing;
pub use truth::TruthTrack;

use crate::observation::Observation;
use crate::sim::false_factors::InjectedFactor;
use crate::sim::radio::RadioStats;
use crate::sim::world::World;
use serde::Serialize;
use sgm_actors::optimiser::OptimiserStatus;
use sgm_model::geometry::Pose3;
use sgm_model::perception::deskew::DeskewCounts;
use sgm_model::scene_graph::{KeyframeId, SceneGraph, Stamp};
use std::collections::BTreeSet;

/// Bytes per point of a raw PointCloud2 (x, y, z, label as four 32-bit fields): what sending
/// every scan would cost, the paper's "point-cloud raw" row.
pub const RAW_BYTES_PER_POINT: u64 = 16;

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
    pub restarts: Vec<Restart>,
    /// Each robot's keyframe ids at the end (to show that no restored keyframe was lost).
    pub final_keyframes: Vec<BTreeSet<KeyframeId>>,
    /// False inter-robot factors injected (`[[false_factors]]`).
    pub false_factors: Vec<InjectedFactor>,
    /// Each robot's pose graph at the end (`None`: not running).
    pub optimisers: Vec<Option<OptimiserStatus>>,
    /// Each robot's pose graph at the end, for the team-graph reference (`None`: not running).
    pub pose_graphs: Vec<Option<sgm_actors::optimiser::OptimiserState>>,
    /// Each robot's scans deskewed and used as they came (`None`: not running).
    pub deskew: Vec<Option<DeskewCounts>>,
    /// Each robot's internal odometry (`None`: external, or not running).
    pub odometry: Vec<Option<sgm_actors::odometry::OdometryStatus>>,
}

/// A finished run: everything the report is made of.
pub struct RunOutcome {
    pub record: RunRecord,
    pub world: World,
    /// Each robot's final map (with its clouds), for the merged semantic map.
    pub maps: Vec<SceneGraph>,
    pub timing: Timing,
    /// The threads the run had (`--threads`): the report's heavy parts use as many.
    pub threads: crate::threads::Threads,
}

/// One crash and restart of a robot, and what its snapshot carried over.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Restart {
    pub robot: String,
    pub crashed_at: Stamp,
    pub restarted_at: Stamp,
    /// When the snapshot it continued from was taken (`None`: there was none, it started empty).
    pub snapshot_taken_at: Option<Stamp>,
    /// Keyframes in the map when it crashed.
    pub keyframes_at_crash: usize,
    /// Keyframes in the snapshot (the rest, made after it, died with the robot).
    pub keyframes_in_snapshot: usize,
    pub objects_in_snapshot: usize,
    /// The snapshot's keyframe ids, to check that the final map still holds every one.
    #[serde(skip)]
    pub snapshot_keyframes: BTreeSet<KeyframeId>,
}

/// One pair's inter-robot error at one observation.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PairError {
    pub local: String,
    pub remote: String,
    pub translation_error_m: f64,
    pub rotation_error_deg: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SeriesPoint {
    pub t: f64,
    pub team_ate_rmse_m: Option<f64>,
    /// Bytes sent by the whole team so far.
    pub bytes_total: u64,
    /// Bytes of clouds held by the whole team's maps (`tracker.cloud_store`).
    pub cloud_bytes: u64,
    pub alignments: Vec<PairError>,
}
