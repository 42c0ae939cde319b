//! What Comms broadcasts to everyone, as plain state: ObjectData when the object layer changed
//! significantly (an object moved more than `significant_move_m`, or objects came or went),
//! when a neighbour needs it again (first heard, or back from silence), or after
//! `object_data_refresh_s` without a broadcast — at most once per `object_data_interval_s`. An
//! unchanged map goes out again under its old revision, which a neighbour holding it ignores.
//! Revisions never repeat, also after a restart without a snapshot: a new one is at least the
//! clock in whole seconds. With the Scan Context baseline, keyframe descriptors instead, at the
//! same pace, in envelopes of at most `limits.max_ids`. Our alignments (`Alignments`) when one
//! is made or moves, when a neighbour needs them again, or after `alignments_refresh_s`, at the
//! same pace.

use crate::config::CommsConfig;
use crate::map_view::MapView;
use nalgebra::Point3;
use sgm_model::geometry::Pose3;
use sgm_model::scene_graph::{ObjectId, RobotId, Stamp};
use sgm_model::wire::messages::{Alignments, KeyframeDescriptors, ObjectData, WireAlignment, WireDescriptor};
use std::collections::BTreeMap;
use std::sync::Arc;

/// The object-data broadcast.
#[derive(Clone, Debug)]
pub struct ObjectBroadcast {
    /// Off when the Matcher associates by descriptors.
    enabled: bool,
    revision: u32,
    /// The map as last shared: its objects are what goes out.
    latest: Option<Arc<MapView>>,
    /// The centroids of the last broadcast, to judge what is significant.
    centroids: BTreeMap<ObjectId, Point3<f64>>,
    change_pending: bool,
    /// Someone needs the current ObjectData again (a new or returning neighbour).
    repeat_pending: bool,
    last: Option<Stamp>,
}

impl Default for ObjectBroadcast {
    fn default() -> Self {
        Self {
            enabled: true,
            revision: 0,
            latest: None,
            centroids: BTreeMap::new(),
            change_pending: false,
            repeat_pending: false,
            last: None,
        }
    }
}

impl ObjectBroadcast {
    pub fn disabled() -> Self {
        Self { enabled: false, ..Self::default() }
    }

    /// Off from now on (everything else kept).
    pub fn disable(&mut self) {
        self.enabled = false;
    }

    /// Continues from a snapshot's revision.
    pub fn with_revision(mut self, revision: u32) -> Self {
        self.revision = revision;
        self
    }

    pub fn revision(&self) -> u32 {
        self.revision
    }

    /// The map as last shared (kept also while disabled).
    pub fn latest(&self) -> Option<&Arc<MapView>> {
        self.latest.as_ref()
    }

    /// The object layer now; whether it changed significantly since the last broadcast.
    pub fn objects(&mut self, map: Arc<MapView>, significant_move_m: f64) {
        let objects = &map.objects;
        let significant = objects
            .objects
            .iter()
            .any(|o| self.centroids.get(&o.id).is_none_or(|c| (c - o.centroid).norm() > significant_move_m))
            || objects.objects.len() != self.centroids.len();
        self.change_pending |= significant;
        self.latest = Some(map);
    }

    /// A neighbour needs the current object data again.
    pub fn repeat(&mut self) {
        self.repeat_pending = true;
    }

    /// The ObjectData to broadcast now, if any is due (see the module documentation).
    pub fn due(&mut self, now: Stamp, config: &CommsConfig) -> Option<ObjectData> {
        let since = self.last.map(|t| now - t);
        let due = since.is_none_or(|s| s >= config.object_data_interval_s);
        let stale = since.is_some_and(|s| s >= config.object_data_refresh_s);
        if !self.enabled || !due || !(self.change_pending || self.repeat_pending || stale) {
            return None;
        }
        let objects = &self.latest.as_ref()?.objects;
        if self.change_pending || self.revision == 0 {
            self.revision = (self.revision + 1).max(now.clamp(0.0, f64::from(u32::MAX)) as u32);
        }
        let data = ObjectData::quantise(
            self.revision,
            config.centroid_resolution_mm,
            objects.objects.iter().map(|o| (o.id, o.label, o.centroid, o.size.unwrap_or_default())),
        );
        self.centroids = objects.objects.iter().map(|o| (o.id, o.centroid)).collect();
        self.change_pending = false;
        self.repeat_pending = false;
        self.last = Some(now);
        Some(data)
    }
}

