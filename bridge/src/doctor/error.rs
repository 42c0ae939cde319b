//! Why the doctor cannot run: the configuration, the bag, or the master.

use crate::bag::reader::BagError;
use crate::config::RosConfigError;
use sgm_actors::config::ConfigError;

/// Why the doctor cannot run.
#[derive(Debug, thiserror::Error)]
pub enum DoctorError {
    /// The robot's sections make no class tables or colour map (`[fusion]`, `[classes]`).
    #[error("{0}")]
    Config(#[from] ConfigError),
    /// The `[ros]` section is refused.
    #[error("[ros]: {0}")]
    Ros(#[from] RosConfigError),
    /// The bag cannot be read, or a topic in it has the wrong type.
    #[error("{0}")]
    Bag(#[from] BagError),
    /// No master answers at `ROS_MASTER_URI` (rosrust's error is not `Sync`: its text is kept).
    #[error("no ROS master at ROS_MASTER_URI: {0}")]
    NoMaster(String),
    /// An input topic could not be subscribed.
    #[error("subscribing {topic}: {reason}")]
    Subscribe { topic: String, reason: String },
    /// The live doctor's state was already taken (not expected: it is taken once).
    #[error("the doctor was taken twice")]
    TakenTwice,
}

#[cfg(test)]
mod tests {
    use crate::doctor::{Doctor, DoctorError};
    use crate::node::NodeConfig;

    /// A `[ros]` section the node would refuse: the doctor does not start, and says which key.
    #[test]
    fn a_refused_ros_section_is_named() {
        let mut config = NodeConfig::default();
        config.ros.body_from_lidar = Some([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0]);
        let Err(e) = Doctor::new(&config) else { panic!("a bad mounting is refused") };
        assert!(matches!(e, DoctorError::Ros(_)), "{e:?}");
        assert!(e.to_string().starts_with("[ros]: ros.body_from_lidar: "), "{e}");
    }
}
