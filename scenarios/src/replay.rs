//! `sgm replay`: recorded missions, one ROS 1 bag per robot, driven through the robots in
//! timestamp order with no ROS master, as fast as the CPU allows — the scenario runner's
//! stepping ([`Team`]) with bags instead of the simulator. Each step of `frame_interval_s`
//! takes every bag's messages recorded up to then, passes them through the bridge's checks and
//! synchroniser, and hands out the frames that are ready. Robots talk over the configuration's
//! radio model (its range needs positions: from the bags' ground truth when they have it).
//! The report is the scenarios' report; trajectory errors need a ground-truth topic.

use crate::record::{RobotTruth, RunOutcome, RunRecord, Timing, TruthTrack};
use crate::report::series_point;
use crate::result_bag::ResultBag;
use crate::scenario::Scenario;
use crate::sim::radio::{RadioShared, SimulatedRadio};
use crate::sim::world::World;
use crate::team::{RunError, Team};
use crate::threads::Threads;
use indicatif::ProgressBar;
use serde::Serialize;
use sgm_actors::config::OdometrySource;
use sgm_actors::messages::FrameLabels;
use sgm_actors::transport::InProcessRadio;
use sgm_bridge::bag::reader::{read_bag, BagItem, BagSource, Payload};
use sgm_bridge::config::LabelSource;
use sgm_bridge::convert::time::Epoch;
use sgm_bridge::health::judge_whole_stream;
use sgm_bridge::sync::{SyncCounts, Synchroniser};
use sgm_bridge::timeline::TimelineCounts;
use sgm_model::geometry::Pose3;
use sgm_model::scene_graph::{nanos_from_stamp, stamp_from_nanos, RobotId, Stamp};
use std::collections::BTreeMap;
use std::iter::Peekable;
use std::path::PathBuf;
use std::sync::mpsc::IntoIter;
use std::time::{Duration, Instant};

/// Per robot: what came out of its bag.
#[derive(Clone, Debug, Default, Serialize)]
pub struct BagStats {
    pub robot: String,
    pub bag: String,
    /// Messages refused, by topic (each is logged with the reason).
    pub refused: BTreeMap<String, u64>,
    pub sync: SyncCounts,
    /// Stamps checked against the stream: outliers dropped, jumps that restarted the timeline.
    pub timeline: TimelineCounts,
    /// What the health checks found over the whole bag (`[ros.health]`; also logged).
    pub health: Vec<sgm_bridge::health::Finding>,
    /// The sensors' mounts (pinned or from the bag's tf), tf refusals, odometry against tf.
    pub tf: Option<sgm_bridge::tf::listener::TfStatus>,
}

/// A finished replay: the run and what the bags held.
pub struct ReplayOutcome {
    pub run: RunOutcome,
    pub bags: Vec<BagStats>,
}

struct BagRobot {
    stream: Peekable<IntoIter<BagItem>>,
    sync: Synchroniser,
    /// The robot runs its own odometry: its world frame is where that started.
    internal: bool,
    truth: Vec<(Stamp, Pose3)>,
    first_odometry: Option<(Stamp, Pose3)>,
    stats: BagStats,
    /// Per input: accepted and refused, for the health checks.
    inputs: BTreeMap<String, sgm_bridge::health::TopicTally>,
    frames: u64,
    raw_bytes: u64,
    raw_max_bytes: u64,
}

impl BagRobot {
    /// Logs and counts a refused message.
    fn refused(&mut self, topic: String, input: &'static str, error: &sgm_bridge::error::InputError) {
        tracing::warn!(robot = %self.stats.robot, %topic, "message refused: {error}");
        *self.stats.refused.entry(topic).or_default() += 1;
        let tally = self.inputs.entry(input.to_string()).or_default();
        tally.refused += 1;
        tally.last_refusal = Some(error.to_string());
    }

    /// Record time of the next message (refusals before it are counted and passed over).
    fn next_time(&mut self) -> Result<Option<u64>, RunError> {
        loop {
            match self.stream.peek() {
                None => return Ok(None),
                Some(BagItem::Message { time_nanos, .. }) => return Ok(Some(*time_nanos)),
                Some(_) => match self.stream.next() {
                    Some(BagItem::Refused { topic, input, error }) => self.refused(topic, input, &error),
                    Some(BagItem::Failed(e)) => return Err(RunError::Input(e.to_string())),
                    _ => {}
                },
            }
        }
    }

