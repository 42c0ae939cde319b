//! `sgm ros --robot NAME [--id N] [--config FILE | --scenario NAME_OR_FILE]
//! [--development-key] [remappings…]`: one robot as a ROS 1 node until SIGINT. A public team key
//! (the default, or one printed in the book) is refused unless `--development-key` is given.

use anyhow::{bail, Context, Result};
use sgm_bridge::node::{self, NodeConfig, PublicKeys};
use sgm_scenarios::scenario::Scenario;
use std::path::PathBuf;

pub struct Options {
    pub robot: String,
    pub id: Option<u16>,
    pub config: Option<PathBuf>,
    pub scenario: Option<String>,
    /// Start even with a public team key (a loud warning).
    pub development_key: bool,
}

pub fn execute(options: Options) -> Result<()> {
    let mut config = match &options.scenario {
        Some(name) => {
            let scenario = Scenario::load(name)?;
            let Some(k) = (0..scenario.robots.len()).find(|&k| scenario.robot_name(k) == options.robot) else {
                let names: Vec<String> = (0..scenario.robots.len()).map(|k| scenario.robot_name(k)).collect();
                bail!("scenario {name} has no robot {} (it has {})", options.robot, names.join(", "));
            };
            NodeConfig { robot: scenario.robot_config(k), ros: scenario.ros.clone() }
        }
        None => NodeConfig::load(options.config.as_deref()).context("loading the configuration")?,
    };
    config.robot.robot.name = options.robot;
    if let Some(id) = options.id {
        config.robot.robot.id = id;
    }
    // The node runs for hours on wall time, with no observations to give free pages back at.
    let _release = sgm_scenarios::memory::release_free_pages_every(sgm_scenarios::memory::RELEASE_INTERVAL)
        .context("starting the thread that gives free memory back")?;
    let public = if options.development_key { PublicKeys::AllowForDevelopment } else { PublicKeys::Refuse };
    node::run(config, public)?;
    Ok(())
}