/// An alignment moves significantly when an object this far from us would move by more than
/// `significant_move_m`: ‖Δt‖ + LEVER_M · |Δθ|.
const LEVER_M: f64 = 10.0;

/// The alignments broadcast: the Matcher's current alignments, sent when one was made, dropped
/// or moved significantly, when a neighbour needs them again, or after `alignments_refresh_s`
/// without a broadcast — at most once per `object_data_interval_s`, never while we hold none.
#[derive(Clone, Debug, Default)]
pub struct AlignmentBroadcast {
    latest: Vec<(RobotId, Pose3)>,
    sent: Vec<(RobotId, Pose3)>,
    repeat_pending: bool,
    last: Option<Stamp>,
}

impl AlignmentBroadcast {
    /// The Matcher's alignments now.
    pub fn alignments(&mut self, latest: Vec<(RobotId, Pose3)>) {
        self.latest = latest;
    }

    /// A neighbour needs our alignments again.
    pub fn repeat(&mut self) {
        self.repeat_pending = true;
    }

    fn moved(&self, significant_move_m: f64) -> bool {
        self.latest.len() != self.sent.len()
            || self.latest.iter().zip(&self.sent).any(|((ra, a), (rb, b))| {
                let turn = a.rotation.angle_to(&b.rotation);
                ra != rb || (a.translation.vector - b.translation.vector).norm() + LEVER_M * turn > significant_move_m
            })
    }

    /// The Alignments to broadcast now, if any is due (see the type's documentation).
    pub fn due(&mut self, now: Stamp, config: &CommsConfig) -> Option<Alignments> {
        let since = self.last.map(|t| now - t);
        let due = since.is_none_or(|s| s >= config.object_data_interval_s);
        let stale = since.is_some_and(|s| s >= config.alignments_refresh_s);
        let wanted = self.repeat_pending || stale || self.moved(config.significant_move_m);
        if self.latest.is_empty() || !due || !wanted {
            return None;
        }
        self.sent = self.latest.clone();
        self.repeat_pending = false;
        self.last = Some(now);
        let alignments = self
            .latest
            .iter()
            .take(config.limits.max_ids)
            .map(|(robot, pose)| WireAlignment { robot: *robot, sender_from_robot: pose.into() })
            .collect();
        Some(Alignments { alignments })
    }
}

/// The keyframe descriptors not yet broadcast (the Scan Context baseline).
#[derive(Clone, Debug, Default)]
pub struct DescriptorBroadcast {
    pending: Vec<WireDescriptor>,
    last: Option<Stamp>,
}

impl DescriptorBroadcast {
    pub fn push(&mut self, descriptor: WireDescriptor) {
        self.pending.push(descriptor);
    }

