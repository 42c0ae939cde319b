//! `sgm bench odometry`: SGM's LiDAR-inertial front end (`sgm_model::odometry`) on the library
//! scenarios' simulated sweeps and IMU (`sgm_scenarios::front_end`), beside the synthetic
//! odometry the scenarios use today (`[odometry]`'s noise model). For each scenario's first
//! robot, and `handheld_indoor`'s handheld rig (its third, charlie: the only platform the
//! first robots do not cover, and the one whose odometry ran 570 m off while the bench
//! watched only its first robot): the path length, the relative drift of both (KITTI's metric, `eval::drift`, over
//! 50–400 m segments, whichever fit the path), the estimator's CPU time per frame and its
//! counts (registered, coasted, degenerate, resets). Each scenario runs on its own thread; the
//! figures do not depend on the thread count, the times do.

use super::{duration_arg, load_cut, or_dash, Section};
use anyhow::Context;
use serde::Serialize;
use sgm_model::eval::drift::{kitti_drift, Drift};
use sgm_model::geometry::Pose3;
use sgm_model::odometry::config::OdometryConfig;
use sgm_scenarios::front_end::{run_front_end_recording, FrontEndRun};
use sgm_scenarios::report::tum;
use std::fmt::Write;
use std::path::Path;

/// The scenarios the issue names — the paper's two environments and the unkind world's two —
/// and the robot of each that runs: every platform (wheeled, legged, handheld) once at least.
pub const RUNS: [(&str, usize); 5] = [
    ("outdoor_two_robots", 0),
    ("indoor_three_robots", 0),
    ("legged_campus", 0),
    ("handheld_indoor", 0),
    ("handheld_indoor", 2),
];
/// A sweep every 0.1 s (10 Hz), whatever the scenario's frame interval (which paces the
/// mapping, at 0.5–1 s in the library).
const LIDAR_INTERVAL_S: f64 = 0.1;
/// Segment lengths, m.
const LENGTHS: [f64; 4] = [50.0, 100.0, 200.0, 400.0];

#[derive(Serialize)]
struct Row {
    scenario: String,
    robot: String,
    path_m: f64,
    frames: usize,
    points_per_frame: f64,
    ours: Option<Drift>,
    synthetic: Option<Drift>,
    /// Our end pose's translation error from the first accepted frame, % of the path.
    ours_end_pct: Option<f64>,
    ms_per_frame: f64,
    registered: u64,
    coasted: u64,
    degenerate: u64,
    resets: u64,
    refused: u64,
}

/// Both trajectories from the first frame the estimator took, each relative to its own start
/// (evo's `--align_origin`).
fn aligned(run: &FrontEndRun) -> (Vec<Pose3>, Vec<Pose3>, Vec<Pose3>) {
    let taken: Vec<_> = run.frames.iter().filter_map(|f| f.estimate.map(|e| (e, f.truth, f.synthetic))).collect();
    let Some(&(e0, t0, s0)) = taken.first() else { return (Vec::new(), Vec::new(), Vec::new()) };
    let rel = |a: Pose3, b: Pose3| a.inverse() * b;
    (
        taken.iter().map(|(e, _, _)| rel(e0, *e)).collect(),
        taken.iter().map(|(_, t, _)| rel(t0, *t)).collect(),
        taken.iter().map(|(_, _, s)| rel(s0, *s)).collect(),
    )
}

fn row(name: &str, run: &FrontEndRun) -> Row {
    let (ours, truth, synthetic) = aligned(run);
    let path_m: f64 = truth.windows(2).map(|w| (w[1].translation.vector - w[0].translation.vector).norm()).sum();
    let lengths: Vec<f64> = LENGTHS.iter().copied().filter(|l| *l <= path_m / 2.0).collect();
    let end = ours
        .last()
        .zip(truth.last())
        .map(|(e, t)| 100.0 * (e.translation.vector - t.translation.vector).norm() / path_m);
    let c = run.counts;
    Row {
        scenario: name.into(),
        robot: run.robot.clone(),
        path_m,
        frames: run.frames.len(),
        points_per_frame: run.points_per_frame,
        ours: kitti_drift(&ours, &truth, &lengths, 10),
        synthetic: kitti_drift(&synthetic, &truth, &lengths, 10),
        ours_end_pct: end.filter(|v| v.is_finite()),
        ms_per_frame: run.time_per_frame.as_secs_f64() * 1e3,
        registered: c.registered,
        coasted: c.coasted,
        degenerate: c.degenerate,
        resets: c.resets,
        refused: c.refused,
    }
}

