//! `Fusion` (paper §IV-A): a thin actor over `model::perception::scan_fusion::ScanFusion`.
//! A scan whose points carry their times is first deskewed (`model::perception::deskew`, the
//! twist from the previous frame's odometry pose to this one's, its rotation from the gyro when
//! the frame brings IMU samples that cover the sweep); one without is used as it came
//! and counted. Points take the class of their pixel in the segmented image (`model::perception::projection`),
//! the motion between the image's stamp and the scan's compensated at the same velocity
//! (`model::perception::motion`), or keep per-point labels given upstream; the scan is fused (the segmenter's values mapped to
//! SGM classes, the label vote, ranges, clustering) and goes on as a [`LabelledScan`] to the
//! Tracker. Pixel values `[classes]` does not know are logged once each and counted.

use crate::config::FusionConfig;
use crate::containment::contained;
use crate::messages::{FrameLabels, LabelledScan, SensorFrame};
use actix::{Actor, Context, Handler, Message, MessageResult, Recipient, Supervised};
use serde::{Deserialize, Serialize};
use sgm_model::geometry::lie::Tangent3;
use sgm_model::geometry::Pose3;
use sgm_model::perception::classes::ClassTable;
use sgm_model::perception::deskew::{DeskewCounts, DeskewRefusal, Deskewer};
use sgm_model::perception::imu::{GyroBuffer, GyroCounts};
use sgm_model::perception::label_map::LabelMap;
use sgm_model::perception::motion::{camera_at_offset, ConstantVelocity};
use sgm_model::perception::projection::label_points;
use sgm_model::perception::scan_fusion::{ScanFusion, ScanFusionConfig};

pub struct Fusion {
    fusion: ScanFusion,
    /// The odometry's velocity over the last frame.
    velocity: ConstantVelocity,
    /// `fusion.deskew`: none when off.
    deskewer: Option<Deskewer>,
    /// The IMU's recent gyro samples (the deskew's rotation when they cover a sweep).
    gyro: GyroBuffer,
    images: ImageTiming,
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
    /// Scans deskewed, and those used as they came with the reason (`fusion.deskew`).
    pub deskew: DeskewCounts,
    /// Label images taken at another time than their scan, and how they were used.
    pub images: ImageTiming,
    /// IMU samples kept for the deskew's rotation, and those refused.
    pub imu: GyroCounts,
}

/// Label images whose stamp is not their scan's (the camera fires at its own time).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ImageTiming {
    /// Images whose offset from their scan was compensated at the odometry's velocity.
    pub compensated: u64,
    /// Images with an offset but no velocity known yet (the first frame): used as they came.
    pub uncompensated: u64,
    /// Largest |image stamp − scan stamp| seen, ms (rounded up).
    pub offset_max_ms: u64,
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
        clustering.merge_stacked = config.merge_stacked_objects;
        clustering.far_side_shift = config.far_side_shift;
        let fusion_config = ScanFusionConfig {
            clustering,
            max_range_m: config.max_range_m,
            object_range_m: config.object_range_m,
            label_vote: config.label_vote.clone(),
        };
        let deskewer = config.deskew.then(Deskewer::default);
        Self {
            fusion: ScanFusion::new(classes, label_map, fusion_config),
            velocity: ConstantVelocity::default(),
            deskewer,
            gyro: GyroBuffer::default(),
            images: ImageTiming::default(),
            tracker,
        }
    }
}

impl Fusion {
    /// `frame` with its points deskewed when it carries their times; else as it came (the
    /// first refusal of each kind is logged).
    fn deskewed(&mut self, mut frame: SensorFrame, twist: Option<&Tangent3>) -> SensorFrame {
        let Some(deskewer) = self.deskewer.as_mut() else { return frame };
        if frame.points_deskewed {
            deskewer.count_upstream();
            return frame;
        }
        let before = deskewer.counts();
        let points = std::mem::take(&mut frame.points_in_body);
        let gyro = (self.gyro.counts().kept > 0).then_some((&self.gyro, frame.stamp));
        let (points, outcome) = deskewer.apply(twist, gyro, points, frame.point_times.as_deref());
        frame.points_in_body = points;
        if let Err(refusal) = outcome {
            let first = match refusal {
                DeskewRefusal::NoTimes => before.no_times == 0,
                DeskewRefusal::NoMotion => before.no_motion == 0,
                DeskewRefusal::TimesMismatch { .. } | DeskewRefusal::TimeOutOfRange => before.refused == 0,
            };
            if first && refusal != DeskewRefusal::NoMotion {
                tracing::info!(stamp = frame.stamp, "scan not deskewed: {refusal}");
            }
        }
        if before.imu_not_covering == 0 && deskewer.counts().imu_not_covering == 1 {
            tracing::warn!(
                stamp = frame.stamp,
                "the IMU's samples do not cover this sweep (a gap, or samples late): deskewed with the odometry's \
                 twist; the fusion status counts each (deskew.imu_not_covering)"
            );
        }
        frame
    }

