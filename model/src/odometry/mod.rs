//! LiDAR-inertial odometry (issue 32), the parts built so far: the bounded local map that scans
//! register against (`local_map`), the adaptive correspondence threshold learnt from the
//! prediction's errors (`threshold`), and scan-to-map registration with a motion prior that
//! reports the directions the scan leaves unconstrained (`registration`). IMU propagation and
//! the estimator that joins them come next; the Odometry actor composes them.

pub mod local_map;
pub mod registration;
pub mod threshold;
