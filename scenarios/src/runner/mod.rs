//! The scenario runner: drives every robot's actor tree on the virtual clock as fast as the CPU
//! allows. Each step of `frame_interval_s`: every robot that is on gets a simulated frame (LiDAR,
//! segmentation, odometry); the team runs until quiet; every robot ticks; the radio delivers
//! what is due; the team runs until quiet again. Nothing reads the wall clock except the
//! timing kept apart in [`Timing`], so the same scenario and seed give the same run.
//!
//! With `odometry.source = "internal"`, a robot also gets an unlabelled sweep every
//! `odometry.sweep_interval_s` between two frames (its LiDAR turns faster than its camera
//! fires), for its own odometry; the frame's pose is then the odometry's, and its world frame is
//! the body's pose where that odometry started, levelled. The people walking through the scene
//! move once per frame.
//!
//! A robot with `crash_s` goes down then (its vehicle and odometry drive on, unheard), and at
//! `restart_s` comes back from its latest snapshot: the run keeps snapshots whenever a robot
//! crashes or `persistence.directory` is set.

use crate::bag_out::{BagRecorder, RecordedFrame, RecordedImage};
mod sensing;
mod sensors;

use crate::observation::Observation;
use crate::record::Timing;
use crate::record::{RobotTruth, RunOutcome, RunRecord, TruthTrack};
use crate::report::series_point;
use crate::result_bag::ResultBag;
use crate::scenario::{OdometrySourceSpec, Scenario};
use crate::sim::false_factors::FalseFactors;
use crate::sim::radio::{RadioShared, SimulatedRadio};
use crate::sim::trajectory::Route;
pub use crate::team::RunError;
use crate::team::Team;
use crate::threads::Threads;
use indicatif::ProgressBar;
use sensing::Sensed;
use sensors::{SensorState, Sensors};
use sgm_actors::messages::{FrameLabels, SensorFrame};
use sgm_actors::transport::InProcessRadio;
use sgm_model::geometry::Pose3;
use sgm_model::scene_graph::{stamp_from_nanos, RobotId};
use std::path::Path;
use std::time::{Duration, Instant};

/// Runs `scenario` to its end. Must be called inside an actix system (`actix_rt::System`).
pub async fn run(scenario: &Scenario, progress: Option<&ProgressBar>) -> Result<RunOutcome, RunError> {
    run_recording(scenario, progress, None).await
}

/// As [`run`], also writing each robot's sensor streams as a ROS 1 bag into `bag_out`.
pub async fn run_recording(
    scenario: &Scenario,
    progress: Option<&ProgressBar>,
    bag_out: Option<&Path>,
) -> Result<RunOutcome, RunError> {
    run_with(scenario, progress, RunOutputs { bag_out, ..RunOutputs::default() }).await
}

/// What a run writes beside its outcome, and how many threads it may use.
#[derive(Clone, Copy, Debug, Default)]
pub struct RunOutputs<'a> {
    /// Each robot's sensor streams as a ROS 1 bag, into this directory (`NAME.bag`).
    pub bag_out: Option<&'a Path>,
    /// The team's result as a ROS 1 bag ([`crate::result_bag`]), at this path.
    pub result_bag: Option<&'a Path>,
    /// How many robots run at once (default: every core); the outcome does not depend on it.
    pub threads: Threads,
}

