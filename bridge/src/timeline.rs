//! The timeline: sensor stamps checked against the stream before anything believes them.
//!
//! A driver glitch, `rosbag play --loop` or a `/clock` jump puts a stamp far from the rest. The
//! synchroniser refuses whatever is older than the newest stamp of its stream, and the robot's
//! clock never runs backwards, so one message stamped years ahead would stop mapping until a
//! restart. Here every stamped input passes first:
//!
//! - the first timeline is believed once `confirm_messages` stamps agree (each within
//!   `max_jump_s` of the one before); until then they wait, and a stamp that disagrees starts
//!   the count again (the earlier ones were outliers: dropped and counted);
//! - on an established timeline, a stamp within `max_jump_s` of its newest passes at once
//!   (ordering within that is the synchroniser's business); one farther off waits as the start
//!   of a candidate timeline. A candidate that gathers `confirm_messages` agreeing stamps is a
//!   real jump: the timeline **restarts** (logged, counted, in the status) and everything that
//!   waited passes. Stamps that return to the old timeline first show the candidate was a
//!   glitch: its messages are dropped as outliers.
//!
//! Downstream time never jumps: stamps are mapped to *mission time* by an offset, zero until
//! the first restart, which then places the new timeline [`RESTART_GAP_S`] after the newest
//! mission time handed out. Outputs go back to ROS time through the same offset ([`Self::to_ros`]).
//! No wall clock here: the same stamps give the same decisions, live or replayed.

use rosrust::Time;
use serde::{Deserialize, Serialize};

/// Mission time between the last stamp of a timeline and the first of the next, s.
pub const RESTART_GAP_S: f64 = 1.0;

/// `[ros.timeline]`: when a stamp is believed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TimelineConfig {
    /// Stamps farther than this from the timeline's newest (ahead or behind) are a possible
    /// jump and wait for confirmation, s. Default 10.
    pub max_jump_s: f64,
    /// Agreeing stamps in a row that establish the first timeline or confirm a jump.
    /// Default 5.
    pub confirm_messages: usize,
}

impl Default for TimelineConfig {
    fn default() -> Self {
        Self { max_jump_s: 10.0, confirm_messages: 5 }
    }
}

/// What the timeline did, for the status and the replay's report.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TimelineCounts {
    /// Jumps confirmed (the timeline restarted).
    pub restarts: u64,
    /// Messages whose stamps no timeline confirmed (dropped).
    pub outliers: u64,
    /// Messages waiting for confirmation now.
    pub waiting: u64,
    /// The last restart: ROS time before and after the jump, s.
    pub last_jump: Option<(f64, f64)>,
    /// Mission time minus ROS time, ns (0 until the first restart).
    pub offset_ns: i64,
}

/// A timeline restart, for the log.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Restart {
    /// The old timeline's newest stamp and the new one's first, ROS time in s.
    pub from_s: f64,
    pub to_s: f64,
}

/// What [`Timeline::admit`] gives back.
#[derive(Debug)]
pub struct Admitted<T> {
    /// Messages that may go on, in order, with their stamps in mission time.
    pub released: Vec<(Time, T)>,
    /// The timeline restarted before `released` (the synchroniser should start afresh).
    pub restart: Option<Restart>,
}

fn nanos(t: Time) -> i64 {
    i64::from(t.sec) * 1_000_000_000 + i64::from(t.nsec)
}

fn time(nanos: i64) -> Time {
    let nanos = nanos.clamp(0, i64::from(u32::MAX) * 1_000_000_000 + 999_999_999);
    Time { sec: (nanos / 1_000_000_000) as u32, nsec: (nanos % 1_000_000_000) as u32 }
}

/// One robot's timeline; `T` is whatever travels with a stamp.
#[derive(Debug)]
pub struct Timeline<T> {
    config: TimelineConfig,
    /// Newest ROS stamp of the established timeline (none until established).
    newest: Option<i64>,
    /// Newest mission time handed out, ns.
    handed_out: Option<i64>,
    offset: i64,
    /// Messages of a timeline not yet confirmed (the first one, or a jump), in arrival order.
    candidate: Vec<(i64, T)>,
    pub counts: TimelineCounts,
}

impl<T> Timeline<T> {
    pub fn new(config: TimelineConfig) -> Self {
        Self {
            config,
            newest: None,
            handed_out: None,
            offset: 0,
            candidate: Vec::new(),
            counts: TimelineCounts::default(),
        }
    }