    /// Feeds every message recorded up to `limit` (ns since 1970) to the synchroniser.
    /// `epoch` is the stamps' (header times), set from the first stamped message of the replay:
    /// record times and header stamps may differ (a bag recorded while another played at 3×).
    fn pull(
        &mut self,
        limit: u64,
        epoch: &mut Option<Epoch>,
        id: RobotId,
        shared: &RadioShared,
    ) -> Result<(), RunError> {
        while self.next_time()?.is_some_and(|t| t <= limit) {
            let Some(BagItem::Message { payload, .. }) = self.stream.next() else { break };
            self.inputs.entry(payload.input_name().to_string()).or_default().accepted += 1;
            let stamped = match &payload {
                Payload::Cloud(t, _)
                | Payload::Image(t, ..)
                | Payload::Odometry(t, _)
                | Payload::GroundTruth(t, _)
                | Payload::Imu(t, _)
                | Payload::Clock(t) => Some(*t),
                Payload::CameraInfo(_) | Payload::Tf(_) => None,
            };
            // Only a sensor's stamp sets the epoch (camera info has none; tf's may be anything).
            let epoch = match stamped {
                Some(t) => *epoch.get_or_insert_with(|| Epoch::at(t)),
                None => epoch.unwrap_or(Epoch { sec: 0 }),
            };
            match &payload {
                // The robot's own odometry: raw bytes are counted per labelled frame, as a run does.
                Payload::Cloud(..) if self.internal => {}
                Payload::Cloud(_, scan) => {
                    let raw = scan.points.len() as u64 * crate::record::RAW_BYTES_PER_POINT;
                    self.raw_bytes += raw;
                    self.raw_max_bytes = self.raw_max_bytes.max(raw);
                }
                Payload::Odometry(stamp, pose) => {
                    self.first_odometry.get_or_insert((epoch.stamp(*stamp), *pose));
                }
                _ => {}
            }
            if let Some((stamp, pose)) = self.sync.feed(epoch, payload) {
                shared.set_position(id, pose.translation.vector.into());
                self.truth.push((stamp, pose));
            }
        }
        Ok(())
    }
}

/// Replays `bags` (robot k ← `bags[k]`) with `scenario`'s robot configuration, radio and
/// `[ros]` topics. Must be called inside an actix system.
pub async fn replay(
    scenario: &Scenario,
    bags: &[PathBuf],
    progress: Option<&ProgressBar>,
) -> Result<ReplayOutcome, RunError> {
    replay_with(scenario, bags, progress, None, Threads::default()).await
}

