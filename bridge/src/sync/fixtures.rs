//! Inputs the synchroniser's tests share.

use crate::convert::cloud::Scan;
use nalgebra::Point3;
use sgm_model::perception::projection::{CameraModel, LabelImage};

pub(super) fn scan(n: usize) -> Scan {
    Scan { points: vec![Point3::new(1.0, 0.0, 0.0); n], labels: Some(vec![3; n]), dropped_non_finite: 0, times: None }
}

pub(super) fn camera() -> CameraModel {
    CameraModel { width: 2, height: 2, fx: 1.0, fy: 1.0, cx: 1.0, cy: 1.0, distortion: [0.0; 5] }
}

pub(super) fn image() -> LabelImage {
    LabelImage::new(2, 2, vec![1; 4]).unwrap()
}
