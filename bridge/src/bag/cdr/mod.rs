//! CDR, the serialisation of rosbag2's messages: a bounded reader ([`reader`]) and the ROS 2
//! messages SGM reads, decoded into the ROS 1 types the bridge checks ([`messages`]).

pub mod messages;
pub mod reader;

pub use messages::{decode, FromCdr};
pub use reader::{CdrError, CdrReader};
