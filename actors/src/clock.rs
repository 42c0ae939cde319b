//! The robot's clock (DESIGN.md §3): owned by the supervisor, handed to every child. Virtual in
//! scenarios and replay (the runner advances it), ROS time in the bridge. Handlers read time only
//! from here — never from the wall clock — so the same inputs give the same outputs.

use sgm_model::scene_graph::Stamp;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// A shared, monotone clock in seconds since the mission's epoch.
#[derive(Clone, Debug, Default)]
pub struct Clock {
    bits: Arc<AtomicU64>,
}

impl Clock {
    pub fn starting_at(t: Stamp) -> Self {
        let clock = Self::default();
        clock.advance_to(t);
        clock
    }

    pub fn now(&self) -> Stamp {
        f64::from_bits(self.bits.load(Ordering::Acquire))
    }

    /// Moves the clock forward to `t`; earlier or non-finite times are ignored (time never runs
    /// backwards). Returns whether it moved.
    pub fn advance_to(&self, t: Stamp) -> bool {
        if !t.is_finite() || t <= self.now() {
            return false;
        }
        self.bits.store(t.to_bits(), Ordering::Release);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotone_and_shared() {
        let a = Clock::starting_at(1.0);
        let b = a.clone();
        assert!(a.advance_to(2.5));
        assert_eq!(b.now(), 2.5);
        assert!(!b.advance_to(2.0));
        assert!(!b.advance_to(f64::NAN));
        assert_eq!(a.now(), 2.5);
    }
}
