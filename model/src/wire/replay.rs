//! Duplicate and replay rejection by sequence number: a sliding window of the last 64 sequence
//! numbers per sender (the IPsec anti-replay scheme, RFC 4303 §3.4.3). Messages may arrive out
//! of order within the window; a sequence seen before, or older than the window, is refused.

use serde::{Deserialize, Serialize};

const WINDOW: u64 = 64;

/// The receive window of one sender.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ReplayWindow {
    /// Highest sequence accepted so far.
    highest: Option<u64>,
    /// Bit k set: sequence `highest − k` was accepted.
    seen: u64,
}

/// Why a sequence number was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ReplayError {
    #[error("sequence {0} was already received")]
    Duplicate(u64),
    #[error("sequence {sequence} is older than the window (highest {highest})")]
    TooOld { sequence: u64, highest: u64 },
}

impl ReplayWindow {
    /// Accepts `sequence` once; refuses repeats and anything older than the window.
    pub fn accept(&mut self, sequence: u64) -> Result<(), ReplayError> {
        let Some(highest) = self.highest else {
            self.highest = Some(sequence);
            self.seen = 1;
            return Ok(());
        };
        if sequence > highest {
            let shift = sequence - highest;
            self.seen = if shift >= WINDOW { 1 } else { (self.seen << shift) | 1 };
            self.highest = Some(sequence);
            return Ok(());
        }
        let age = highest - sequence;
        if age >= WINDOW {
            return Err(ReplayError::TooOld { sequence, highest });
        }
        let bit = 1u64 << age;
        if self.seen & bit != 0 {
            return Err(ReplayError::Duplicate(sequence));
        }
        self.seen |= bit;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::collections::BTreeSet;

    #[test]
    fn in_order_reordered_duplicated_and_old() {
        let mut w = ReplayWindow::default();
        for s in [10, 12, 11, 20] {
            w.accept(s).unwrap();
        }
        assert_eq!(w.accept(12), Err(ReplayError::Duplicate(12)));
        w.accept(13).unwrap();
        w.accept(100).unwrap();
        assert_eq!(w.accept(20), Err(ReplayError::TooOld { sequence: 20, highest: 100 }));
        w.accept(37).unwrap(); // age 63: still inside
        assert_eq!(w.accept(36), Err(ReplayError::TooOld { sequence: 36, highest: 100 }));
    }

    proptest! {
        /// Against a model that remembers every sequence: accepted exactly when new and within
        /// 64 of the highest accepted so far.
        #[test]
        fn matches_a_model(seqs in prop::collection::vec(0u64..300, 1..200)) {
            let mut w = ReplayWindow::default();
            let mut seen = BTreeSet::new();
            let mut highest: Option<u64> = None;
            for s in seqs {
                let fresh = !seen.contains(&s) && highest.is_none_or(|h| s + WINDOW > h);
                prop_assert_eq!(w.accept(s).is_ok(), fresh, "sequence {}", s);
                if fresh {
                    seen.insert(s);
                    highest = Some(highest.map_or(s, |h| h.max(s)));
                }
            }
        }
    }
}