/// As [`replay`], also writing the team's result as a ROS 1 bag at `result_bag`
/// ([`crate::result_bag`]), stamped by the bags' clock.
pub async fn replay_with(
    scenario: &Scenario,
    bags: &[PathBuf],
    progress: Option<&ProgressBar>,
    result_bag: Option<&std::path::Path>,
    threads: Threads,
) -> Result<ReplayOutcome, RunError> {
    let classes = sgm_model::perception::classes::ClassTable::new(scenario.fusion.classes.clone())
        .map_err(|e| RunError::Input(format!("fusion.classes: {e}")))?;
    let mut result: Option<ResultBag> = None;
    let wall = Instant::now();
    if bags.is_empty() {
        return Err(RunError::Input("no bag given".into()));
    }
    if scenario.robots.len() != bags.len() {
        return Err(RunError::Input(format!(
            "{} bags but the configuration has {} robots: one bag per robot, in the order of [[robots]]",
            bags.len(),
            scenario.robots.len()
        )));
    }
    let mut ros = scenario.ros.clone();
    if !scenario.camera.enabled {
        ros.labels = LabelSource::Cloud;
    }
    let names: Vec<String> = (0..bags.len()).map(|k| scenario.robot_name(k)).collect();
    let mut robots = Vec::with_capacity(bags.len());
    for (k, path) in bags.iter().enumerate() {
        let id = k as u16 + 1;
        let inputs = sgm_bridge::inputs::Inputs::new(&ros, &names[k], id);
        let config = scenario.robot_config(k);
        let colours = config.colour_ids().map_err(|e| RunError::Input(e.to_string()))?;
        // The robot's own odometry reads the IMU; an external one the odometry topic.
        let source = config.odometry.source;
        let mut reading = BagSource::new(&ros, &names[k], id).with_colours(colours);
        if source == OdometrySource::Internal {
            reading = reading.with_imu();
        }
        robots.push(BagRobot {
            stream: read_bag(path, reading).into_iter().peekable(),
            sync: Synchroniser::for_robot(&ros, &inputs, source).map_err(|e| RunError::Input(format!("[ros]: {e}")))?,
            internal: source == OdometrySource::Internal,
            truth: Vec::new(),
            first_odometry: None,
            stats: BagStats { robot: names[k].clone(), bag: path.display().to_string(), ..BagStats::default() },
            inputs: BTreeMap::new(),
            frames: 0,
            raw_bytes: 0,
            raw_max_bytes: 0,
        });
    }
    let mut first = None;
    for robot in &mut robots {
        if let Some(t) = robot.next_time()? {
            first = Some(first.map_or(t, |f: u64| f.min(t)));
        }
    }
    let Some(first) = first else {
        return Err(RunError::Input(format!(
            "no message on the configured topics ({}, {}, {}, {}) in any bag",
            ros.topics.points, ros.topics.labels, ros.topics.camera_info, ros.topics.odometry
        )));
    };
    // Steps go by record time from the first record's whole second; stamps by header time.
    let record_epoch_nanos = first / 1_000_000_000 * 1_000_000_000;
    let mut epoch: Option<Epoch> = None;
    let mut latest_stamp = f64::NEG_INFINITY;

    let seed = scenario.scenario.seed;
    let shared = RadioShared::default();
    let dt_nanos = nanos_from_stamp(scenario.scenario.frame_interval_s).max(1);
    let report_every =
        ((scenario.scenario.report_interval_s / scenario.scenario.frame_interval_s).round() as u64).max(1);
    let mut observations = Vec::new();
    let mut memory = Vec::new();
    let mut decoding = Duration::ZERO;
    let mut team: Option<Team> = None;
    let mut step = 0u64;
    let mut last_t = 0.0;
    loop {
        let started = Instant::now();
        let exhausted = robots.iter_mut().all(|r| r.stream.peek().is_none() && r.sync.pending() == 0);
        if exhausted {
            decoding += started.elapsed();
            break;
        }
        step += 1;
        let t = stamp_from_nanos(step as i64 * dt_nanos);
        let limit = record_epoch_nanos + step * dt_nanos as u64;
        let mut frames = Vec::new();
        for (k, robot) in robots.iter_mut().enumerate() {
            robot.pull(limit, &mut epoch, RobotId::from_index(k), &shared)?;
            // At the bag's end no partner can come: settle every waiting cloud now, or the
            // replay would wait for it forever.
            let ready = if robot.stream.peek().is_none() {
                robot.sync.finish(epoch.unwrap_or(Epoch { sec: 0 }))
            } else {
                robot.sync.ready()
            };
            for frame in ready {
                // A sweep for the robot's own odometry alone is no frame of the map's.
                if !matches!(frame.labels, FrameLabels::Unlabelled) {
                    robot.frames += 1;
                    if robot.internal {
                        let raw = frame.points_in_body.len() as u64 * crate::record::RAW_BYTES_PER_POINT;
                        robot.raw_bytes += raw;
                        robot.raw_max_bytes = robot.raw_max_bytes.max(raw);
                    }
                }
                frames.push((k, frame));
            }
        }
        let team = match &mut team {
            Some(team) => team,
            None => {
                let mut spec = scenario.radio.clone();
                if spec.range_m > 0.0 && robots.iter().any(|r| r.truth.is_empty()) {
                    tracing::warn!("a bag has no ground truth: the radio's range limit is off");
                    spec.range_m = 0.0;
                }
                let radio = InProcessRadio::new(Box::new(SimulatedRadio::new(&spec, seed, shared.clone(), &names)));
                let workers = threads.workers().map_err(RunError::Input)?;
                team.insert(Team::new(names.clone(), radio, threads, workers))
            }
        };
        decoding += started.elapsed();
        // The team's time: the step, or the newest stamp if the stamps run ahead of the records.
        latest_stamp = frames.iter().map(|(_, f)| f.stamp).fold(latest_stamp, f64::max);
        let t = t.max(latest_stamp);
        for (k, frame) in frames {
            team.advance(k, t);
            team.frame(k, || scenario.robot_config(k), frame).await?;
        }
        team.settle(t).await?;
        last_t = t;
        if step % report_every == 0 {
            let observation = team.observe(t).await?;
            if let Some(path) = result_bag {
                let result = match &mut result {
                    Some(result) => result,
                    None => result.insert(ResultBag::create(
                        path,
                        &names,
                        &ros,
                        classes.clone(),
                        epoch.unwrap_or(Epoch { sec: 0 }),
                    )?),
                };
                result.observe(&observation)?;
            }
            observations.push(observation);
            crate::memory::release_free_pages();
            memory.extend(crate::memory::sample(t));
        }
        if let Some(bar) = progress {
            bar.set_position(step);
        }
    }
    let Some(team) = team else { return Err(RunError::Input("the bags hold no frame".into())) };
    if observations.last().is_none_or(|o| o.t != last_t) {
        observations.push(team.observe(last_t).await?);
    }
    let maps = team.maps().await?;
    let odometry = team.odometry_statuses().await?;
    let bounds = bounds(&robots, &maps);
    let mut bag_stats = Vec::new();
    let mut truths = Vec::new();
    for (k, r) in robots.into_iter().enumerate() {
        let truth = TruthTrack::Samples(r.truth);
        // Where the robot's world frame sits in the truth frame: truth · odometry⁻¹ at the first
        // odometry pose that has a true pose beside it.
        // With its own odometry: the body's true pose where that started, levelled.
        let origin = odometry.get(k).copied().flatten().and_then(|status| status.origin_stamp);
        let truth_from_world = match origin {
            Some(origin) if r.internal => truth.odometry_origin(origin),
            _ => r.first_odometry.and_then(|(t, odometry)| Some(truth.pose_at(t)? * odometry.inverse())),
        }
        .unwrap_or_else(Pose3::identity);
        truths.push(RobotTruth {
            name: names[k].clone(),
            truth_from_world,
            truth,
            frames: r.frames,
            raw_bytes: r.raw_bytes,
            raw_max_bytes: r.raw_max_bytes,
        });
        // The checks over the whole bag, judged at its end; mission time counts from the bags'
        // epoch, the first message's whole second.
        let confirmed = observations
            .last()
            .and_then(|o| o.maps.get(k))
            .and_then(|m| m.as_ref())
            .map_or(0, |(map, _, _)| map.objects.iter().filter(|o| o.confirmed).count());
        let health = judge_whole_stream(&ros.health, &r.sync, &r.inputs, Some(confirmed), 0.0, last_t);
        let tf = r.sync.tf();
        bag_stats.push(BagStats {
            sync: r.sync.counts.clone(),
            timeline: r.sync.timeline().clone(),
            tf: Some(tf),
            health,
            ..r.stats
        });
    }
    let world = World {
        bounds,
        colours: scenario.fusion.classes.iter().map(|c| (c.id, c.colour)).collect(),
        ..World::default()
    };
    // The mission's span: the steps, or the stamps when they ran ahead of the records.
    let stepped = step as f64 * scenario.scenario.frame_interval_s;
    let sim_s = if last_t > stepped + scenario.scenario.frame_interval_s { last_t } else { stepped };
    // The truth is known only now (read from the bags as they went): the series is made here.
    let series = observations.iter().map(|o| series_point(o, &truths)).collect();
    let last = observations.pop().unwrap_or_default();
    if let Some(path) = result_bag {
        let result = match result {
            Some(result) => result,
            None => ResultBag::create(path, &names, &ros, classes, epoch.unwrap_or(Epoch { sec: 0 }))?,
        };
        result.finish(&maps, &last)?;
    }
    let record = RunRecord {
        scenario: format!("replay of {}", names.join(", ")),
        seed,
        sim_s,
        robots: truths,
        series,
        last,
        radio: shared.stats(),
        world_objects: Vec::new(),
        restarts: Vec::new(),
        final_keyframes: maps.iter().map(|m| m.keyframes().map(|k| k.id).collect()).collect(),
        false_factors: Vec::new(),
        optimisers: team.optimiser_statuses().await?,
        pose_graphs: team.pose_graphs().await?,
        deskew: team.deskew_counts().await?,
        odometry,
    };
    let timing = Timing::measure(wall, sim_s, (decoding, decoding), memory, team.busy_time().await);
    Ok(ReplayOutcome { run: RunOutcome { record, world, maps, timing, threads }, bags: bag_stats })
}

/// The plot's extent: every true and estimated position, with a 10 m margin.
fn bounds(robots: &[BagRobot], maps: &[sgm_model::scene_graph::SceneGraph]) -> [f64; 4] {
    let points = robots
        .iter()
        .flat_map(|r| r.truth.iter().map(|(_, p)| p.translation.vector))
        .chain(maps.iter().flat_map(|m| m.keyframes().map(|k| k.world_from_body.translation.vector)));
    let mut b = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
    for p in points {
        b = [b[0].min(p.x), b[1].min(p.y), b[2].max(p.x), b[3].max(p.y)];
    }
    if !b.iter().all(|v| v.is_finite()) {
        return [-50.0, -50.0, 50.0, 50.0];
    }
    [b[0] - 10.0, b[1] - 10.0, b[2] + 10.0, b[3] + 10.0]
}
