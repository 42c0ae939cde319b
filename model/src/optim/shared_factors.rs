//! What a robot's pose graph shares with its neighbours (`optimiser.share_factors`): an
//! append-only *factor log* of its own measurements, read by each neighbour in slices from the
//! position it has reached.
//!
//! A neighbour's keyframes held only by their marginals (the ties of
//! [`super::keyframe_graph`]) can move as one rigid block and no more: the marginals are
//! correlated, and a map whose own factors are not in the graph cannot bend to meet ours. With
//! the neighbour's own factors — its odometry and loop closures, and the inter-robot factors
//! it measured to us — each robot solves the pair's whole graph (its own part and the
//! neighbour's chain), as one graph of the team would:
//!
//! ```text
//! X* = argmin Σ_{own factors} ‖r‖² + Σ_{neighbour's factors} ‖r‖² + Σ_{inter-robot, both robots'} ‖r‖²
//! ```
//!
//! The log holds, in the order they entered the graph, each local keyframe and each between
//! factor of our own measurements (odometry, loop closures, inter-robot factors to a
//! neighbour's keyframe). It only grows, so a position in it never changes meaning: a neighbour
//! asks from the position its last slice ended at, and a request or reply lost on the radio is
//! simply asked again. A slice for a receiver carries our keyframes (with their poses now) and
//! our odometry and loop factors, and of the inter-robot factors only those to the receiver's
//! keyframes (it holds no variable for a third robot's). An inter-robot factor of an alignment
//! later withdrawn is struck from the log (its place stays, empty).

use crate::geometry::Pose3;
use crate::scene_graph::{KeyframeEdge, KeyframeEdgeKind, KeyframeId, KeyframeRef, RobotId};
use nalgebra::{Matrix6, Vector3};

/// One entry of the factor log.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum LogEntry {
    /// A local keyframe entered the graph.
    Keyframe(KeyframeId),
    /// A between factor of our own measurements, from a local keyframe.
    Factor(Box<KeyframeEdge>),
    /// An inter-robot factor of an alignment withdrawn since.
    Struck,
}

/// The factor log (see the module's documentation).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FactorLog {
    entries: Vec<LogEntry>,
}

/// What a shared factor measures, as the receiver sees it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SharedKind {
    Odometry,
    Loop,
    /// `to` is one of the receiver's keyframes.
    InterRobot,
}

/// A between factor of the sender's graph: `measured` = from_body_from_to_body, information Ω.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SharedFactor {
    pub kind: SharedKind,
    /// The sender's keyframe.
    pub from: KeyframeId,
    /// The sender's keyframe, or the receiver's for [`SharedKind::InterRobot`].
    pub to: KeyframeId,
    pub measured: Pose3,
    pub information: Matrix6<f64>,
}

/// A sender's keyframe in a slice: its pose in the sender's world now, and the world's up in
/// its body as the sender's odometry measured it (gravity-aligned worlds only).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SharedKeyframe {
    pub keyframe: KeyframeId,
    pub pose: Pose3,
    pub up: Option<Vector3<f64>>,
}

/// Log positions `from..next` for one receiver.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LogSlice {
    pub from: u32,
    pub next: u32,
    pub keyframes: Vec<SharedKeyframe>,
    pub factors: Vec<SharedFactor>,
}

impl LogSlice {
    /// Keyframes and factors: what the wire's limit counts.
    pub fn items(&self) -> usize {
        self.keyframes.len() + self.factors.len()
    }
}

impl FactorLog {
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    pub fn entries(&self) -> &[LogEntry] {
        &self.entries
    }

    pub fn keyframe(&mut self, keyframe: KeyframeId) {
        self.entries.push(LogEntry::Keyframe(keyframe));
    }

    /// Logs `edge` if it is ours to share: local to local, or an inter-robot factor to a
    /// neighbour's keyframe.
    pub fn factor(&mut self, edge: &KeyframeEdge) {
        let shareable = match edge.to {
            KeyframeRef::Local(_) => edge.kind != KeyframeEdgeKind::InterRobot,
            KeyframeRef::Remote { .. } => edge.kind == KeyframeEdgeKind::InterRobot,
        };
        if shareable {
            self.entries.push(LogEntry::Factor(Box::new(edge.clone())));
        }
    }

    /// Strikes our inter-robot factors to `robot` (its alignment was withdrawn); how many.
    pub fn strike(&mut self, robot: RobotId) -> usize {
        let mut struck = 0;
        for entry in &mut self.entries {
            if matches!(entry, LogEntry::Factor(edge) if matches!(edge.to, KeyframeRef::Remote { robot: r, .. } if r == robot))
            {
                *entry = LogEntry::Struck;
                struck += 1;
            }
        }
        struck
    }