/// As [`run`], with the outputs `outputs` asks for.
pub async fn run_with(
    scenario: &Scenario,
    progress: Option<&ProgressBar>,
    outputs: RunOutputs<'_>,
) -> Result<RunOutcome, RunError> {
    let bag_out = outputs.bag_out;
    let wall = Instant::now();
    let seed = scenario.scenario.seed;
    let shared = RadioShared::default();
    let names: Vec<String> = (0..scenario.robots.len()).map(|k| scenario.robot_name(k)).collect();
    let radio = InProcessRadio::new(Box::new(SimulatedRadio::new(&scenario.radio, seed, shared.clone(), &names)));
    // One robot's registrations split over `threads` threads (none: on its own).
    let workers = outputs.threads.workers().map_err(RunError::Input)?;
    let mut team = Team::new(names.clone(), radio, outputs.threads, workers);
    let mut false_factors =
        FalseFactors::new(&scenario.false_factors, seed, |name| names.iter().position(|n| n == name));
    let snapshots = SnapshotDir::for_run(scenario)?;
    if let Some(dir) = &snapshots {
        team.keep_snapshots(dir.path(), &scenario.persistence)?;
    }
    let mut result = match outputs.result_bag {
        Some(path) => {
            let classes = sgm_model::perception::classes::ClassTable::new(scenario.fusion.classes.clone())
                .map_err(|e| RunError::Input(format!("fusion.classes: {e}")))?;
            let epoch = sgm_bridge::convert::time::SCENARIO_EPOCH;
            Some(ResultBag::create(path, &names, &scenario.ros, classes, epoch)?)
        }
        None => None,
    };
    let mut recorder = match bag_out {
        Some(dir) => Some(BagRecorder::new(dir, &scenario.ros, names)?.with_imu(&scenario.imu)),
        None => None,
    };
    let state = SensorState::of(scenario)?;

    let dt = scenario.scenario.frame_interval_s;
    let steps = (scenario.scenario.duration_s / dt).round() as u64;
    // The routes as the false factors need them (the sensors keep their own).
    let routes: Vec<Route> = state.robots.iter().map(|r| r.route.clone()).collect();
    let report_every = ((scenario.scenario.report_interval_s / dt).round() as u64).max(1);
    // The truth as the series needs it (the world's placement is kept up to date, the frame and
    // byte counts are filled in at the end).
    let mut truths: Vec<RobotTruth> = state
        .robots
        .iter()
        .map(|robot| RobotTruth {
            name: robot.name.clone(),
            truth: TruthTrack::Route(robot.route.clone()),
            truth_from_world: robot.odometry.truth_from_world,
            frames: 0,
            raw_bytes: 0,
            raw_max_bytes: 0,
        })
        .collect();
    let mut series = Vec::new();
    let mut last = Observation::default();
    let mut memory = Vec::new();
    let (mut simulation, mut waited) = (Duration::ZERO, Duration::ZERO);
    if let Some(bar) = progress {
        bar.set_length(steps);
    }
    let dt_nanos = state.sensing.dt_nanos;
    let internal = scenario.odometry.source == OdometrySourceSpec::Internal;
    // Where each robot's odometry started in the truth, as of the step the team is at.
    let mut truth_from_world: Vec<Pose3> = truths.iter().map(|t| t.truth_from_world).collect();
    let mut sensors = Sensors::start(state, outputs.threads)?;
    for step in 1..=steps {
        let t = stamp_from_nanos(step as i64 * dt_nanos);
        let waiting = Instant::now();
        let sensed = sensors.step(step, steps).await?;
        (simulation, waited) = (simulation + sensed.took, waited + waiting.elapsed());
        for (k, sensed) in sensed.robots.into_iter().enumerate() {
            let Some(Sensed { truth, odometry, truth_from_world: origin, down, sweeps, frame }) = sensed else {
                continue;
            };
            if let Some(slot) = truth_from_world.get_mut(k) {
                *slot = origin;
            }
            team.advance(k, t);
            shared.set_position(RobotId::from_index(k), truth.translation.vector.into());
            if down {
                if team.is_running(k) {
                    team.crash(k, t).await?;
                }
                continue;
            }
            for sweep in sweeps {
                if let Some(recorder) = recorder.as_mut() {
                    recorder.record_sweep(k, sweep.stamp, &sweep.points, sweep.times.as_deref(), &sweep.imu)?;
                }
                let sweep_frame = SensorFrame {
                    stamp: sweep.stamp,
                    odom_from_body: Pose3::identity(),
                    points_in_body: sweep.points,
                    point_times: sweep.times,
                    points_deskewed: false,
                    labels: FrameLabels::Unlabelled,
                    imu: sweep.imu,
                    motion_covariance: None,
                    measured_up: None,
                };
                team.frame(k, || scenario.robot_config(k), sweep_frame).await?;
            }
            let Some(frame) = frame else { continue };
            if let Some(recorder) = recorder.as_mut() {
                let image = match &frame.labels {
                    FrameLabels::Image { image, camera, camera_from_body, image_offset_s } => Some(RecordedImage {
                        image,
                        camera,
                        stamp: t + image_offset_s,
                        camera_from_body: *camera_from_body,
                    }),
                    FrameLabels::PerPoint(_) | FrameLabels::Unlabelled => None,
                };
                let recorded = RecordedFrame {
                    t,
                    odometry: &odometry,
                    truth: &truth,
                    points: &frame.points,
                    labels: frame.recorded_labels.as_deref(),
                    image,
                    times: frame.times.as_deref(),
                    imu: &frame.imu,
                };
                recorder.record(k, recorded)?;
            }
            let sensor_frame = SensorFrame {
                stamp: t,
                odom_from_body: odometry,
                points_in_body: frame.points,
                point_times: frame.times,
                points_deskewed: false,
                labels: frame.labels,
                imu: frame.imu,
                motion_covariance: None,
                measured_up: None,
            };
            team.frame(k, || scenario.robot_config(k), sensor_frame).await?;
        }
        team.settle(t).await?;
        if false_factors.due(t) {
            let observation = team.observe(t).await?;
            for (k, message) in false_factors.make(t, &observation, |k, s| routes.get(k)?.pose_at(s)) {
                team.inject(k, message);
            }
            team.settle(t).await?;
        }
        team.snapshot_due(t).await?;
        if step % report_every == 0 || step == steps {
            last = team.observe(t).await?;
            if let Some(result) = result.as_mut() {
                result.observe(&last)?;
            }
            // A robot's world is placed on the truth at its first step, or where its internal
            // odometry started.
            let origins = match internal {
                true => team.odometry_statuses().await?.into_iter().map(|s| s.and_then(|s| s.origin_stamp)).collect(),
                false => Vec::new(),
            };
            for (k, (truth, simulated)) in truths.iter_mut().zip(&truth_from_world).enumerate() {
                truth.truth_from_world = origins
                    .get(k)
                    .copied()
                    .flatten()
                    .and_then(|origin| truth.truth.odometry_origin(origin))
                    .unwrap_or(*simulated);
            }
            series.push(series_point(&last, &truths));
            crate::memory::release_free_pages();
            memory.extend(crate::memory::sample(t));
        }
        if let Some(bar) = progress {
            bar.set_position(step);
        }
    }
    if let Some(recorder) = recorder {
        recorder.finish()?;
    }

    let SensorState { mut world, people, robots, .. } = sensors.finish()?;
    people.remove(&mut world);
    let maps = team.maps().await?;
    if let Some(result) = result {
        result.finish(&maps, &last)?;
    }
    let optimisers = team.optimiser_statuses().await?;
    let deskew = team.deskew_counts().await?;
    for (truth, robot) in truths.iter_mut().zip(&robots) {
        (truth.frames, truth.raw_bytes, truth.raw_max_bytes) = (robot.frames, robot.raw_bytes, robot.raw_max_bytes);
    }
    let sim_s = steps as f64 * dt;
    let timing = Timing::measure(wall, sim_s, (simulation, waited), memory, team.busy_time().await);
    let record = RunRecord {
        scenario: scenario.scenario.name.clone(),
        seed,
        sim_s,
        robots: truths,
        series,
        last,
        radio: shared.stats(),
        world_objects: world.objects.iter().map(|o| (o.label, o.centre)).collect(),
        restarts: team.restarts().to_vec(),
        final_keyframes: maps.iter().map(|m| m.keyframes().map(|k| k.id).collect()).collect(),
        false_factors: false_factors.injected,
        optimisers,
        pose_graphs: team.pose_graphs().await?,
        deskew,
        odometry: team.odometry_statuses().await?,
    };
    drop(snapshots);
    Ok(RunOutcome { record, world, maps, timing, threads: outputs.threads })
}

/// Where a run keeps its snapshots: `persistence.directory`, or (when a robot crashes and none
/// is set) a directory of its own in the system's temporary directory, removed at the end.
struct SnapshotDir {
    path: std::path::PathBuf,
    temporary: bool,
}

impl SnapshotDir {
    fn for_run(scenario: &Scenario) -> Result<Option<Self>, RunError> {
        let configured = &scenario.persistence.directory;
        if !configured.is_empty() {
            return Ok(Some(Self { path: configured.into(), temporary: false }));
        }
        if !scenario.has_crashes() {
            return Ok(None);
        }
        let name: String =
            scenario.scenario.name.chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '_' }).collect();
        let path = std::env::temp_dir().join(format!("sgm-snapshots-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&path).map_err(|e| RunError::Input(format!("{}: {e}", path.display())))?;
        Ok(Some(Self { path, temporary: true }))
    }

    fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for SnapshotDir {
    fn drop(&mut self) {
        if self.temporary {
            let _ = std::fs::remove_dir_all(&self.path);
        }
    }
}