    /// The envelopes' contents due now: every pending descriptor, in chunks of `max_ids`, at
    /// most once per `object_data_interval_s`.
    pub fn due(&mut self, now: Stamp, config: &CommsConfig) -> Vec<KeyframeDescriptors> {
        let due = self.last.is_none_or(|t| now - t >= config.object_data_interval_s);
        if self.pending.is_empty() || !due {
            return Vec::new();
        }
        self.last = Some(now);
        let pending = std::mem::take(&mut self.pending);
        pending.chunks(config.limits.max_ids.max(1)).map(|c| KeyframeDescriptors { descriptors: c.to_vec() }).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map_view::LocalObjects;
    use sgm_model::matching::GraphObject;
    use sgm_model::scene_graph::LabelId;

    fn objects(xs: &[f64]) -> Arc<MapView> {
        let objects = LocalObjects {
            objects: xs
                .iter()
                .enumerate()
                .map(|(k, x)| GraphObject {
                    id: ObjectId(k as u32),
                    label: LabelId(2),
                    centroid: Point3::new(*x, 0.0, 0.0),
                    size: None,
                })
                .collect(),
            ..LocalObjects::default()
        };
        Arc::new(MapView { objects, ..MapView::default() })
    }

    fn config() -> CommsConfig {
        CommsConfig {
            object_data_interval_s: 2.0,
            object_data_refresh_s: 30.0,
            significant_move_m: 0.5,
            ..CommsConfig::default()
        }
    }

    /// Rate-limited, sent on significant change only, again when a neighbour needs it or after
    /// the refresh, its revision new only when the map changed (and at least the clock).
    #[test]
    fn object_data_goes_out_on_change_repeat_or_refresh() {
        let c = config();
        let mut b = ObjectBroadcast::default();
        assert!(b.due(0.0, &c).is_none(), "nothing to send yet");
        b.objects(objects(&[1.0, 5.0]), c.significant_move_m);
        let first = b.due(100.0, &c).unwrap();
        assert_eq!((first.revision, first.objects.len()), (100, 2));
        b.objects(objects(&[1.2, 5.0]), c.significant_move_m);
        assert!(b.due(103.0, &c).is_none(), "a small move is not significant");
        b.objects(objects(&[1.2, 6.0]), c.significant_move_m);
        assert!(b.due(101.0, &c).is_none(), "rate limit");
        assert_eq!(b.due(103.0, &c).unwrap().revision, 103);
        b.repeat();
        assert_eq!(b.due(105.5, &c).unwrap().revision, 103, "repeated under its revision");
        assert!(b.due(120.0, &c).is_none());
        assert_eq!(b.due(135.5, &c).unwrap().revision, 103, "refreshed");
        assert!(ObjectBroadcast::disabled().due(0.0, &c).is_none());
    }

    #[test]
    fn descriptors_go_out_in_chunks_at_the_same_pace() {
        let mut c = config();
        c.limits.max_ids = 2;
        let mut d = DescriptorBroadcast::default();
        let descriptor = |k| {
            WireDescriptor::quantise(
                sgm_model::scene_graph::KeyframeId(k),
                &sgm_model::geometry::Pose3::identity(),
                &sgm_model::matching::scan_context::ScanContext { rings: 2, sectors: 3, cells: vec![0.5; 6] },
            )
        };
        for k in 0..3 {
            d.push(descriptor(k));
        }
        assert_eq!(d.due(0.0, &c).iter().map(|m| m.descriptors.len()).collect::<Vec<_>>(), [2, 1]);
        d.push(descriptor(3));
        assert!(d.due(1.0, &c).is_empty(), "rate limit");
        assert_eq!(d.due(2.0, &c).len(), 1);
    }

    /// Sent when one is made or moves by more than `significant_move_m` at 10 m (not for less),
    /// rate-limited, again when a neighbour needs them or after `alignments_refresh_s`; never
    /// while there is none.
    #[test]
    fn alignments_go_out_when_made_moved_repeated_or_stale() {
        use nalgebra::Vector3;
        use sgm_model::geometry::pose_from_rpy_translation;
        let c = CommsConfig { alignments_refresh_s: 30.0, ..config() };
        let mut b = AlignmentBroadcast::default();
        b.repeat();
        assert!(b.due(0.0, &c).is_none(), "nothing to send yet");
        let at = |yaw: f64, x: f64| pose_from_rpy_translation(0.0, 0.0, yaw, Vector3::new(x, 0.0, 0.0));
        b.alignments(vec![(RobotId(2), at(0.0, 1.0))]);
        let first = b.due(10.0, &c).unwrap();
        assert_eq!(first.alignments.len(), 1);
        assert_eq!(first.alignments[0].robot, RobotId(2));
        assert_eq!(first.alignments[0].sender_from_robot.to_pose().unwrap(), at(0.0, 1.0));
        // 0.2 m + 10 m × 0.01 rad = 0.3 m: not significant; 0.2 m + 10 m × 0.04 rad is.
        b.alignments(vec![(RobotId(2), at(0.01, 1.2))]);
        assert!(b.due(13.0, &c).is_none());
        b.alignments(vec![(RobotId(2), at(0.04, 1.2))]);
        assert!(b.due(11.0, &c).is_none(), "rate limit");
        assert!(b.due(13.0, &c).is_some());
        b.alignments(vec![(RobotId(2), at(0.04, 1.2)), (RobotId(3), at(0.0, 0.0))]);
        assert_eq!(b.due(15.0, &c).unwrap().alignments.len(), 2, "a new alignment");
        assert!(b.due(20.0, &c).is_none());
        b.repeat();
        assert!(b.due(20.0, &c).is_some(), "a neighbour needs them");
        assert!(b.due(45.0, &c).is_none());
        assert!(b.due(50.0, &c).is_some(), "refreshed");
    }
}
