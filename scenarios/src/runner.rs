//! The scenario runner: drives every robot's actor tree on the virtual clock as fast as the CPU
//! allows. Each step of `frame_interval_s`: every robot that is on gets a simulated frame (LiDAR,
//! segmentation, odometry); the team runs until quiet; every robot ticks; the radio delivers
//! what is due; the team runs until quiet again. Nothing reads the wall clock except the
//! timing kept apart in [`Timing`], so the same scenario and seed give the same run.

use crate::report::{Observation, RobotTruth, RunRecord};
use crate::scenario::Scenario;
use crate::sim::camera::{camera_from_body, camera_model, mislabels, noisy_labels, render};
use crate::sim::lidar::Lidar;
use crate::sim::odometry::Odometry;
use crate::sim::radio::{RadioShared, SimulatedRadio};
use crate::sim::trajectory::Route;
use crate::sim::world::{generate, World, NO_LABEL};
use indicatif::ProgressBar;
use nalgebra::Point2;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sgm_actors::clock::Clock;
use sgm_actors::comms::GetCommsStatus;
use sgm_actors::matcher::GetNeighbours;
use sgm_actors::messages::{FrameLabels, SensorFrame, Tick};
use sgm_actors::quiescence::until_quiet;
use sgm_actors::supervisor::{start_robot, RobotHandle};
use sgm_actors::tracker::{GetMapSummary, GetSceneGraph};
use sgm_actors::transport::InProcessRadio;
use sgm_model::scene_graph::{nanos_from_stamp, stamp_from_nanos, LabelId, RobotId, SceneGraph};
use std::time::{Duration, Instant};

/// Wall-clock facts of a run: kept out of the report so that the report is deterministic.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Timing {
    pub wall_s: f64,
    pub sim_s: f64,
    pub realtime_factor: f64,
    /// Time in handlers per actor kind, s (one thread: CPU time).
    pub actor_busy_s: std::collections::BTreeMap<String, f64>,
    /// Time simulating sensors, s.
    pub simulation_s: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("robot {robot}: {message}")]
    Robot { robot: String, message: String },
    #[error("the actor system stopped answering: {0}")]
    Mailbox(String),
}

/// A finished run: everything the report is made of.
pub struct RunOutcome {
    pub record: RunRecord,
    pub world: World,
    /// Each robot's final map (with its clouds), for the merged semantic map.
    pub maps: Vec<SceneGraph>,
    pub timing: Timing,
}

struct SimRobot {
    name: String,
    route: Route,
    odometry: Odometry,
    lidar: Lidar,
    rng: ChaCha8Rng,
    clock: Clock,
    handle: Option<RobotHandle>,
    frames: u64,
    raw_bytes: u64,
    raw_max_bytes: u64,
}

/// Bytes per point of a raw PointCloud2 (x, y, z, label as four 32-bit fields): what sending
/// every scan would cost, the paper's "point-cloud raw" row.
pub const RAW_BYTES_PER_POINT: u64 = 16;

fn mailbox(e: actix::MailboxError) -> RunError {
    RunError::Mailbox(e.to_string())
}

