//! Why a node does not start or stops.

use crate::config::RosConfigError;
use sgm_actors::config::ConfigError;
use sgm_model::perception::classes::ClassTableError;

#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    #[error("{0}")]
    Config(ConfigError),
    #[error(
        "the team key is public ({published}): anyone who reaches the ROS master could forge, alter \
         and replay this team's messages. Give the team a key of its own: \
         `(umask 077 && head -c 32 /dev/urandom | od -An -vtx1 | tr -d ' \\n' > team.key)`, copy team.key \
         to every robot (mode 600) and set comms.team_key_file to its absolute path \
         (SGM__COMMS__TEAM_KEY_FILE=/path/to/team.key, or roslaunch sgm robot.launch \
         team_key_file:=/path/to/team.key); for development on a private network only, \
         `sgm ros --development-key` starts with a public key"
    )]
    PublicKey { published: &'static str },
    #[error("[ros]: {0}")]
    Ros(RosConfigError),
    /// `fusion.classes` does not make a class table (a configuration `NodeConfig::load` read
    /// was validated already).
    #[error("[ros]: fusion.classes: {0}")]
    Classes(ClassTableError),
    #[error("ROS: {0}")]
    Ros1(String),
    #[error("[persistence]: {0}")]
    Snapshot(sgm_actors::snapshot::StoreError),
}

pub(super) fn ros_error(e: impl std::fmt::Display) -> NodeError {
    NodeError::Ros1(e.to_string())
}
