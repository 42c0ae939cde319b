//! Duplicate and replay rejection by sequence number: a sliding window of the last 64 sequence
//! numbers (the IPsec anti-replay scheme, RFC 4303 §3.4.3) per sender *and incarnation*.
//! Messages may arrive out of order within the window; a sequence seen before, or older than
//! the window, is refused.
//!
//! An envelope's sequence number is `incarnation ‖ counter` ([`Sequence`]): the top
//! [`INCARNATION_BITS`] bits name one run of the sender (a random value drawn at each start of
//! `sgm ros`; 0 in simulation, whose clock never goes back), the rest count its envelopes. A
//! receiver keeps a window per incarnation ([`ReplayGuard`]), so a robot that reboots — with
//! its clock behind, or its snapshot lost — is heard again at once under its new incarnation,
//! and a forged envelope with a huge counter can only spoil the incarnation it names, never the
//! sender's next one. A counter more than [`MAX_JUMP`] ahead of its window is refused too. Each
//! sender has at most [`MAX_INCARNATIONS`] windows; the least recently used one is retired
//! (remembered, at most [`MAX_RETIRED`] per sender, and refused from then on).

use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, VecDeque};

const WINDOW: u64 = 64;
/// Bits of the sequence number that name the sender's incarnation.
pub const INCARNATION_BITS: u32 = 24;
/// Bits of the sequence number that count envelopes within an incarnation.
pub const COUNTER_BITS: u32 = 64 - INCARNATION_BITS;
/// A counter this far beyond its window's highest is refused (a forgery, not a gap).
pub const MAX_JUMP: u64 = 1 << 32;
/// Incarnations with a window, per sender.
pub const MAX_INCARNATIONS: usize = 4;
/// Retired incarnations remembered (and refused), per sender.
pub const MAX_RETIRED: usize = 64;
/// Counters reserved ahead of the highest accepted, per (sender, incarnation): the journal a
/// restored receiver reads is written at most every `RESERVE / 2` envelopes of a sender.
pub const RESERVE: u64 = 64;

/// A sequence number's two parts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Sequence {
    pub incarnation: u32,
    pub counter: u64,
}

impl Sequence {
    /// The first sequence of `incarnation` (counter 1).
    pub fn first(incarnation: u32) -> u64 {
        Self { incarnation, counter: 1 }.to_bits()
    }

    pub fn from_bits(bits: u64) -> Self {
        Self { incarnation: (bits >> COUNTER_BITS) as u32, counter: bits & ((1 << COUNTER_BITS) - 1) }
    }

    pub fn to_bits(self) -> u64 {
        (u64::from(self.incarnation) << COUNTER_BITS) | (self.counter & ((1 << COUNTER_BITS) - 1))
    }
}

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
    #[error("sequence {sequence} is more than {MAX_JUMP} ahead of the window (highest {highest})")]
    TooFarAhead { sequence: u64, highest: u64 },
    #[error("incarnation {0:#x} of the sender was retired")]
    Retired(u32),
    #[error("sequence {sequence} is at or below {floor}, what this receiver may have accepted before it restarted")]
    BeforeRestore { sequence: u64, floor: u64 },
}

impl ReplayWindow {
    /// The highest sequence accepted so far.
    pub fn highest(&self) -> Option<u64> {
        self.highest
    }

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

/// One sender's windows, by incarnation.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SenderWindows {
    /// Incarnation → (its window, when it was last used: the guard's use counter).
    windows: BTreeMap<u32, (ReplayWindow, u64)>,
    retired: VecDeque<u32>,
    /// Per incarnation: counters at or below this were possibly accepted before a restart
    /// (see [`ReplayGuard::restored`]).
    floors: BTreeMap<u32, u64>,
}