    fn max_jump(&self) -> i64 {
        (self.config.max_jump_s * 1e9) as i64
    }

    fn near(&self, a: i64, b: i64) -> bool {
        (a - b).abs() <= self.max_jump()
    }

    /// The mission time of ROS time `t` (for inputs that are not checked: ground truth).
    pub fn to_mission(&self, t: Time) -> Time {
        time(nanos(t) + self.offset)
    }

    /// The ROS time of mission time `t`.
    pub fn to_ros(&self, t: Time) -> Time {
        time(nanos(t) - self.offset)
    }

    fn release(&mut self, stamp: i64, item: T, out: &mut Vec<(Time, T)>) {
        let mission = stamp + self.offset;
        self.handed_out = Some(self.handed_out.map_or(mission, |h| h.max(mission)));
        out.push((time(mission), item));
    }

    /// Checks `item` stamped `stamp` (ROS time): it goes on now, waits, or is dropped.
    pub fn admit(&mut self, stamp: Time, item: T) -> Admitted<T> {
        let t = nanos(stamp);
        let mut released = Vec::new();
        let mut restart = None;
        match self.newest {
            Some(newest) if self.near(t, newest) => {
                // Back on the established timeline: whatever started a candidate was a glitch.
                self.drop_candidate();
                self.newest = Some(newest.max(t));
                self.release(t, item, &mut released);
            }
            _ => {
                if self.candidate.last().is_some_and(|(last, _)| !self.near(t, *last)) {
                    self.drop_candidate();
                }
                self.candidate.push((t, item));
                if self.candidate.len() >= self.config.confirm_messages.max(1) {
                    restart = self.confirm(&mut released);
                }
            }
        }
        self.counts.waiting = self.candidate.len() as u64;
        Admitted { released, restart }
    }

    fn drop_candidate(&mut self) {
        self.counts.outliers += self.candidate.len() as u64;
        self.candidate.clear();
    }

    /// The candidate is the timeline now: the first one, or a jump (a restart).
    fn confirm(&mut self, released: &mut Vec<(Time, T)>) -> Option<Restart> {
        let candidate = std::mem::take(&mut self.candidate);
        let first = candidate.first().map_or(0, |(t, _)| *t);
        let restart = match (self.newest, self.handed_out) {
            (Some(old), handed_out) => {
                // Mission time goes on after the newest handed out, whatever ROS time did.
                let resume = handed_out.unwrap_or(old + self.offset) + (RESTART_GAP_S * 1e9) as i64;
                self.offset = resume - first;
                self.counts.restarts += 1;
                let jump = (old as f64 / 1e9, first as f64 / 1e9);
                self.counts.last_jump = Some(jump);
                self.counts.offset_ns = self.offset;
                Some(Restart { from_s: jump.0, to_s: jump.1 })
            }
            (None, _) => None,
        };
        let newest = candidate.iter().map(|(t, _)| *t).max().unwrap_or(first);
        self.newest = Some(newest);
        for (t, item) in candidate {
            self.release(t, item, released);
        }
        restart
    }

