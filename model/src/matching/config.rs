//! Every parameter of object-graph matching, with its default and unit beside it.

use crate::geometry::RigidModel;
use serde::{Deserialize, Serialize};

/// Matcher parameters (section `[matcher]` of a robot configuration).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MatcherConfig {
    /// μ of d_e = exp(−μ |w_ij − w_mn|) (paper eq. 7), 1/m. Default 1.0.
    pub edge_sharpness: f64,
    /// Edge pairs whose lengths differ by more than this contribute no affinity, m. Default 3.0
    /// (d_e < 0.05 beyond it at the default μ).
    pub edge_tolerance_m: f64,
    /// Object-layer edges longer than this are left out of the affinity (long edges carry the most
    /// drift), m. Default 60.0.
    pub max_edge_length_m: f64,
    /// Each local object's edges in the affinity are limited to its this-many nearest neighbours
    /// (keeps large graphs sparse and the eigenvector informative; the paper's graphs are fully
    /// connected). Default 12.
    pub max_neighbours: usize,
    /// Power-iteration stop: largest change of any eigenvector entry, relative to the largest
    /// entry. Default 1e-5.
    pub power_tolerance: f64,
    /// Power-iteration cap. Default 200.
    pub max_power_iterations: usize,
    /// Minimum eigenvector value of an assignment, relative to the largest entry (the paper's
    /// minimum allowable eigenvector value). Default 0.1.
    pub min_assignment_score: f64,
    /// Candidate associations, best eigenvector entries first, that seed rigid hypotheses.
    /// Default 40.
    pub hypothesis_pool: usize,
    /// Seed pairs sampled along the affinity rows when the pool yields no significant transform
    /// (large graphs). 0 disables the second stage. Default 1024.
    pub hypothesis_samples: usize,
    /// A match is an inlier of a transform when the transformed remote centroid lies within this
    /// horizontal distance of the local one, m. Default 3.0 (the paper's ±1 m error on both
    /// graphs puts true pairs up to 2.8 m apart).
    pub inlier_distance_m: f64,
    /// ... and within this vertical distance, m. Default 1.5.
    pub inlier_height_m: f64,
    /// Largest tilt between the two robots' world frames (roll/pitch drift of an odometry
    /// without IMU), degrees: a planar hypothesis whose vertical residuals show a significant
    /// tilt up to this is refitted in 6-DoF (`matching::tilt`). 0: gravity-aligned frames (an
    /// IMU), the transform stays 4-DoF (x, y, z, yaw). Default 5.
    pub max_tilt_deg: f64,
    /// Largest expected number of false alarms (a-contrario NFA) of an accepted transform.
    /// Default 0.1: the bound is conservative; measured false claims stay near 1% (book,
    /// matching chapter, `sgm bench matching`).
    pub max_false_alarms: f64,
    /// A second, different transform that is itself significant and scores at least this fraction
    /// of the best makes the match ambiguous: refused. Default 0.8.
    pub ambiguity_ratio: f64,
    /// Fewest verified matches of an accepted transform. Default 3 (at least 3, paper §IV-C).
    pub min_matches: usize,
    /// Fewest metres of spread of the matched centroids across their main axis (collinearity
    /// guard). Default 0.5.
    pub min_spread_m: f64,
    /// Similarity of two different labels (0 = hard labels as in the paper; > 0 lets mislabelled
    /// objects count as evidence). Default 0.3.
    pub mislabel_similarity: f64,
    /// Compare objects' heights (vertical extent of `size`) when both report one. Default true.
    pub compare_heights: bool,
    /// Largest height difference of two views of one object, m. Default 0.5.
    pub height_tolerance_m: f64,
    /// Per-pair overrides of label similarity, e.g. chair/sofa 0.6.
    pub label_confusion: Vec<LabelConfusion>,
    /// Rigid model of the final estimate. Default planar (x, y, yaw + z offset, paper §IV-C).
    pub model: RigidModel,
    /// Largest number of objects per graph accepted (bounds memory and time). Default 4096.
    pub max_objects: usize,
}

/// Similarity of one pair of labels, overriding `mislabel_similarity`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LabelConfusion {
    pub a: String,
    pub b: String,
    pub similarity: f64,
}

impl Default for MatcherConfig {
    fn default() -> Self {
        Self {
            edge_sharpness: 1.0,
            edge_tolerance_m: 3.0,
            max_edge_length_m: 60.0,
            max_neighbours: 12,
            power_tolerance: 1e-5,
            max_power_iterations: 200,
            min_assignment_score: 0.1,
            hypothesis_pool: 40,
            hypothesis_samples: 1024,
            inlier_distance_m: 3.0,
            inlier_height_m: 1.5,
            max_tilt_deg: 5.0,
            max_false_alarms: 0.1,
            ambiguity_ratio: 0.8,
            min_matches: 3,
            min_spread_m: 0.5,
            mislabel_similarity: 0.3,
            compare_heights: true,
            height_tolerance_m: 0.5,
            label_confusion: Vec::new(),
            model: RigidModel::Planar,
            max_objects: 4096,
        }
    }
}

