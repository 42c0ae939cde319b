//! `sgm ros --robot NAME [--id N] [--config FILE | --scenario NAME_OR_FILE]
//! [--development-key] [remappings…]`: one robot as a ROS 1 node until SIGINT. A public team key
//! (the default, or one printed in the book) is refused unless `--development-key` is given.

use anyhow::{bail, Context, Result};
use sgm_bridge::node::{self, NodeConfig, PublicKeys};
use sgm_scenarios::scenario::Scenario;
use std::path::{Path, PathBuf};

/// Which robot, configured how: what `sgm ros` and `sgm doctor` share.
#[derive(clap::Args, Clone, Debug)]
pub struct RobotArgs {
    /// The robot's name (node sgm_NAME; `{robot}` in topics and frames; with `sgm doctor --live`,
    /// its namespace).
    #[arg(long)]
    pub robot: String,
    /// The robot's id, unique in the team (default: the configuration's robot.id).
    #[arg(long)]
    pub id: Option<u16>,
    /// Robot configuration file (TOML: the robot's sections and [ros]).
    #[arg(long, conflicts_with = "scenario")]
    pub config: Option<PathBuf>,
    /// Take the robot's configuration from a scenario (library name or file) instead:
    /// its shared sections, [ros], and this robot's name and id from [[robots]].
    #[arg(long)]
    pub scenario: Option<String>,
}

impl RobotArgs {
    /// The robot's node configuration.
    pub fn node_config(&self) -> Result<NodeConfig> {
        node_config(&self.robot, self.id, self.config.as_deref(), self.scenario.as_deref())
    }
}

pub struct Options {
    pub robot: RobotArgs,
    /// Start even with a public team key (a loud warning).
    pub development_key: bool,
}

/// Robot `robot`'s node configuration: from a file (or the defaults), or from a scenario's
/// robot of that name; `id` overrides the configuration's.
fn node_config(robot: &str, id: Option<u16>, config: Option<&Path>, scenario: Option<&str>) -> Result<NodeConfig> {
    let mut node = match scenario {
        Some(name) => {
            let scenario = Scenario::load(name)?;
            let Some(k) = (0..scenario.robots.len()).find(|&k| scenario.robot_name(k) == robot) else {
                let names: Vec<String> = (0..scenario.robots.len()).map(|k| scenario.robot_name(k)).collect();
                bail!("scenario {name} has no robot {robot} (it has {})", names.join(", "));
            };
            NodeConfig { robot: scenario.robot_config(k), ros: scenario.ros.clone() }
        }
        None => NodeConfig::load(config).context("loading the configuration")?,
    };
    node.robot.robot.name = robot.to_string();
    if let Some(id) = id {
        node.robot.robot.id = id;
    }
    Ok(node)
}

pub fn execute(options: Options) -> Result<()> {
    let config = options.robot.node_config()?;
    // The node runs for hours on wall time, with no observations to give free pages back at.
    let _release = sgm_scenarios::memory::release_free_pages_every(sgm_scenarios::memory::RELEASE_INTERVAL)
        .context("starting the thread that gives free memory back")?;
    let public = if options.development_key { PublicKeys::AllowForDevelopment } else { PublicKeys::Refuse };
    node::run(config, public)?;
    Ok(())
}
