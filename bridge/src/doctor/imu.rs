//! What the doctor tells of an IMU stream the robot's own odometry would run on: the samples it
//! would drop, and why (the odometry's own screen, `ImuLimits::screen`, with the robot's
//! `odometry.estimator.imu_limits`), and the gaps it would coast across.

use crate::convert::imu::ImuReading;
use sgm_model::odometry::imu_queue::{ImuDrop, ImuLimits};
use sgm_model::perception::imu::ImuSample;

/// Counts over an IMU stream, in arrival order.
#[derive(Clone, Debug, Default)]
pub struct ImuTally {
    limits: ImuLimits,
    pub kept: u64,
    pub non_finite: u64,
    pub saturated: u64,
    pub out_of_order: u64,
    /// Intervals between kept samples longer than `max_gap_s`, and the longest interval, s.
    pub gaps: u64,
    pub longest_interval_s: f64,
    newest: Option<f64>,
}

impl ImuTally {
    pub fn new(limits: ImuLimits) -> Self {
        Self { limits, ..Self::default() }
    }

    pub fn limits(&self) -> &ImuLimits {
        &self.limits
    }

    /// One reading at `stamp` (s, mission time). Saturation is judged on the IMU's own axes,
    /// where its range applies.
    pub fn add(&mut self, stamp: f64, reading: &ImuReading) {
        let sample = ImuSample {
            stamp,
            angular_velocity: reading.angular_velocity,
            specific_force: reading.linear_acceleration,
        };
        match self.limits.screen(&sample, self.newest) {
            Some(ImuDrop::NonFinite) => self.non_finite += 1,
            Some(ImuDrop::OutOfOrder) => self.out_of_order += 1,
            // The odometry keeps it, clipped: it holds the time as any sample does.
            screened @ (Some(ImuDrop::Saturated) | None) => {
                if screened.is_some() {
                    self.saturated += 1;
                } else {
                    self.kept += 1;
                }
                if let Some(newest) = self.newest {
                    let interval = stamp - newest;
                    self.longest_interval_s = self.longest_interval_s.max(interval);
                    if interval > self.limits.max_gap_s {
                        self.gaps += 1;
                    }
                }
                self.newest = Some(stamp);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn drops_and_gaps_are_counted_as_the_odometry_counts_them() {
        let still =
            ImuReading { angular_velocity: Vector3::zeros(), linear_acceleration: Vector3::new(0.0, 0.0, 9.81) };
        let mut tally = ImuTally::new(ImuLimits::default());
        for k in 0..10 {
            tally.add(f64::from(k) * 0.005, &still);
        }
        tally.add(0.2, &still); // 0.155 s after the last: a gap
        tally.add(0.1, &still); // backwards
        tally.add(0.2, &still); // a repeat
        tally.add(0.21, &ImuReading { angular_velocity: Vector3::new(0.0, 40.0, 0.0), ..still });
        tally.add(0.22, &ImuReading { linear_acceleration: Vector3::new(f64::NAN, 0.0, 9.81), ..still });
        tally.add(0.225, &still);
        assert_eq!((tally.kept, tally.gaps, tally.out_of_order, tally.saturated, tally.non_finite), (12, 1, 2, 1, 1));
        assert!((tally.longest_interval_s - 0.155).abs() < 1e-12);
    }
}
