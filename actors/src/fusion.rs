//! `Fusion` (paper §IV-A): LiDAR points take the class of their pixel in the segmented image
//! (`model::perception::projection`), or keep per-point labels given upstream; a vote among
//! 3D neighbours undoes labels that bled across depth edges (`model::perception::label_vote`);
//! classes that are not objects are cleared; points beyond range are dropped; objects are clustered per class
//! (`model::perception::clustering`). Out: a [`LabelledScan`] to the Tracker.

use crate::config::FusionConfig;
use crate::containment::contained;
use crate::messages::{FrameLabels, LabelledScan, SensorFrame};
use actix::{Actor, Context, Handler, Recipient, Supervised};
use sgm_model::perception::classes::ClassTable;
use sgm_model::perception::clustering::{cluster, ClusterConfig};
use sgm_model::perception::label_vote::{vote, LabelVote};
use sgm_model::perception::projection::label_points;
use sgm_model::scene_graph::LabelId;

pub struct Fusion {
    classes: ClassTable,
    clustering: ClusterConfig,
    max_range_m: f64,
    object_range_m: f64,
    label_vote: LabelVote,
    tracker: Recipient<LabelledScan>,
}

impl Fusion {
    /// `classes`: the validated table of `config.classes`.
    pub fn new(config: &FusionConfig, classes: ClassTable, tracker: Recipient<LabelledScan>) -> Self {
        let mut clustering = classes.cluster_config(config.cluster_tolerance_m);
        clustering.min_height_m = config.min_object_height_m;
        Self {
            classes,
            clustering,
            max_range_m: config.max_range_m,
            object_range_m: config.object_range_m,
            label_vote: config.label_vote.clone(),
            tracker,
        }
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
                world_from_body: frame.world_from_body,
                points_in_body: points,
                labels: kept,
                candidates,
            });
        });
    }
}

stops_on_injected_failure!(Fusion => "fusion");
