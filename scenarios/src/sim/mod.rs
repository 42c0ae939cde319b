//! The simulator: a seeded world, routes, the LiDAR, the camera with its segmentation errors,
//! drifting odometry and the radio — everything a robot would get from hardware.

pub mod camera;
pub mod false_factors;
pub mod imu;
pub mod lidar;
pub mod mount;
pub mod odometry;
pub mod path;
pub mod people;
pub mod platform;
pub mod radio;
pub mod segmenter_errors;
pub mod setup;
pub mod shapes;
pub mod speed_profile;
pub mod terrain;
pub mod trajectory;
pub mod world;