/// Runs `scenario` to its end. Must be called inside an actix system (`actix_rt::System`).
pub async fn run(scenario: &Scenario, progress: Option<&ProgressBar>) -> Result<RunOutcome, RunError> {
    let wall = Instant::now();
    let seed = scenario.scenario.seed;
    let routes: Vec<Route> = scenario.robots.iter().enumerate().map(|(k, r)| Route::of(r, k, seed)).collect();
    let paths: Vec<Vec<Point2<f64>>> = routes.iter().map(|r| r.points.clone()).collect();
    let world = generate(&scenario.world, &scenario.fusion.classes, &paths, seed);
    let shared = RadioShared::default();
    let radio = InProcessRadio::new(Box::new(SimulatedRadio::new(&scenario.radio, seed, shared.clone())));
    let camera = camera_model(&scenario.camera);
    let splat = splat_px(scenario, camera.fx);

    let mut robots: Vec<SimRobot> = routes
        .into_iter()
        .enumerate()
        .map(|(k, route)| SimRobot {
            name: scenario.robot_name(k),
            route,
            odometry: Odometry::new(&scenario.odometry),
            lidar: Lidar::new(&scenario.lidar),
            rng: ChaCha8Rng::seed_from_u64(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (k as u64 + 1)),
            clock: Clock::starting_at(0.0),
            handle: None,
            frames: 0,
            raw_bytes: 0,
            raw_max_bytes: 0,
        })
        .collect();

    let dt = scenario.scenario.frame_interval_s;
    let steps = (scenario.scenario.duration_s / dt).round() as u64;
    let report_every = ((scenario.scenario.report_interval_s / dt).round() as u64).max(1);
    let mut observations = Vec::new();
    let mut simulation = Duration::ZERO;
    if let Some(bar) = progress {
        bar.set_length(steps);
    }
    let dt_nanos = nanos_from_stamp(dt);
    for step in 1..=steps {
        let t = stamp_from_nanos(step as i64 * dt_nanos);
        let sim_started = Instant::now();
        for (k, robot) in robots.iter_mut().enumerate() {
            let Some(truth) = robot.route.pose_at(t) else { continue };
            robot.clock.advance_to(t);
            let id = RobotId(k as u16 + 1);
            shared.set_position(id, truth.translation.vector.into());
            if robot.handle.is_none() {
                let config = scenario.robot_config(k);
                let handle = start_robot(&config, robot.clock.clone(), &radio)
                    .map_err(|e| RunError::Robot { robot: robot.name.clone(), message: e.to_string() })?;
                robot.handle = Some(handle);
            }
            let odometry = robot.odometry.step(&truth, &mut robot.rng);
            let frame = robot.lidar.scan(&world, &truth, &mut robot.rng);
            let wrong = mislabels(&frame, scenario.camera.mislabel_rate, &world.matchable_labels, &mut robot.rng);
            let labels = if scenario.camera.enabled {
                let image = render(&scenario.camera, &frame, &wrong, splat, &mut robot.rng);
                FrameLabels::Image { image, camera: camera.clone(), camera_from_body: camera_from_body() }
            } else {
                let labels = noisy_labels(&frame, &wrong);
                FrameLabels::PerPoint(labels.into_iter().map(|l| (l != NO_LABEL).then_some(LabelId(l))).collect())
            };
            robot.frames += 1;
            let raw = frame.points.len() as u64 * RAW_BYTES_PER_POINT;
            robot.raw_bytes += raw;
            robot.raw_max_bytes = robot.raw_max_bytes.max(raw);
            if let Some(handle) = &robot.handle {
                handle.supervisor.do_send(SensorFrame {
                    stamp: t,
                    world_from_body: odometry,
                    points_in_body: frame.points,
                    labels,
                });
            }
        }
        simulation += sim_started.elapsed();
        until_quiet().await;
        for robot in &robots {
            if let Some(handle) = &robot.handle {
                handle.supervisor.do_send(Tick { now: t });
            }
        }
        until_quiet().await;
        radio.deliver_due(t);
        until_quiet().await;
        if step % report_every == 0 || step == steps {
            observations.push(observe(t, &robots).await?);
        }
        if let Some(bar) = progress {
            bar.set_position(step);
        }
    }

    let mut maps = Vec::new();
    let mut truths = Vec::new();
    for robot in &robots {
        let map = match &robot.handle {
            Some(handle) => handle.tracker.send(GetSceneGraph).await.map_err(mailbox)?,
            None => SceneGraph::new(),
        };
        maps.push(map);
        truths.push(RobotTruth {
            name: robot.name.clone(),
            route: robot.route.clone(),
            truth_from_world: robot.odometry.truth_from_world,
            frames: robot.frames,
            raw_bytes: robot.raw_bytes,
            raw_max_bytes: robot.raw_max_bytes,
        });
    }
    let sim_s = steps as f64 * dt;
    let wall_s = wall.elapsed().as_secs_f64();
    let timing = Timing {
        wall_s,
        sim_s,
        realtime_factor: sim_s / wall_s.max(1e-9),
        actor_busy_s: sgm_actors::containment::busy_time()
            .into_iter()
            .map(|(k, v)| (k.to_string(), v.as_secs_f64()))
            .collect(),
        simulation_s: simulation.as_secs_f64(),
    };
    let record = RunRecord {
        scenario: scenario.scenario.name.clone(),
        seed,
        sim_s,
        robots: truths,
        observations,
        radio: shared.stats(),
        world_objects: world.objects.iter().map(|o| (o.label, o.centre)).collect(),
    };
    Ok(RunOutcome { record, world, maps, timing })
}

/// What every robot knows at time `t`.
async fn observe(t: f64, robots: &[SimRobot]) -> Result<Observation, RunError> {
    let mut observation = Observation { t, ..Observation::default() };
    for robot in robots {
        let Some(handle) = &robot.handle else {
            observation.maps.push(None);
            continue;
        };
        let map = handle.tracker.send(GetMapSummary).await.map_err(mailbox)?;
        let neighbours = handle.matcher.send(GetNeighbours).await.map_err(mailbox)?;
        let comms = handle.comms.send(GetCommsStatus).await.map_err(mailbox)?;
        observation.maps.push(Some((map, neighbours, comms)));
    }
    Ok(observation)
}

/// Half-size of a return's splat in the label image: half the scan pattern's spacing in pixels.
fn splat_px(scenario: &Scenario, fx: f64) -> i64 {
    let l = &scenario.lidar;
    let spacing_deg = match l.pattern {
        crate::scenario::LidarPattern::Spinning => {
            let vertical = (l.vertical_fov_deg[1] - l.vertical_fov_deg[0]) / (l.beams.max(2) - 1) as f64;
            vertical.max(l.azimuth_step_deg)
        }
        crate::scenario::LidarPattern::Livox => {
            let area = 360.0 * (l.vertical_fov_deg[1] - l.vertical_fov_deg[0]);
            (area / l.points_per_frame.max(1) as f64).sqrt()
        }
    };
    ((spacing_deg.to_radians() * fx / 2.0).ceil() as i64).clamp(1, 8)
}
