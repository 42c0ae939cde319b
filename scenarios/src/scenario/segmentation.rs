//! `[segmentation]`: how the simulated segmentation network errs beyond `camera.mislabel_rate`
//! and `camera.boundary_noise_px` (`sim::segmenter_errors`), and people walking through the
//! world (`sim::people`). Every effect defaults to off, the segmenter of the first milestone.

use serde::{Deserialize, Serialize};
use sgm_model::perception::classes::ClassSpec;
use std::collections::BTreeMap;

/// The name of the class people are labelled with.
pub const PERSON: &str = "person";

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SegmentationSpec {
    /// Class-confusion matrix: true class name → {reported class name: probability}, each row
    /// summing to 1. Systematic: each object, seen from one of 8 sectors of 45° around it, is
    /// reported as one class drawn once from its row (the same for every frame and robot).
    /// Classes without a row are reported as they are. Default {} (none).
    pub confusion: BTreeMap<String, BTreeMap<String, f64>>,
    /// Labels of a nearer object bleed over farther surfaces within this many pixels of its
    /// edge (where the depth steps by more than 0.5 m), pixels. Default 0.
    pub edge_bleed_px: f64,
    /// Objects whose returns span a smaller image area (bounding box) are missed: no label,
    /// pixels². Default 0.
    pub min_pixels: f64,
    /// Objects farther than this (their nearest return) are missed, m. Default unset (none).
    pub max_range_m: Option<f64>,
    /// Mean number (Poisson) of false positive blobs per label image (per frame in per-point
    /// mode): a disc of a random matchable class painted on the ground or a wall. Default 0.
    pub false_blobs_per_frame: f64,
    /// Radius of a false blob, pixels. Default 10.
    pub false_blob_px: f64,
    /// People walking through the world (moving solids the LiDAR sees, labelled `person`).
    /// Default 0.
    pub people: usize,
    /// Their walking speed, m/s. Default 1.2.
    pub person_speed_mps: f64,
}

impl Default for SegmentationSpec {
    fn default() -> Self {
        Self {
            confusion: BTreeMap::new(),
            edge_bleed_px: 0.0,
            min_pixels: 0.0,
            max_range_m: None,
            false_blobs_per_frame: 0.0,
            false_blob_px: 10.0,
            people: 0,
            person_speed_mps: 1.2,
        }
    }
}

impl SegmentationSpec {
    /// No error model is on (people aside): the frame goes to the camera as the LiDAR saw it.
    pub fn is_exact(&self) -> bool {
        self.confusion.is_empty()
            && self.edge_bleed_px == 0.0
            && self.min_pixels == 0.0
            && self.max_range_m.is_none()
            && self.false_blobs_per_frame == 0.0
    }

    /// With people, the class they are labelled with: `classes`' `person`, or one added
    /// (dynamic, not matchable, the next free id) when the table has none.
    pub fn add_person_class(&self, classes: &mut Vec<ClassSpec>) {
        if self.people == 0 || classes.iter().any(|c| c.name == PERSON) {
            return;
        }
        let id = classes.iter().map(|c| c.id).max().map_or(0, |m| m.saturating_add(1));
        classes.push(ClassSpec {
            name: PERSON.into(),
            id,
            colour: [220, 20, 60],
            matchable: false,
            object: true,
            dynamic: true,
            min_points: 5,
            max_points: 50_000,
            max_extent_m: 2.0,
        });
    }
}