/// Every sender's windows: what a receiver applies to each authenticated envelope.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ReplayGuard {
    senders: BTreeMap<u16, SenderWindows>,
    uses: u64,
    /// Per (sender, incarnation): no counter above this has been accepted; grown by
    /// [`RESERVE`] when the highest comes within `RESERVE / 2` of it.
    reserved: BTreeMap<(u16, u32), u64>,
}

/// What an accepted envelope means for the journal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Accepted {
    /// Within the reservation already made.
    Reserved,
    /// The reservation grew: write [`ReplayGuard::reservations`] to the journal.
    ReservationGrew,
}

impl ReplayGuard {
    /// Accepts `sequence` from `sender` once (see the module comment).
    pub fn accept(&mut self, sender: u16, sequence: u64) -> Result<Accepted, ReplayError> {
        let Sequence { incarnation, counter } = Sequence::from_bits(sequence);
        self.uses += 1;
        let uses = self.uses;
        let s = self.senders.entry(sender).or_default();
        if s.retired.contains(&incarnation) {
            return Err(ReplayError::Retired(incarnation));
        }
        if let Some(&floor) = s.floors.get(&incarnation) {
            if counter <= floor {
                return Err(ReplayError::BeforeRestore { sequence: counter, floor });
            }
        }
        if let Some((window, _)) = s.windows.get(&incarnation) {
            if let Some(highest) = window.highest() {
                if counter > highest && counter - highest > MAX_JUMP {
                    return Err(ReplayError::TooFarAhead { sequence: counter, highest });
                }
            }
        } else if s.windows.len() >= MAX_INCARNATIONS {
            // Room for the new incarnation: the least recently used one retires.
            if let Some(oldest) = s.windows.iter().min_by_key(|(_, (_, used))| *used).map(|(i, _)| *i) {
                s.windows.remove(&oldest);
                s.floors.remove(&oldest);
                self.reserved.remove(&(sender, oldest));
                if s.retired.len() >= MAX_RETIRED {
                    s.retired.pop_front();
                }
                s.retired.push_back(oldest);
            }
        }
        let (window, used) = s.windows.entry(incarnation).or_default();
        window.accept(counter)?;
        *used = uses;
        let reserved = self.reserved.entry((sender, incarnation)).or_default();
        if counter + RESERVE / 2 > *reserved {
            *reserved = counter + RESERVE;
            return Ok(Accepted::ReservationGrew);
        }
        Ok(Accepted::Reserved)
    }

    /// Every (sender, incarnation, reserved counter): what a journal keeps.
    pub fn reservations(&self) -> Vec<(u16, u32, u64)> {
        self.reserved.iter().map(|((s, i), r)| (*s, *i, *r)).collect()
    }

