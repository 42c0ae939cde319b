//! `[fusion]` and `[tracker]`: how scans become labelled objects and keyframes, and the
//! built-in class table.

use super::error::{check, non_negative, positive, ConfigError};
use serde::{Deserialize, Serialize};
use sgm_model::perception::classes::ClassSpec;
use sgm_model::perception::keyframes::KeyframeConfig;
use sgm_model::perception::label_vote::LabelVote;
use sgm_model::perception::loop_closure::LoopClosureConfig;
use sgm_model::perception::tracker::TrackerConfig;
use sgm_model::scene_graph::CloudStoreConfig;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FusionConfig {
    /// Points of one class closer than this join one cluster, m. Default 0.3.
    pub cluster_tolerance_m: f64,
    /// LiDAR returns farther than this are ignored, m. Default 60.
    pub max_range_m: f64,
    /// Objects are clustered from labelled returns within this range only (farther ones keep
    /// their labels in the keyframe cloud): distant objects are seen by too few, too sparse
    /// returns for a trustworthy centroid, m. Default 30.
    pub object_range_m: f64,
    /// Clusters flatter than this are not objects: labels that bled onto the ground behind an
    /// object in the image, m. Default 0.2.
    pub min_object_height_m: f64,
    /// Clusters of one class stacked in one column (a lamp post cut in two by a gap between
    /// beams, a bookshelf by an occluder) are one object candidate
    /// (`model::perception::clustering`). Default true.
    pub merge_stacked_objects: bool,
    /// A cluster's returns lie on its visible side; its centroid is moved away from the sensor
    /// by this times half its width across the line of sight, and its box made symmetric about
    /// the moved centre (`model::perception::clustering`, module doc, "The far side"). 0: off (the mean of
    /// the returns, the paper's centroid). Default 2/π (a round object's visible half).
    pub far_side_shift: f64,
    /// Each labelled return takes the most common class among its neighbours first: labels
    /// that bled across depth edges in the image go back to what surrounds them in 3D
    /// (`model::perception::label_vote`).
    pub label_vote: LabelVote,
    /// The class table. Default: [`default_classes`].
    pub classes: Vec<ClassSpec>,
    /// Deskew scans whose points carry their times (constant velocity from the previous
    /// frame's odometry pose, `model::perception::deskew`). Default true.
    pub deskew: bool,
}

impl Default for FusionConfig {
    fn default() -> Self {
        Self {
            cluster_tolerance_m: 0.3,
            max_range_m: 60.0,
            object_range_m: 30.0,
            min_object_height_m: 0.2,
            merge_stacked_objects: true,
            far_side_shift: std::f64::consts::FRAC_2_PI,
            label_vote: LabelVote::default(),
            classes: default_classes(),
            deskew: true,
        }
    }
}

impl FusionConfig {
    /// Checks every `fusion.*` key against its allowed range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let f = self;
        check(positive(f.cluster_tolerance_m), "fusion.cluster_tolerance_m", f.cluster_tolerance_m, "finite and > 0")?;
        check(positive(f.max_range_m), "fusion.max_range_m", f.max_range_m, "finite and > 0")?;
        check(positive(f.object_range_m), "fusion.object_range_m", f.object_range_m, "finite and > 0")?;
        check(
            non_negative(f.min_object_height_m),
            "fusion.min_object_height_m",
            f.min_object_height_m,
            "finite and ≥ 0",
        )?;
        check(
            non_negative(f.far_side_shift) && f.far_side_shift <= 1.0,
            "fusion.far_side_shift",
            f.far_side_shift,
            "in [0, 1] (0: off)",
        )?;
        check(non_negative(f.label_vote.voxel_m), "fusion.label_vote.voxel_m", f.label_vote.voxel_m, "finite and ≥ 0")?;
        Ok(())
    }
}