pub struct Options<'a> {
    pub duration: Option<f64>,
    pub only: Option<&'a str>,
    /// Write each scenario's sweeps, IMU and truth as a ROS 1 bag, and our estimate and the
    /// truth as TUM files, to `DIR/SCENARIO/` (`benches/compare_kiss_icp.sh` runs KISS-ICP on
    /// the bags).
    pub bag_out: Option<&'a Path>,
}

/// Our estimates (the frames the front end took) and the truth at every frame, as
/// `NAME.ours.tum` and `NAME.truth.tum` in `dir`.
fn write_tum(dir: &Path, run: &FrontEndRun) -> anyhow::Result<()> {
    let (mut ours, mut truth) = (String::new(), String::new());
    for frame in &run.frames {
        if let Some(estimate) = &frame.estimate {
            tum::line(&mut ours, frame.t, estimate);
        }
        tum::line(&mut truth, frame.t, &frame.truth);
    }
    for (suffix, text) in [("ours", ours), ("truth", truth)] {
        let path = dir.join(format!("{}.{suffix}.tum", run.robot));
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

pub fn run_bench(options: &Options) -> anyhow::Result<Section> {
    let runs: Vec<(&str, usize)> =
        RUNS.iter().copied().filter(|(n, _)| options.only.is_none_or(|o| n.contains(o))).collect();
    anyhow::ensure!(!runs.is_empty(), "no scenario matches --only {:?}", options.only);
    let config = OdometryConfig::default();
    let runs: Vec<anyhow::Result<Row>> = std::thread::scope(|scope| {
        let handles: Vec<_> = runs
            .iter()
            .map(|&(name, robot)| {
                let config = config.clone();
                scope.spawn(move || -> anyhow::Result<Row> {
                    let scenario = load_cut(name, options.duration)?;
                    let dir = options.bag_out.map(|d| d.join(name));
                    let run = run_front_end_recording(
                        &scenario,
                        robot,
                        &config,
                        None,
                        Some(LIDAR_INTERVAL_S),
                        dir.as_deref(),
                    )?;
                    if let Some(dir) = &dir {
                        write_tum(dir, &run)?;
                    }
                    eprintln!(
                        "{name} ({}): {} frames, {:.1} ms per frame",
                        run.robot,
                        run.frames.len(),
                        run.time_per_frame.as_secs_f64() * 1e3
                    );
                    Ok(row(name, &run))
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|_| Err(anyhow::anyhow!("a scenario's run panicked"))))
            .collect()
    });
    let rows = runs.into_iter().collect::<anyhow::Result<Vec<Row>>>()?;
    let mut md = String::new();
    let _ = writeln!(
        md,
        "### LiDAR-inertial odometry against the synthetic noise model\n\n`sgm bench odometry{}`: each \
         scenario's first robot and handheld_indoor's handheld rig, its front end on the simulated sweeps and IMU. Drift is KITTI's \
         (mean over 50–400 m segments that fit the path, from the first frame the front end \
         took); the synthetic odometry is what the scenarios use today.\n",
        duration_arg(options.duration)
    );
    let _ = writeln!(
        md,
        "| scenario | robot | path m | drift % (ours) | °/100 m (ours) | end error % (ours) | drift % (synthetic) | °/100 m (synthetic) | ms/frame | points/frame | registered | coasted | degenerate | resets |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for r in &rows {
        let _ = writeln!(
            md,
            "| {} | {} | {:.0} | {} | {} | {} | {} | {} | {:.1} | {:.0} | {} | {} | {} | {} |",
            r.scenario,
            r.robot,
            r.path_m,
            or_dash(r.ours.map(|d| d.translation_pct), 2),
            or_dash(r.ours.map(|d| d.rotation_deg_per_100m), 3),
            or_dash(r.ours_end_pct, 2),
            or_dash(r.synthetic.map(|d| d.translation_pct), 2),
            or_dash(r.synthetic.map(|d| d.rotation_deg_per_100m), 3),
            r.ms_per_frame,
            r.points_per_frame,
            r.registered,
            r.coasted,
            r.degenerate,
            r.resets
        );
    }
    Ok(Section { markdown: md, json: serde_json::to_value(&rows)? })
}
