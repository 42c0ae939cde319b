//! How far the robot's pipeline has got: the stamp of the last sensor frame the Tracker has
//! handled (its pose decided, the map updated). Written by the Tracker, read by whoever measures
//! latency (the ROS node's status); never read by a handler, so it changes nothing a robot
//! decides.

use sgm_model::scene_graph::Stamp;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// The stamp of the newest frame handled by the Tracker (NaN-free, −∞ before the first).
#[derive(Clone, Debug)]
pub struct FrameProgress(Arc<AtomicU64>);

impl Default for FrameProgress {
    fn default() -> Self {
        Self(Arc::new(AtomicU64::new(f64::NEG_INFINITY.to_bits())))
    }
}

impl FrameProgress {
    pub fn handled(&self, stamp: Stamp) {
        if stamp.is_finite() && stamp > self.latest() {
            self.0.store(stamp.to_bits(), Ordering::Release);
        }
    }

    pub fn latest(&self) -> Stamp {
        f64::from_bits(self.0.load(Ordering::Acquire))
    }
}
