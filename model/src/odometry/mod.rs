//! LiDAR-inertial odometry (issue 32), the parts built so far: the bounded local map that scans
//! register against (`local_map`) and the adaptive correspondence threshold learnt from the
//! prediction's errors (`threshold`). Registration, IMU propagation and the estimator that joins
//! them come next; the Odometry actor composes them.

pub mod local_map;
pub mod threshold;
