//! Vertex comparison d_v (paper eq. 6), extended. The paper compares labels only (1 if equal,
//! else 0). We multiply in two optional, documented refinements:
//! * label confusion (`LabelSimilarity`): different labels may keep a weaker similarity;
//! * height consistency: when both objects report a size, their vertical extents must agree
//!   within `height_tolerance_m`. Unlike horizontal extents, an object's height barely depends on
//!   the viewpoint, so it rejects chance associations without the paper's concern about
//!   partially observed large objects.

use super::{GraphObject, LabelSimilarity, MatcherConfig};

/// d_v over pairs of objects.
pub struct VertexCompare<'a> {
    pub labels: &'a LabelSimilarity,
    /// `None`: heights are not compared.
    pub height_tolerance_m: Option<f64>,
}

impl<'a> VertexCompare<'a> {
    pub fn new(labels: &'a LabelSimilarity, config: &MatcherConfig) -> Self {
        Self { labels, height_tolerance_m: config.compare_heights.then_some(config.height_tolerance_m) }
    }

    /// d_v(p, q) ∈ [0, 1].
    pub fn similarity(&self, p: &GraphObject, q: &GraphObject) -> f64 {
        if let (Some(tolerance), Some(a), Some(b)) = (self.height_tolerance_m, p.size, q.size) {
            if (a.z - b.z).abs() > tolerance {
                return 0.0;
            }
        }
        self.labels.get(p.label, q.label)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene_graph::{LabelId, ObjectId};
    use nalgebra::{Point3, Vector3};

    fn object(label: u16, height: Option<f64>) -> GraphObject {
        GraphObject {
            id: ObjectId(0),
            label: LabelId(label),
            centroid: Point3::origin(),
            size: height.map(|h| Vector3::new(1.0, 1.0, h)),
        }
    }

    #[test]
    fn heights_gate_labels_when_both_are_known() {
        let labels = LabelSimilarity::uniform(2, 0.3);
        let config = MatcherConfig::default();
        let v = VertexCompare::new(&labels, &config);
        assert_eq!(v.similarity(&object(0, Some(1.0)), &object(0, Some(1.2))), 1.0);
        assert_eq!(v.similarity(&object(0, Some(1.0)), &object(0, Some(2.0))), 0.0);
        assert_eq!(v.similarity(&object(0, Some(1.0)), &object(1, Some(1.1))), 0.3);
        assert_eq!(v.similarity(&object(0, None), &object(0, Some(2.0))), 1.0);
        let off = MatcherConfig { compare_heights: false, ..Default::default() };
        let v = VertexCompare::new(&labels, &off);
        assert_eq!(v.similarity(&object(0, Some(1.0)), &object(0, Some(2.0))), 1.0);
    }
}
