//! `sgm doctor --robot NAME [--id N] [--config FILE | --scenario NAME] (--bag FILE | --live
//! [--duration S]) [--json] [remappings…]`: a robot's inputs checked, a verdict per input
//! (`sgm_bridge::doctor`). Exit status 0 when nothing failed (warnings allowed), 1 when an
//! input failed, 2 when the doctor could not run.

use super::ros_cmd::RobotArgs;
use anyhow::{bail, Context, Result};
use sgm_bridge::doctor::{self, Verdict};
use std::path::PathBuf;
use std::time::Duration;

pub struct Options {
    pub robot: RobotArgs,
    pub bag: Option<PathBuf>,
    pub live: bool,
    pub duration_s: f64,
    pub json: bool,
}

/// Runs the doctor; `Ok(true)` when no input failed.
pub fn execute(options: Options) -> Result<bool> {
    let config = options.robot.node_config()?;
    let report = match (&options.bag, options.live) {
        (Some(bag), false) => doctor::bag::examine_bag(bag, &config)?,
        (None, true) => {
            if !(options.duration_s.is_finite() && options.duration_s > 0.0 && options.duration_s <= 3600.0) {
                bail!("--duration {}: between 0 and 3600 s expected", options.duration_s);
            }
            // As roslaunch runs the node: in the robot's namespace, unless told otherwise.
            let ns_given =
                std::env::args().any(|a| a.starts_with("__ns:=")) || std::env::var_os("ROS_NAMESPACE").is_some();
            if !ns_given {
                std::env::set_var("ROS_NAMESPACE", format!("/{}", options.robot.robot));
            }
            doctor::live::examine_live(&config, Duration::from_secs_f64(options.duration_s))?
        }
        _ => bail!("give --bag FILE or --live"),
    };
    let text = if options.json {
        format!("{}\n", serde_json::to_string_pretty(&report).context("the report as JSON")?)
    } else {
        report.text()
    };
    if !super::stdout::emit_text("doctor", &text) {
        bail!("the report could not be written");
    }
    Ok(report.verdict != Verdict::Fail)
}
