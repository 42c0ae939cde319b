//! ROS time ↔ SGM stamps. A stamp is seconds since the mission's epoch; the epoch is a whole
//! ROS second (the first message's, floored), so stamps stay small and exact
//! ([`stamp_from_nanos`]): a scenario step written to a bag reads back as the same `f64`.

use rosrust::Time;
use sgm_model::scene_graph::{nanos_from_stamp, stamp_from_nanos, Stamp};

/// The mission's epoch in ROS time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Epoch {
    pub sec: u32,
}

/// Scenario bags start at this ROS time (2023-11-14 22:13:20 UTC): real-looking stamps, far
/// from zero (which ROS treats as "no time").
pub const SCENARIO_EPOCH: Epoch = Epoch { sec: 1_700_000_000 };

impl Epoch {
    /// The epoch of a mission whose first message is stamped `first`.
    pub fn at(first: Time) -> Self {
        Self { sec: first.sec }
    }

    pub fn stamp(&self, t: Time) -> Stamp {
        let nanos = (i64::from(t.sec) - i64::from(self.sec)) * 1_000_000_000 + i64::from(t.nsec);
        stamp_from_nanos(nanos)
    }

    /// The ROS time of `stamp` (clamped to ROS time's range).
    pub fn time(&self, stamp: Stamp) -> Time {
        let nanos = i64::from(self.sec) * 1_000_000_000 + nanos_from_stamp(stamp);
        let nanos = nanos.clamp(0, i64::from(u32::MAX) * 1_000_000_000);
        Time { sec: (nanos / 1_000_000_000) as u32, nsec: (nanos % 1_000_000_000) as u32 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_round_trip_exactly() {
        let dt = nanos_from_stamp(0.1);
        for step in 0..10_000i64 {
            let t = stamp_from_nanos(step * dt);
            assert_eq!(SCENARIO_EPOCH.stamp(SCENARIO_EPOCH.time(t)).to_bits(), t.to_bits());
        }
        let e = Epoch::at(Time { sec: 1_650_000_123, nsec: 999_999_999 });
        assert_eq!(e.stamp(Time { sec: 1_650_000_124, nsec: 500_000_000 }), 1.5);
    }
}
