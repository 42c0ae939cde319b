//! LiDAR-inertial odometry (issue 32), the parts built so far: the bounded local map that scans
//! register against (`local_map`), the adaptive correspondence threshold learnt from the
//! prediction's errors (`threshold`), scan-to-map registration with a motion prior that
//! reports the directions the scan leaves unconstrained (`registration`), and IMU propagation
//! of the state and its error covariance (`propagation`). The estimator that joins them comes
//! next; the Odometry actor composes them.

pub mod local_map;
pub mod propagation;
pub mod registration;
pub mod threshold;
