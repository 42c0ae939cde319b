//! `sgm replay --bag A.bag --bag B.bag [--config FILE] [--out DIR] [--quiet] [--no-result-bag] [--threads N]`: replays
//! recorded missions through the robots with no ROS master and writes the scenarios' report,
//! plus `bags.json` (per robot: messages refused by topic, and the synchroniser's counts).

use super::run_cmd::{fresh_run_dir, progress_bar, summary};
use anyhow::{Context, Result};
use sgm_bridge::tf::mounts::MountSource;
use sgm_scenarios::replay::replay_with;
use sgm_scenarios::report;
use sgm_scenarios::scenario::{RobotSpec, Scenario};
use std::fmt::Write as _;
use std::path::PathBuf;

pub struct Options {
    pub bags: Vec<PathBuf>,
    pub config: Option<String>,
    pub out: Option<PathBuf>,
    pub quiet: bool,
    /// Write `result.bag` into the report directory.
    pub result_bag: bool,
    /// `--threads N` (default: every core).
    pub threads: Option<usize>,
}

pub fn execute(options: Options) -> Result<()> {
    let threads = super::run_cmd::threads(options.threads)?;
    let scenario = match &options.config {
        Some(name) => Scenario::load(name)?,
        None => Scenario {
            robots: options
                .bags
                .iter()
                .map(|b| RobotSpec {
                    name: b.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
                    ..RobotSpec::default()
                })
                .collect(),
            ..Scenario::default()
        },
    };
    let dir = options.out.unwrap_or_else(|| fresh_run_dir("replay"));
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create the report directory {}", dir.display()))?;
    let bar = progress_bar(options.quiet, "{prefix} {pos} steps, {elapsed} wall");
    bar.set_prefix(format!("replaying {} bags", options.bags.len()));
    let system = actix_rt::System::new();
    let result_bag = options.result_bag.then(|| dir.join(super::run_cmd::RESULT_BAG));
    let outcome = system
        .block_on(replay_with(&scenario, &options.bags, Some(&bar), result_bag.as_deref(), threads))
        .context("the replay failed")?;
    bar.finish_and_clear();
    let report = report::write(&outcome.run, &dir).context("writing the report")?;
    let bags = serde_json::to_string_pretty(&outcome.bags).context("bag statistics")?;
    std::fs::write(dir.join("bags.json"), bags)
        .with_context(|| format!("writing {}", dir.join("bags.json").display()))?;
    let mut text = summary(&report, &outcome.run.timing, &dir);
    if let Some(path) = &result_bag {
        let _ = writeln!(text, "result bag (RViz: bridge/ros/sgm/rviz/team.rviz): {}", path.display());
    }
    for b in &outcome.bags {
        let refused: u64 = b.refused.values().sum();
        let _ = writeln!(
            text,
            "  {}: {} frames from {} ({} messages refused, {} clouds without odometry, {} without a label image)",
            b.robot,
            b.sync.frames,
            b.bag,
            refused,
            b.sync.no_odometry,
            b.sync.no_image + b.sync.no_camera_info
        );
        let s = &b.sync;
        if s.compensated > 0 || s.unlabelled > 0 {
            let labelled = s.frames - s.unlabelled;
            let _ = writeln!(
 text,
                "  {}: {} frames labelled by an image up to {} ms away ({} motion-compensated, mean skew {} ms), {} without labels",
                b.robot,
                labelled,
                s.label_skew_max_ms,
                s.compensated,
                s.label_skew_sum_ms.checked_div(labelled).unwrap_or(0),
                s.unlabelled
            );
        }
        if let Some(tf) = &b.tf {
            let mounts: Vec<String> = tf
                .mounts
                .iter()
                .map(|m| match m.source {
                    MountSource::SameFrame => format!("{} in the body frame", m.sensor),
                    MountSource::Tf => format!("{} from tf ({} ← {})", m.sensor, m.body_frame, m.sensor_frame),
                    MountSource::Config => format!("{} from {}", m.sensor, m.key),
                    MountSource::Missing => {
                        format!("{} unknown ({} ← {} not in tf)", m.sensor, m.body_frame, m.sensor_frame)
                    }
                })
                .collect();
            let _ = writeln!(text, "  {}: mounts: {}", b.robot, mounts.join(", "));
        }
        for finding in &b.health {
            let _ = writeln!(text, "  {}: health: {}; likely cause: {}", b.robot, finding.detail, finding.likely_cause);
        }
        let t = &b.timeline;
        if t.restarts > 0 || t.outliers > 0 {
            let _ = writeln!(
                text,
                "  {}: stamps: {} outliers dropped, the timeline restarted {} times (last jump {:?})",
                b.robot, t.outliers, t.restarts, t.last_jump
            );
        }
    }
    if !super::stdout::emit_text("replay", &text) {
        anyhow::bail!("the summary could not be written (the report is in {})", dir.display());
    }
    Ok(())
}
