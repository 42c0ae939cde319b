//! The object graph one robot shares (paper §IV-B): object id, label and centroid, optionally
//! size. Edges (centroid distances) are implied. Construction validates: ids unique, coordinates
//! finite, size bounded.

use crate::scene_graph::{LabelId, ObjectId, SceneGraph};
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

/// One vertex of an object graph: φ(v_i) = (p_i, l_i).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GraphObject {
    pub id: ObjectId,
    pub label: LabelId,
    /// Centroid in the owning robot's world frame.
    pub centroid: Point3<f64>,
    pub size: Option<Vector3<f64>>,
}

/// A validated object graph.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ObjectGraph {
    objects: Vec<GraphObject>,
}

/// Why a set of objects is not a valid object graph.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GraphError {
    #[error("object id {0} appears more than once")]
    DuplicateId(u32),
    #[error("object {id}: {field} is not finite")]
    NonFinite { id: u32, field: &'static str },
    #[error("object {id}: size has a negative extent")]
    NegativeSize { id: u32 },
    #[error("{count} objects exceed the limit of {limit}")]
    TooManyObjects { count: usize, limit: usize },
}

impl ObjectGraph {
    /// Validates and builds a graph. Objects keep their given order.
    pub fn new(objects: Vec<GraphObject>, max_objects: usize) -> Result<Self, GraphError> {
        if objects.len() > max_objects {
            return Err(GraphError::TooManyObjects { count: objects.len(), limit: max_objects });
        }
        let mut ids: Vec<u32> = objects.iter().map(|o| o.id.0).collect();
        ids.sort_unstable();
        if let Some(w) = ids.windows(2).find(|w| w[0] == w[1]) {
            return Err(GraphError::DuplicateId(w[0]));
        }
        for o in &objects {
            if o.centroid.coords.iter().any(|v| !v.is_finite()) {
                return Err(GraphError::NonFinite { id: o.id.0, field: "centroid" });
            }
            if let Some(size) = &o.size {
                if size.iter().any(|v| !v.is_finite()) {
                    return Err(GraphError::NonFinite { id: o.id.0, field: "size" });
                }
                if size.iter().any(|v| *v < 0.0) {
                    return Err(GraphError::NegativeSize { id: o.id.0 });
                }
            }
        }
        Ok(Self { objects })
    }

    /// The object layer of a scene graph at the keyframes' current poses (objects whose label is
    /// accepted by `matchable`: the paper matches only selected classes).
    pub fn from_scene_graph(graph: &SceneGraph, matchable: impl Fn(LabelId) -> bool) -> Self {
        let objects = graph
            .objects()
            .filter(|o| matchable(o.label))
            .filter_map(|o| {
                graph.centroid_in_world(o.id).map(|centroid| GraphObject {
                    id: o.id,
                    label: o.label,
                    centroid,
                    size: Some(o.size),
                })
            })
            .collect();
        // A scene graph already guarantees unique ids and finite positions.
        Self { objects }
    }

    pub fn objects(&self) -> &[GraphObject] {
        &self.objects
    }

    pub fn len(&self) -> usize {
        self.objects.len()
    }

    pub fn is_empty(&self) -> bool {
        self.objects.is_empty()
    }
}

/// A graph of one label from horizontal points at height 0, ids in order (for tests).
#[cfg(test)]
pub(crate) fn flat_graph(points: &[(f64, f64)]) -> ObjectGraph {
    let objects = points
        .iter()
        .enumerate()
        .map(|(k, &(x, y))| GraphObject {
            id: ObjectId(k as u32),
            label: LabelId(0),
            centroid: Point3::new(x, y, 0.0),
            size: None,
        })
        .collect();
    ObjectGraph { objects }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obj(id: u32, x: f64) -> GraphObject {
        GraphObject { id: ObjectId(id), label: LabelId(0), centroid: Point3::new(x, 0.0, 0.0), size: None }
    }

    #[test]
    fn validation() {
        assert!(ObjectGraph::new(vec![obj(1, 0.0), obj(2, 1.0)], 10).is_ok());
        assert_eq!(ObjectGraph::new(vec![obj(1, 0.0), obj(1, 1.0)], 10), Err(GraphError::DuplicateId(1)));
        assert_eq!(
            ObjectGraph::new(vec![obj(4, f64::INFINITY)], 10),
            Err(GraphError::NonFinite { id: 4, field: "centroid" })
        );
        let mut s = obj(5, 0.0);
        s.size = Some(Vector3::new(1.0, -1.0, 1.0));
        assert_eq!(ObjectGraph::new(vec![s], 10), Err(GraphError::NegativeSize { id: 5 }));
        assert!(matches!(ObjectGraph::new(vec![obj(1, 0.0), obj(2, 0.0)], 1), Err(GraphError::TooManyObjects { .. })));
    }
}
