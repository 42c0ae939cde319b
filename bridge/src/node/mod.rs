//! `sgm ros`: one robot as a ROS 1 node. Sensor topics in (checked by
//! [`Inputs`](crate::inputs::Inputs), assembled by the
//! [`Synchroniser`](crate::sync::Synchroniser)), the robot's actor tree in the middle, RViz-ready
//! outputs and the inter-robot [`RosTransport`](crate::transport::RosTransport) out. Names come
//! from the `[ros]` section and resolve in the node's namespace; rosrust honours `ROS_MASTER_URI`,
//! `ROS_IP`/`ROS_HOSTNAME`, `ROS_NAMESPACE`, `__name:=`, `__ns:=` and `from:=to` remappings on the
//! command line.
//!
//! The robot's clock is the newest sensor stamp (ROS time, seconds since 1970): the node runs
//! the same whether its sensors are live or a bag played at any rate. Handlers never read the
//! wall clock; only the tick and publish loop waits on it.
//!
//! The node's configuration file (`config.rs`: [`NodeConfig`]) and its errors (`error.rs`:
//! [`NodeError`]); the team key refused unless public keys are allowed (`team_key.rs`); the
//! sensor side, inputs checked, counted and fed to the synchroniser (`sensors.rs`); the outputs
//! and their publication failures (`outputs.rs`); this robot's world frame registered on the
//! master (`world_frames.rs`); and the node itself, started and ticked (`run.rs`: [`run`]).

mod config;
mod error;
mod outputs;
mod run;
mod sensors;
mod team_key;
mod world_frames;

pub use config::NodeConfig;
pub use error::NodeError;
pub use run::run;
pub use team_key::{check_team_key, PublicKeys};
