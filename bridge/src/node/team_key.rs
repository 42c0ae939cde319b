//! The team key a node starts with: a public one (the default, or one printed in the book or the
//! shipped configurations) is refused unless development allows it.

use super::error::NodeError;
use sgm_actors::config::RobotConfig;

/// Whether a node may start with a team key of
/// [`PUBLIC_TEAM_KEYS`](sgm_actors::config::PUBLIC_TEAM_KEYS).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PublicKeys {
    /// Refuse to start (the default of `sgm ros`).
    Refuse,
    /// Start, with a warning (`sgm ros --development-key`).
    AllowForDevelopment,
}

/// Refuses a public team key (the default, or one printed in the book or the shipped
/// configurations) unless `public` allows it, and then warns. A ROS node listens on a network,
/// where anyone who knows the key can speak for the team.
pub fn check_team_key(config: &RobotConfig, public: PublicKeys) -> Result<(), NodeError> {
    let Some(key) = config.comms.public_team_key().map_err(NodeError::Config)? else { return Ok(()) };
    match public {
        PublicKeys::Refuse => Err(NodeError::PublicKey { published: key.published }),
        PublicKeys::AllowForDevelopment => {
            tracing::warn!(
                robot = %config.robot.name,
                "DEVELOPMENT KEY: the team key is public ({}); anyone who reaches the ROS master can \
                 forge, alter and replay this team's messages. Never use --development-key in the field: \
                 set comms.team_key_file to a key of the team's own",
                key.published
            );
            Ok(())
        }
    }
}