/// The built-in class table: the outdoor and indoor objects of the paper's experiments.
pub fn default_classes() -> Vec<ClassSpec> {
    let class = |name: &str, id: u16, colour: [u8; 3], matchable: bool, object: bool, max_extent_m: f64| ClassSpec {
        name: name.into(),
        id,
        colour,
        matchable,
        object,
        dynamic: false,
        min_points: 5,
        max_points: 50_000,
        max_extent_m,
    };
    vec![
        class("ground", 0, [120, 120, 120], false, false, 1e3),
        class("wall", 1, [200, 200, 200], false, false, 1e3),
        class("tree", 2, [30, 140, 40], true, true, 8.0),
        class("lamp_post", 3, [250, 220, 60], true, true, 6.0),
        class("bench", 4, [150, 90, 40], true, true, 3.0),
        class("trash_can", 5, [60, 60, 200], true, true, 1.5),
        class("chair", 6, [220, 80, 80], true, true, 1.5),
        class("table", 7, [180, 130, 70], true, true, 3.0),
        class("bookshelf", 8, [120, 60, 160], true, true, 3.0),
        class("car", 9, [40, 160, 200], false, true, 6.0),
    ]
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackerSection {
    pub keyframes: KeyframeConfig,
    pub tracking: TrackerConfig,
    pub loop_closure: LoopClosureConfig,
    /// How much of the semantic layer the map holds (old scans compacted, then evicted).
    pub cloud_store: CloudStoreConfig,
}

impl TrackerSection {
    /// Checks every `tracker.*` key against its allowed range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let k = &self.keyframes;
        check(positive(k.min_translation_m), "tracker.keyframes.min_translation_m", k.min_translation_m, "> 0")?;
        check(positive(k.min_rotation_rad), "tracker.keyframes.min_rotation_rad", k.min_rotation_rad, "> 0")?;
        let t = &self.tracking;
        check(
            positive(t.max_track_distance_m),
            "tracker.tracking.max_track_distance_m",
            t.max_track_distance_m,
            "> 0",
        )?;
        check(positive(t.search_radius_m), "tracker.tracking.search_radius_m", t.search_radius_m, "> 0")?;
        check(t.confirm_after >= 1, "tracker.tracking.confirm_after", t.confirm_after, "≥ 1")?;
        check(non_negative(t.moving_m), "tracker.tracking.moving_m", t.moving_m, "finite and ≥ 0 (0: off)")?;
        check(positive(t.moving_window_s), "tracker.tracking.moving_window_s", t.moving_window_s, "> 0")?;
        check(
            non_negative(t.max_stack_gap_m),
            "tracker.tracking.max_stack_gap_m",
            t.max_stack_gap_m,
            "finite and ≥ 0",
        )?;
        check(
            t.sighting_memory >= 1,
            "tracker.tracking.sighting_memory",
            t.sighting_memory,
            "≥ 1 (1: the latest sighting alone)",
        )?;
        check(
            non_negative(t.glimpse_spacing_m),
            "tracker.tracking.glimpse_spacing_m",
            t.glimpse_spacing_m,
            "finite and ≥ 0 (0: only keyframes count)",
        )?;
        check(
            non_negative(t.tentative_expiry_s),
            "tracker.tracking.tentative_expiry_s",
            t.tentative_expiry_s,
            "finite and ≥ 0 (0: never)",
        )?;
        let l = &self.loop_closure;
        check(positive(l.search_radius_m), "tracker.loop_closure.search_radius_m", l.search_radius_m, "> 0")?;
        check(non_negative(l.time_gap_s), "tracker.loop_closure.time_gap_s", l.time_gap_s, "finite and ≥ 0")?;
        check(positive(l.max_rmse_m), "tracker.loop_closure.max_rmse_m", l.max_rmse_m, "> 0")?;
        check(
            non_negative(l.min_interval_s),
            "tracker.loop_closure.min_interval_s",
            l.min_interval_s,
            "finite and ≥ 0",
        )?;
        let c = &self.cloud_store;
        for (key, v) in [
            ("tracker.cloud_store.budget_mb", c.budget_mb),
            ("tracker.cloud_store.redundant_within_m", c.redundant_within_m),
        ] {
            check(non_negative(v), key, v, "finite and ≥ 0")?;
        }
        for (key, v) in [
            ("tracker.cloud_store.object_voxel_m", c.object_voxel_m),
            ("tracker.cloud_store.structure_voxel_m", c.structure_voxel_m),
        ] {
            check(positive(v), key, v, "finite and > 0")?;
        }
        Ok(())
    }
}
