//! Which neighbours are heard, as plain state. A neighbour owing us keyframes and silent for
//! `link_timeout_s` since the later of when it was last heard and when it began to owe goes
//! down; one with nothing outstanding may be quiet for as long as it likes. A neighbour heard
//! for the first time, or again after its link went down, needs our ObjectData soon; one back
//! from silence also has its unanswered keyframe requests asked afresh.

use sgm_model::scene_graph::{RobotId, Stamp};
use std::collections::{BTreeMap, BTreeSet};

/// What hearing a neighbour means.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Heard {
    /// Heard for the first time.
    pub first: bool,
    /// Its link was down and is up again.
    pub back: bool,
}

#[derive(Clone, Debug, Default)]
pub struct LinkWatch {
    last_heard: BTreeMap<RobotId, Stamp>,
    down: BTreeSet<RobotId>,
}

impl LinkWatch {
    /// `from` was heard at `now`.
    pub fn heard(&mut self, from: RobotId, now: Stamp) -> Heard {
        let first = self.last_heard.insert(from, now).is_none();
        Heard { first, back: self.down.remove(&from) }
    }

    /// When `robot` was last heard.
    pub fn last_heard(&self, robot: RobotId) -> Option<Stamp> {
        self.last_heard.get(&robot).copied()
    }

    pub fn is_down(&self, robot: RobotId) -> bool {
        self.down.contains(&robot)
    }

    /// The neighbours now down, in id order.
    pub fn down(&self) -> Vec<RobotId> {
        self.down.iter().copied().collect()
    }

    /// The links that go down at `now` (in id order): `owed_since(r)` is since when `r` has
    /// owed us keyframes without a break, if it does.
    pub fn lost(&mut self, now: Stamp, timeout_s: f64, owed_since: impl Fn(RobotId) -> Option<Stamp>) -> Vec<RobotId> {
        let silent: Vec<RobotId> = self
            .last_heard
            .iter()
            .filter(|(r, heard)| {
                owed_since(**r).is_some_and(|since| now - since.max(**heard) >= timeout_s) && !self.down.contains(r)
            })
            .map(|(r, _)| *r)
            .collect();
        self.down.extend(silent.iter().copied());
        silent
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_silent_neighbour_that_owes_goes_down_and_comes_back() {
        let mut w = LinkWatch::default();
        let (a, b) = (RobotId(2), RobotId(3));
        assert_eq!(w.heard(a, 0.0), Heard { first: true, back: false });
        assert_eq!(w.heard(b, 0.0), Heard { first: true, back: false });
        assert_eq!(w.heard(a, 1.0), Heard::default());
        // a owes since 5 s; b owes nothing and may be quiet.
        let owed = |r: RobotId| (r == a).then_some(5.0);
        assert!(w.lost(14.9, 10.0, owed).is_empty(), "10 s from the later of heard and owed");
        assert_eq!(w.lost(15.0, 10.0, owed), vec![a]);
        assert!(w.lost(100.0, 10.0, owed).is_empty(), "down once");
        assert_eq!((w.is_down(a), w.down()), (true, vec![a]));
        assert_eq!(w.heard(a, 101.0), Heard { first: false, back: true });
        assert!(w.down().is_empty());
        assert_eq!(w.last_heard(a), Some(101.0));
    }
}
