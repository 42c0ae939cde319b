//! `Fusion` (paper §IV-A): LiDAR points take the class of their pixel in the segmented image
//! (`model::perception::projection`), or keep per-point labels given upstream; the segmenter's
//! pixel values become SGM classes (`[classes]`, `model::perception::label_map`: values it does
//! not know are counted per value, logged once each, and carry no class); a vote among
//! 3D neighbours undoes labels that bled across depth edges (`model::perception::label_vote`);
//! classes that are not objects are cleared; points beyond range are dropped; objects are clustered per class
//! (`model::perception::clustering`). Out: a [`LabelledScan`] to the Tracker.

use crate::config::FusionConfig;
use crate::containment::contained;
use crate::messages::{FrameLabels, LabelledScan, SensorFrame};
use actix::{Actor, Context, Handler, Message, MessageResult, Recipient, Supervised};
use serde::{Deserialize, Serialize};
use sgm_model::perception::classes::ClassTable;
use sgm_model::perception::clustering::{cluster, ClusterConfig};
use sgm_model::perception::label_map::{LabelMap, Mapped, UnknownLabels, NO_CLASS};
use sgm_model::perception::label_vote::{vote, LabelVote};
use sgm_model::perception::projection::label_points;
use sgm_model::scene_graph::LabelId;

pub struct Fusion {
    classes: ClassTable,
    label_map: LabelMap,
    status: FusionStatus,
    clustering: ClusterConfig,
    max_range_m: f64,
    object_range_m: f64,
    label_vote: LabelVote,
    unknown: UnknownLabels,
    tracker: Recipient<LabelledScan>,
}

/// What Fusion has seen since the process started (not part of a snapshot).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct FusionStatus {
    /// `classes.segmenter`.
    pub segmenter: String,
    /// Returns whose pixel value `[classes]` does not know (beyond the segmenter's table and in
    /// no group): they carry no class.
    pub unknown_label_points: u64,
    /// Those returns per pixel value, the first 32 values; the rest in
    /// `unknown_label_other_points`.
    pub unknown_label_ids: std::collections::BTreeMap<u16, u64>,
    pub unknown_label_other_points: u64,
}

/// Fusion's [`FusionStatus`].
#[derive(Message)]
#[rtype(result = "FusionStatus")]
pub struct GetFusionStatus;

impl Fusion {
    /// `classes`: the validated table of `config.classes`; `label_map`: `[classes]` against it.
    pub fn new(
        config: &FusionConfig,
        classes: ClassTable,
        label_map: LabelMap,
        tracker: Recipient<LabelledScan>,
    ) -> Self {
        let mut clustering = classes.cluster_config(config.cluster_tolerance_m);
        clustering.min_height_m = config.min_object_height_m;
        Self {
            classes,
            status: FusionStatus { segmenter: label_map.segmenter().into(), ..FusionStatus::default() },
            label_map,
            unknown: UnknownLabels::default(),
            clustering,
            max_range_m: config.max_range_m,
            object_range_m: config.object_range_m,
            label_vote: config.label_vote.clone(),
            tracker,
        }
    }

    /// Pixel values → SGM classes; values of no class vote as [`NO_CLASS`], unknown ones are
    /// counted and logged once each.
    fn map_labels(&mut self, labels: Vec<Option<LabelId>>) -> Vec<Option<LabelId>> {
        labels
            .into_iter()
            .map(|l| {
                l.map(|LabelId(pixel)| match self.label_map.get(pixel) {
                    Mapped::Class(class) => class,
                    Mapped::Ignored => NO_CLASS,
                    Mapped::Unknown => {
                        if self.unknown.add(pixel) {
                            tracing::warn!(
                                segmenter = self.label_map.segmenter(),
                                "label id {pixel} is in no class of [classes] (segmenter {}); its points are ignored",
                                self.label_map.segmenter()
                            );
                        }
                        NO_CLASS
                    }
                })
            })
            .collect()
    }
}

impl Actor for Fusion {
    type Context = Context<Self>;
}

impl Supervised for Fusion {}

impl Handler<SensorFrame> for Fusion {
    type Result = ();
    fn handle(&mut self, frame: SensorFrame, ctx: &mut Context<Self>) {
        contained(ctx, "fusion", || {
            let labels = match &frame.labels {
                FrameLabels::PerPoint(labels) => labels.clone(),
                FrameLabels::Image { image, camera, camera_from_body } => {
                    match label_points(&frame.points_in_body, camera_from_body, camera, image) {
                        Ok(l) => l,
                        Err(e) => {
                            tracing::warn!(stamp = frame.stamp, "label image unusable: {e}");
                            vec![None; frame.points_in_body.len()]
                        }
                    }
                }
            };
            let labels = self.map_labels(labels);
            let classes = &self.classes;
            let labels =
                vote(&frame.points_in_body, &labels, &self.label_vote, |l| classes.object_label(l.0).is_some());
            let (r2, near) = (self.max_range_m * self.max_range_m, self.object_range_m * self.object_range_m);
            let n = labels.len();
            let (mut points, mut kept, mut clustered) =
                (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
            for (p, l) in frame.points_in_body.iter().zip(labels) {
                let d2 = p.coords.norm_squared();
                if p.coords.iter().all(|v| v.is_finite()) && d2 <= r2 {
                    let label = l.and_then(|LabelId(id)| self.classes.object_label(id));
                    points.push(*p);
                    kept.push(label);
                    // Objects are clustered from returns within the object range only.
                    clustered.push(if d2 <= near { label } else { None });
                }
            }
            let candidates = cluster(&points, &clustered, &self.clustering);
            self.tracker.do_send(LabelledScan {
                stamp: frame.stamp,
                odom_from_body: frame.odom_from_body,
                points_in_body: points,
                labels: kept,
                candidates,
            });
        });
    }
}

impl Handler<GetFusionStatus> for Fusion {
    type Result = MessageResult<GetFusionStatus>;
    fn handle(&mut self, _: GetFusionStatus, _: &mut Context<Self>) -> Self::Result {
        let mut status = self.status.clone();
        status.unknown_label_points = self.unknown.points;
        status.unknown_label_ids = self.unknown.ids.clone();
        status.unknown_label_other_points = self.unknown.other_points;
        MessageResult(status)
    }
}

stops_on_injected_failure!(Fusion => "fusion");