    /// The slice for `receiver` from position `from` on, of at most `max_items` keyframes and
    /// factors; `pose_of` gives a local keyframe's pose now and its measured up. A position
    /// beyond the log gives an empty slice that ends where it starts.
    pub fn slice(
        &self,
        receiver: RobotId,
        from: u32,
        max_items: usize,
        pose_of: impl Fn(KeyframeId) -> Option<(Pose3, Option<Vector3<f64>>)>,
    ) -> LogSlice {
        let mut out = LogSlice { from, next: from, ..LogSlice::default() };
        let start = (from as usize).min(self.entries.len());
        for entry in &self.entries[start..] {
            if out.items() >= max_items.max(1) {
                break;
            }
            out.next += 1;
            match entry {
                LogEntry::Keyframe(k) => {
                    if let Some((pose, up)) = pose_of(*k) {
                        out.keyframes.push(SharedKeyframe { keyframe: *k, pose, up });
                    }
                }
                LogEntry::Factor(edge) => {
                    let (kind, to) = match (edge.kind, edge.to) {
                        (KeyframeEdgeKind::Odometry, KeyframeRef::Local(t)) => (SharedKind::Odometry, t),
                        (KeyframeEdgeKind::Loop, KeyframeRef::Local(t)) => (SharedKind::Loop, t),
                        (KeyframeEdgeKind::InterRobot, KeyframeRef::Remote { robot, keyframe })
                            if robot == receiver =>
                        {
                            (SharedKind::InterRobot, keyframe)
                        }
                        _ => continue,
                    };
                    let (measured, information) = (edge.from_from_to, edge.information);
                    out.factors.push(SharedFactor { kind, from: edge.from, to, measured, information });
                }
                LogEntry::Struck => {}
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn edge(kind: KeyframeEdgeKind, from: u32, to: KeyframeRef) -> KeyframeEdge {
        KeyframeEdge {
            kind,
            from: KeyframeId(from),
            to,
            from_from_to: Pose3::translation(1.0, 0.0, 0.0),
            information: Matrix6::identity(),
        }
    }

    fn remote(robot: u16, keyframe: u32) -> KeyframeRef {
        KeyframeRef::Remote { robot: RobotId(robot), keyframe: KeyframeId(keyframe) }
    }

    fn log() -> FactorLog {
        let mut log = FactorLog::default();
        log.keyframe(KeyframeId(0));
        log.keyframe(KeyframeId(1));
        log.factor(&edge(KeyframeEdgeKind::Odometry, 0, KeyframeRef::Local(KeyframeId(1))));
        log.factor(&edge(KeyframeEdgeKind::InterRobot, 1, remote(1, 4)));
        log.factor(&edge(KeyframeEdgeKind::InterRobot, 1, remote(2, 9)));
        log.keyframe(KeyframeId(2));
        log.factor(&edge(KeyframeEdgeKind::Loop, 2, KeyframeRef::Local(KeyframeId(0))));
        // Not ours to share: an edge between a local keyframe and a remote one that is no
        // inter-robot factor.
        log.factor(&edge(KeyframeEdgeKind::Odometry, 2, remote(1, 3)));
        log
    }

    fn pose_of(k: KeyframeId) -> Option<(Pose3, Option<Vector3<f64>>)> {
        Some((Pose3::translation(f64::from(k.0), 0.0, 0.0), None))
    }

    #[test]
    fn a_receiver_gets_our_factors_and_those_to_it_only() {
        let log = log();
        assert_eq!(log.len(), 7);
        let slice = log.slice(RobotId(1), 0, 100, pose_of);
        assert_eq!((slice.from, slice.next), (0, 7));
        assert_eq!(slice.keyframes.iter().map(|k| k.keyframe.0).collect::<Vec<_>>(), vec![0, 1, 2]);
        let kinds: Vec<(SharedKind, u32, u32)> = slice.factors.iter().map(|f| (f.kind, f.from.0, f.to.0)).collect();
        assert_eq!(kinds, vec![(SharedKind::Odometry, 0, 1), (SharedKind::InterRobot, 1, 4), (SharedKind::Loop, 2, 0)]);
        let other = log.slice(RobotId(2), 0, 100, pose_of);
        assert!(other.factors.iter().any(|f| f.kind == SharedKind::InterRobot && f.to.0 == 9));
        assert!(!other.factors.iter().any(|f| f.to.0 == 4));
    }

    #[test]
    fn slices_are_bounded_and_continue_where_they_ended() {
        let log = log();
        let mut from = 0;
        let mut got = Vec::new();
        loop {
            let slice = log.slice(RobotId(1), from, 2, pose_of);
            assert!(slice.items() <= 2);
            if slice.next == from {
                break;
            }
            got.extend(slice.keyframes.iter().map(|k| format!("k{}", k.keyframe.0)));
            got.extend(slice.factors.iter().map(|f| format!("f{}-{}", f.from.0, f.to.0)));
            from = slice.next;
        }
        assert_eq!(got, vec!["k0", "k1", "f0-1", "f1-4", "k2", "f2-0"]);
        let beyond = log.slice(RobotId(1), 1000, 2, pose_of);
        assert_eq!((beyond.next, beyond.items()), (1000, 0));
    }

    #[test]
    fn a_withdrawn_neighbours_factors_are_struck_and_positions_stay() {
        let mut log = log();
        assert_eq!(log.strike(RobotId(1)), 1);
        assert_eq!(log.len(), 7);
        let slice = log.slice(RobotId(1), 0, 100, pose_of);
        assert_eq!(slice.next, 7);
        assert!(!slice.factors.iter().any(|f| f.kind == SharedKind::InterRobot));
        assert_eq!(log.slice(RobotId(2), 0, 100, pose_of).factors.len(), 3);
    }
}
