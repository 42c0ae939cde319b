//! ROS 1 messages ↔ model types. Each input conversion checks what it reads and returns an
//! [`InputError`](crate::error::InputError) naming the problem; each output conversion builds a
//! complete message from model types.

pub mod cloud;
pub mod geometry;
pub mod image;
pub mod imu;
pub mod markers;
pub mod odometry;
pub mod time;