/// A configuration value outside its allowed range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("matcher.{key} = {value} is out of range: {allowed}")]
pub struct MatcherConfigError {
    pub key: String,
    pub value: String,
    pub allowed: &'static str,
}

impl MatcherConfig {
    /// Checks every key against its allowed range.
    pub fn validate(&self) -> Result<(), MatcherConfigError> {
        fn check(ok: bool, key: &str, value: impl ToString, allowed: &'static str) -> Result<(), MatcherConfigError> {
            if ok {
                Ok(())
            } else {
                Err(MatcherConfigError { key: key.to_string(), value: value.to_string(), allowed })
            }
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        check(positive(self.edge_sharpness), "edge_sharpness", self.edge_sharpness, "finite and > 0")?;
        check(positive(self.edge_tolerance_m), "edge_tolerance_m", self.edge_tolerance_m, "finite and > 0")?;
        check(self.max_edge_length_m > 0.0, "max_edge_length_m", self.max_edge_length_m, "> 0 (inf allowed)")?;
        check((2..=100_000).contains(&self.max_neighbours), "max_neighbours", self.max_neighbours, "2..=100000")?;
        check(positive(self.power_tolerance), "power_tolerance", self.power_tolerance, "finite and > 0")?;
        check(
            (1..=100_000).contains(&self.max_power_iterations),
            "max_power_iterations",
            self.max_power_iterations,
            "1..=100000",
        )?;
        check(
            (0.0..1.0).contains(&self.min_assignment_score),
            "min_assignment_score",
            self.min_assignment_score,
            "0 <= x < 1",
        )?;
        check((2..=1024).contains(&self.hypothesis_pool), "hypothesis_pool", self.hypothesis_pool, "2..=1024")?;
        check(self.hypothesis_samples <= 1_000_000, "hypothesis_samples", self.hypothesis_samples, "0..=1000000")?;
        check(positive(self.inlier_distance_m), "inlier_distance_m", self.inlier_distance_m, "finite and > 0")?;
        check(positive(self.inlier_height_m), "inlier_height_m", self.inlier_height_m, "finite and > 0")?;
        check((0.0..=30.0).contains(&self.max_tilt_deg), "max_tilt_deg", self.max_tilt_deg, "0 <= x <= 30")?;
        check(positive(self.max_false_alarms), "max_false_alarms", self.max_false_alarms, "finite and > 0")?;
        check(
            self.ambiguity_ratio > 0.0 && self.ambiguity_ratio <= 1.0,
            "ambiguity_ratio",
            self.ambiguity_ratio,
            "0 < x <= 1",
        )?;
        check((3..=1000).contains(&self.min_matches), "min_matches", self.min_matches, "3..=1000")?;
        check(
            self.min_spread_m.is_finite() && self.min_spread_m >= 0.0,
            "min_spread_m",
            self.min_spread_m,
            "finite and >= 0",
        )?;
        check(
            (0.0..1.0).contains(&self.mislabel_similarity),
            "mislabel_similarity",
            self.mislabel_similarity,
            "0 <= x < 1",
        )?;
        check(positive(self.height_tolerance_m), "height_tolerance_m", self.height_tolerance_m, "finite and > 0")?;
        for (k, c) in self.label_confusion.iter().enumerate() {
            check(
                (0.0..=1.0).contains(&c.similarity),
                &format!("label_confusion[{k}].similarity"),
                c.similarity,
                "0 <= x <= 1",
            )?;
        }
        check((3..=1_000_000).contains(&self.max_objects), "max_objects", self.max_objects, "3..=1000000")?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_errors_name_the_key() {
        MatcherConfig::default().validate().unwrap();
        let bad = MatcherConfig { inlier_distance_m: -1.0, ..Default::default() };
        let err = bad.validate().unwrap_err();
        assert_eq!(err.key, "inlier_distance_m");
        assert!(err.to_string().contains("matcher.inlier_distance_m = -1"), "{err}");
        let bad = MatcherConfig { min_matches: 2, ..Default::default() };
        assert_eq!(bad.validate().unwrap_err().key, "min_matches");
        for tilt in [-1.0, 31.0, f64::NAN] {
            let bad = MatcherConfig { max_tilt_deg: tilt, ..Default::default() };
            assert_eq!(bad.validate().unwrap_err().key, "max_tilt_deg", "{tilt}");
        }
        MatcherConfig { max_tilt_deg: 0.0, ..Default::default() }.validate().unwrap();
    }
}