    /// The highest counter accepted per (sender, incarnation).
    pub fn highest(&self) -> impl Iterator<Item = (u16, u32, u64)> + '_ {
        self.senders.iter().flat_map(|(sender, s)| {
            s.windows.iter().filter_map(move |(inc, (w, _))| Some((*sender, *inc, w.highest()?)))
        })
    }

    /// After a restart from a snapshot: this receiver may have accepted, after the snapshot,
    /// counters up to `reserved` of each (sender, incarnation) (its journal of reservations,
    /// see `Comms`); none of them is accepted again.
    pub fn restored(&mut self, reserved: impl IntoIterator<Item = (u16, u32, u64)>) {
        for (sender, incarnation, floor) in reserved {
            let s = self.senders.entry(sender).or_default();
            let f = s.floors.entry(incarnation).or_default();
            *f = (*f).max(floor);
        }
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

    fn seq(incarnation: u32, counter: u64) -> u64 {
        Sequence { incarnation, counter }.to_bits()
    }

    #[test]
    fn sequences_split_into_incarnation_and_counter() {
        let bits = seq(0xAB_CDEF, 12_345);
        assert_eq!(Sequence::from_bits(bits), Sequence { incarnation: 0xAB_CDEF, counter: 12_345 });
        // Simulation's sequences (incarnation 0, the clock in µs) read as plain counters.
        assert_eq!(Sequence::from_bits(1_700_000_000), Sequence { incarnation: 0, counter: 1_700_000_000 });
        assert_eq!(Sequence::first(7), (7 << COUNTER_BITS) | 1);
    }

    #[test]
    fn a_rebooted_sender_is_heard_at_once_under_its_new_incarnation() {
        let mut g = ReplayGuard::default();
        for c in 1..=500 {
            g.accept(3, seq(0x11, c)).unwrap();
        }
        // Rebooted with its clock behind, snapshot lost: counting from 1 again, new incarnation.
        g.accept(3, seq(0x22, 1)).unwrap();
        g.accept(3, seq(0x22, 2)).unwrap();
        // Recordings of its old run stay refused.
        assert!(matches!(g.accept(3, seq(0x11, 500)), Err(ReplayError::Duplicate(500))));
        assert!(matches!(g.accept(3, seq(0x11, 10)), Err(ReplayError::TooOld { .. })));
    }

    #[test]
    fn a_forged_huge_counter_does_not_lock_the_sender_out() {
        let mut g = ReplayGuard::default();
        g.accept(3, seq(0x11, 1)).unwrap();
        // Under its own incarnation: refused, the window does not move.
        assert!(matches!(g.accept(3, seq(0x11, (1 << COUNTER_BITS) - 1)), Err(ReplayError::TooFarAhead { .. })));
        g.accept(3, seq(0x11, 2)).unwrap();
        // Under an incarnation of its own invention: it spoils only that one.
        g.accept(3, seq(0x99, (1 << COUNTER_BITS) - 1)).unwrap();
        g.accept(3, seq(0x11, 3)).unwrap();
    }

    #[test]
    fn incarnations_are_bounded_and_retired_ones_refused() {
        let mut g = ReplayGuard::default();
        g.accept(3, seq(1, 1)).unwrap();
        for inc in 2..=(MAX_INCARNATIONS as u32) {
            g.accept(3, seq(inc, 1)).unwrap();
        }
        g.accept(3, seq(1, 2)).unwrap(); // incarnation 1 used again: 2 is now the oldest
        g.accept(3, seq(100, 1)).unwrap();
        assert_eq!(g.accept(3, seq(2, 2)), Err(ReplayError::Retired(2)));
        g.accept(3, seq(1, 3)).unwrap();
        assert_eq!(g.highest().filter(|(s, _, _)| *s == 3).count(), MAX_INCARNATIONS);
    }

    #[test]
    fn reservations_run_ahead_of_what_was_accepted() {
        let mut g = ReplayGuard::default();
        let mut grew = Vec::new();
        for c in 1..=200 {
            if g.accept(3, seq(9, c)).unwrap() == Accepted::ReservationGrew {
                grew.push(c);
            }
            // The invariant a restored receiver relies on: nothing accepted above the reservation.
            let reserved = g.reservations()[0].2;
            assert!(c < reserved, "{c} accepted, {reserved} reserved");
        }
        // The journal is written every RESERVE / 2 envelopes, not on each one.
        assert_eq!(grew, vec![1, 34, 67, 100, 133, 166, 199]);
    }

    #[test]
    fn a_restored_receiver_refuses_what_it_may_have_accepted_before() {
        let mut g = ReplayGuard::default();
        g.accept(3, seq(5, 10)).unwrap();
        // Snapshot at counter 10; before the crash it reserved up to 40 in its journal.
        g.restored([(3, 5, 40)]);
        assert_eq!(g.accept(3, seq(5, 25)), Err(ReplayError::BeforeRestore { sequence: 25, floor: 40 }));
        assert_eq!(g.accept(3, seq(5, 40)), Err(ReplayError::BeforeRestore { sequence: 40, floor: 40 }));
        g.accept(3, seq(5, 41)).unwrap();
        // Another sender, another incarnation: untouched.
        g.accept(4, seq(5, 11)).unwrap();
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
