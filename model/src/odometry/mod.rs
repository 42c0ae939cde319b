//! LiDAR-inertial odometry (issue 32): the bounded local map that scans register against
//! (`local_map`), the adaptive correspondence threshold learnt from the prediction's errors
//! (`threshold`), scan-to-map registration with a motion prior that reports the directions the
//! scan leaves unconstrained (`registration`), IMU propagation of the state and its error
//! covariance (`propagation`) over the samples as they arrived (`imu_queue`), the scan's
//! correction of the whole state (`update`), the covariance of the motion between two scans
//! (`clone`), and the estimator that joins them (`estimator`).
//! The Odometry actor is a thin shell over the estimator.

pub mod clone;
pub mod config;
pub mod estimator;
pub mod imu_queue;
pub mod local_map;
pub mod propagation;
pub mod registration;
pub mod threshold;
pub mod update;

#[cfg(test)]
mod testing;