    /// The input has ended (a bag's last message): what still waits passes if it would
    /// establish the first timeline, and is dropped as outliers otherwise.
    pub fn finish(&mut self) -> Vec<(Time, T)> {
        let mut released = Vec::new();
        if self.newest.is_none() && !self.candidate.is_empty() {
            self.confirm(&mut released);
        } else {
            self.drop_candidate();
        }
        self.counts.waiting = 0;
        released
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(s: f64) -> Time {
        time((s * 1e9).round() as i64)
    }

    fn secs(t: Time) -> f64 {
        nanos(t) as f64 / 1e9
    }

    /// Feeds stamps (s) tagged by their index; returns (index, mission s) released.
    fn feed(timeline: &mut Timeline<usize>, stamps: &[f64]) -> Vec<(usize, f64)> {
        stamps
            .iter()
            .enumerate()
            .flat_map(|(k, s)| timeline.admit(at(*s), k).released)
            .map(|(t, k)| (k, secs(t)))
            .collect()
    }

    fn timeline() -> Timeline<usize> {
        Timeline::new(TimelineConfig { max_jump_s: 0.9, confirm_messages: 3 })
    }

    #[test]
    fn a_steady_stream_passes_unchanged_once_established() {
        let mut tl = timeline();
        let stamps: Vec<f64> = (0..10).map(|k| 1_700_000_000.0 + 0.1 * f64::from(k)).collect();
        let out = feed(&mut tl, &stamps);
        assert_eq!(out.len(), 10);
        for (k, (index, s)) in out.iter().enumerate() {
            assert_eq!(*index, k, "in order");
            assert!((s - stamps[k]).abs() < 1e-6, "ROS time unchanged before any restart");
        }
        assert_eq!(tl.counts, TimelineCounts::default());
    }

    #[test]
    fn one_stamp_years_ahead_before_the_stream_is_an_outlier_not_the_timeline() {
        // The case: one odometry stamped years ahead, then the bag.
        let mut tl = timeline();
        let mut stamps = vec![2_000_000_000.0];
        stamps.extend((0..6).map(|k| 1_700_000_000.0 + 0.1 * f64::from(k)));
        let out = feed(&mut tl, &stamps);
        assert_eq!(out.iter().map(|(k, _)| *k).collect::<Vec<_>>(), vec![1, 2, 3, 4, 5, 6]);
        assert!((out[0].1 - 1_700_000_000.0).abs() < 1e-6);
        assert_eq!((tl.counts.outliers, tl.counts.restarts), (1, 0));
    }

    #[test]
    fn a_glitch_mid_stream_is_dropped_and_the_stream_goes_on() {
        let mut tl = timeline();
        let out = feed(&mut tl, &[100.0, 100.1, 100.2, 5000.0, 100.3, 100.4]);
        assert_eq!(out.iter().map(|(k, _)| *k).collect::<Vec<_>>(), vec![0, 1, 2, 4, 5]);
        assert_eq!((tl.counts.outliers, tl.counts.restarts, tl.counts.waiting), (1, 0, 0));
        // Two glitches in a row that agree with each other but are not enough to confirm.
        let out = feed(&mut tl, &[0.0, 0.1, 100.5]);
        assert_eq!(out.len(), 1);
        assert_eq!(tl.counts.outliers, 3);
    }

    #[test]
    fn a_loop_back_in_time_restarts_the_timeline_and_mission_time_goes_on() {
        // `rosbag play --loop`: the stamps start again from the bag's beginning.
        let mut tl = timeline();
        let first: Vec<f64> = (0..5).map(|k| 1000.0 + 0.5 * f64::from(k)).collect(); // ends at 1002
        let out = feed(&mut tl, &first);
        assert_eq!(out.len(), 5);
        let admitted: Vec<Admitted<usize>> = [1000.0, 1000.3, 1000.6].iter().map(|s| tl.admit(at(*s), 9)).collect();
        assert!(admitted[0].released.is_empty() && admitted[1].released.is_empty());
        let restart = admitted[2].restart.expect("a restart");
        assert_eq!((restart.from_s, restart.to_s), (1002.0, 1000.0));
        let mission: Vec<f64> = admitted[2].released.iter().map(|(t, _)| secs(*t)).collect();
        // 1 s after the newest mission time handed out (1002), spaced as in ROS time.
        for (m, expected) in mission.iter().zip([1003.0, 1003.3, 1003.6]) {
            assert!((m - expected).abs() < 1e-6, "{mission:?}");
        }
        assert_eq!(tl.counts.restarts, 1);
        // Outputs go back to ROS time.
        assert!((secs(tl.to_ros(at(1003.3))) - 1000.3).abs() < 1e-6);
        // Later stamps on the new timeline pass at once.
        let later = tl.admit(at(1000.9), 10);
        assert!((secs(later.released[0].0) - 1003.9).abs() < 1e-6);
    }

    #[test]
    fn a_clock_jump_forward_restarts_too() {
        let mut tl = timeline();
        feed(&mut tl, &[10.0, 10.1, 10.2]);
        let out = feed(&mut tl, &[3610.0, 3610.1, 3610.2, 3610.3]);
        assert_eq!(out.len(), 4);
        assert!((out[0].1 - 11.2).abs() < 1e-6, "{out:?}");
        assert_eq!(tl.counts.restarts, 1);
    }

    #[test]
    fn the_end_of_a_bag_settles_what_waits() {
        let mut tl = timeline();
        feed(&mut tl, &[5.0, 5.1]);
        assert_eq!(tl.finish().len(), 2, "a short bag is still its own timeline");
        let mut tl = timeline();
        feed(&mut tl, &[5.0, 5.1, 5.2, 900.0]);
        assert!(tl.finish().is_empty());
        assert_eq!((tl.counts.outliers, tl.counts.waiting), (1, 0));
    }
}
