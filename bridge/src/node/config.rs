//! A node's configuration file: the robot's sections and `[ros]`, loaded and validated.

use super::error::NodeError;
use crate::config::RosConfig;
use serde::{Deserialize, Serialize};
use sgm_actors::config::{ConfigError, RobotConfig};
use std::path::Path;

/// A node's configuration file: the robot's sections plus `[ros]`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct NodeConfig {
    #[serde(flatten)]
    pub robot: RobotConfig,
    pub ros: RosConfig,
}

impl NodeConfig {
    /// Defaults, then `file`, then `SGM__…` variables; both parts validated.
    pub fn load(file: Option<&Path>) -> Result<Self, NodeError> {
        let defaults = config::Config::try_from(&NodeConfig::default()).map_err(|e| {
            NodeError::Config(ConfigError::Load { source_name: "defaults".into(), message: e.to_string() })
        })?;
        let merged = sgm_actors::config::layered(Some(defaults), file, "SGM").map_err(NodeError::Config)?;
        let source_name = file.map_or("environment".into(), |p| p.display().to_string());
        let config: NodeConfig = merged
            .try_deserialize()
            .map_err(|e| NodeError::Config(ConfigError::Load { source_name, message: e.to_string() }))?;
        config.robot.validate().map_err(NodeError::Config)?;
        config.ros.validate().map_err(NodeError::Ros)?;
        Ok(config)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inputs::Inputs;

    /// `NodeConfig` flattens `RobotConfig`: a node's file sets `[classes]` beside `[ros]`, and a
    /// wrong entry is refused by name.
    #[test]
    fn a_node_file_sets_classes() {
        let file = tempfile::Builder::new().suffix(".toml").tempfile().unwrap();
        let text = "[classes]\nsegmenter = \"ade20k_150\"\n[classes.map]\nchair = [\"chair\", 30]\n[ros]\nlabels = \"image\"\n";
        std::fs::write(file.path(), text).unwrap();
        let config = NodeConfig::load(Some(file.path())).unwrap();
        assert_eq!(config.robot.classes.segmenter, "ade20k_150");
        assert_eq!(config.robot.classes.map["chair"].len(), 2);
        std::fs::write(file.path(), "[classes]\nsegmenter = \"ade20k_150\"\n[classes.map]\nsofa = [23]\n").unwrap();
        let error = NodeConfig::load(Some(file.path())).unwrap_err().to_string();
        assert!(error.contains("classes.map.sofa: no class \"sofa\" in fusion.classes"), "{error}");
    }

    /// Frame aliases keep their case and slashes (config's keys are frame ids, not identifiers).
    #[test]
    fn frame_aliases_keep_their_names() {
        let file = tempfile::Builder::new().suffix(".toml").tempfile().unwrap();
        let text = "[ros.frames.aliases]\ncamera_init = \"{robot}/odom\"\n\"Livox_Frame\" = \"{robot}/livox\"\n";
        std::fs::write(file.path(), text).unwrap();
        let config = NodeConfig::load(Some(file.path())).unwrap();
        let inputs = Inputs::new(&config.ros, "alpha", 1);
        assert_eq!(inputs.frame("camera_init"), "alpha/odom");
        assert_eq!(inputs.frame("/Livox_Frame"), "alpha/livox");
        assert_eq!(inputs.frame("body"), "body");
    }
}