    /// The camera from the body at the scan's stamp: the mount, moved by the body's motion
    /// over `offset_s` when the image was taken at another time and the velocity is known.
    fn camera_for_scan(&mut self, camera_from_body: &Pose3, offset_s: f64, twist: Option<&Tangent3>) -> Pose3 {
        if offset_s == 0.0 {
            return *camera_from_body;
        }
        if !offset_s.is_finite() {
            if self.images.uncompensated == 0 {
                tracing::warn!("a label image's offset from its scan is {offset_s}: used as if taken with the scan");
            }
            self.images.uncompensated += 1;
            return *camera_from_body;
        }
        let offset_ms = (offset_s.abs() * 1000.0).ceil() as u64;
        self.images.offset_max_ms = self.images.offset_max_ms.max(offset_ms);
        match twist {
            Some(twist) => {
                self.images.compensated += 1;
                camera_at_offset(camera_from_body, twist, offset_s)
            }
            None => {
                self.images.uncompensated += 1;
                *camera_from_body
            }
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
            let twist = self.velocity.update(frame.stamp, &frame.odom_from_body);
            let refused_before = self.gyro.counts();
            self.gyro.extend(&frame.imu);
            let refused = self.gyro.counts();
            if refused_before.invalid == 0 && refused.invalid > 0 {
                tracing::warn!(
                    stamp = frame.stamp,
                    "IMU samples refused: a non-finite or saturated rate (fusion status imu.invalid)"
                );
            }
            if refused_before.out_of_order == 0 && refused.out_of_order > 0 {
                tracing::warn!(
                    stamp = frame.stamp,
                    "IMU samples refused: not after the newest kept (fusion status imu.out_of_order)"
                );
            }
            let frame = self.deskewed(frame, twist.as_ref());
            let labels = match &frame.labels {
                FrameLabels::PerPoint(labels) => labels.clone(),
                FrameLabels::Unlabelled => vec![None; frame.points_in_body.len()],
                FrameLabels::Image { image, camera, camera_from_body, image_offset_s } => {
                    let camera_from_body = self.camera_for_scan(camera_from_body, *image_offset_s, twist.as_ref());
                    match label_points(&frame.points_in_body, &camera_from_body, camera, image) {
                        Ok(l) => l,
                        Err(e) => {
                            tracing::warn!(stamp = frame.stamp, "label image unusable: {e}");
                            vec![None; frame.points_in_body.len()]
                        }
                    }
                }
            };
            let fused = self.fusion.fuse(&frame.points_in_body, labels, &frame.odom_from_body.rotation);
            for pixel in &fused.new_unknown_ids {
                let segmenter = self.fusion.segmenter();
                tracing::warn!(
                    segmenter,
                    "label id {pixel} is in no class of [classes] (segmenter {segmenter}); its points are ignored"
                );
            }
            self.tracker.do_send(LabelledScan {
                stamp: frame.stamp,
                odom_from_body: frame.odom_from_body,
                points_in_body: fused.points_in_body,
                labels: fused.labels,
                candidates: fused.candidates,
                motion_covariance: frame.motion_covariance,
                measured_up: frame.measured_up,
            });
        });
    }
}

impl Handler<GetFusionStatus> for Fusion {
    type Result = MessageResult<GetFusionStatus>;
    fn handle(&mut self, _: GetFusionStatus, _: &mut Context<Self>) -> Self::Result {
        let unknown = self.fusion.unknown();
        MessageResult(FusionStatus {
            segmenter: self.fusion.segmenter().into(),
            unknown_label_points: unknown.points,
            unknown_label_ids: unknown.ids.clone(),
            unknown_label_other_points: unknown.other_points,
            deskew: self.deskewer.as_ref().map(Deskewer::counts).unwrap_or_default(),
            images: self.images,
            imu: self.gyro.counts(),
        })
    }
}

stops_on_injected_failure!(Fusion => "fusion");
