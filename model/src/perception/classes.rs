//! The class table (section `[[fusion.classes]]` of a robot configuration): every semantic class the
//! segmenter emits, by id, with a display colour, whether its objects are matchable (the paper
//! matches only selected classes: large objects' centroids move with the viewpoint), and the
//! plausible size range of one object.

use crate::perception::clustering::{ClassLimits, ClusterConfig};
use crate::scene_graph::LabelId;
use serde::{Deserialize, Serialize};

/// One class.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClassSpec {
    pub name: String,
    /// Pixel value in the label image.
    pub id: u16,
    /// RGB for markers and exports.
    #[serde(default = "grey")]
    pub colour: [u8; 3],
    /// Objects of this class are shared and matched. Default false.
    #[serde(default)]
    pub matchable: bool,
    /// Objects of this class are clustered at all (ground, sky, walls: false). Default true.
    #[serde(default = "yes")]
    pub object: bool,
    /// Things of this class move (people, animals): they never become map objects, and Fusion
    /// drops their returns from the scan, so that neither the object layer nor a keyframe's
    /// cloud holds them. Default false (and then not written out).
    #[serde(default, skip_serializing_if = "is_false")]
    pub dynamic: bool,
    #[serde(default = "default_min_points")]
    pub min_points: usize,
    #[serde(default = "default_max_points")]
    pub max_points: usize,
    /// Largest plausible extent of one object, m.
    #[serde(default = "default_max_extent")]
    pub max_extent_m: f64,
}

fn grey() -> [u8; 3] {
    [128, 128, 128]
}
fn yes() -> bool {
    true
}
fn is_false(v: &bool) -> bool {
    !*v
}
fn default_min_points() -> usize {
    10
}
fn default_max_points() -> usize {
    50_000
}
fn default_max_extent() -> f64 {
    10.0
}

/// A validated class table.
#[derive(Clone, Debug, PartialEq, Default, Serialize)]
pub struct ClassTable {
    classes: Vec<ClassSpec>,
}

/// What is wrong with a class table; names the entry.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ClassTableError {
    #[error("classes[{index}] ({name}): id {id} is used twice")]
    DuplicateId { index: usize, name: String, id: u16 },
    #[error("classes[{index}]: name {name:?} is used twice")]
    DuplicateName { index: usize, name: String },
    #[error("classes[{index}] ({name}): {what}")]
    Invalid { index: usize, name: String, what: &'static str },
}

impl ClassTable {
    pub fn new(classes: Vec<ClassSpec>) -> Result<Self, ClassTableError> {
        for (index, c) in classes.iter().enumerate() {
            let invalid = |what| ClassTableError::Invalid { index, name: c.name.clone(), what };
            if c.name.trim().is_empty() {
                return Err(invalid("empty name"));
            }
            if c.min_points == 0 || c.min_points > c.max_points {
                return Err(invalid("min_points must be ≥ 1 and ≤ max_points"));
            }
            if !c.max_extent_m.is_finite() || c.max_extent_m <= 0.0 {
                return Err(invalid("max_extent_m must be finite and > 0"));
            }
            if classes[..index].iter().any(|o| o.id == c.id) {
                return Err(ClassTableError::DuplicateId { index, name: c.name.clone(), id: c.id });
            }
            if classes[..index].iter().any(|o| o.name == c.name) {
                return Err(ClassTableError::DuplicateName { index, name: c.name.clone() });
            }
        }
        Ok(Self { classes })
    }

    pub fn get(&self, label: LabelId) -> Option<&ClassSpec> {
        self.classes.iter().find(|c| c.id == label.0)
    }

    pub fn by_name(&self, name: &str) -> Option<&ClassSpec> {
        self.classes.iter().find(|c| c.name == name)
    }

    pub fn is_matchable(&self, label: LabelId) -> bool {
        self.get(label).is_some_and(|c| c.matchable)
    }

    /// The class of a label-image pixel if it names an object class (others are not clustered;
    /// nor is a dynamic class).
    pub fn object_label(&self, pixel: u16) -> Option<LabelId> {
        self.get(LabelId(pixel)).filter(|c| c.object && !c.dynamic).map(|c| LabelId(c.id))
    }

    /// Whether `label` is a dynamic class (its returns are dropped).
    pub fn is_dynamic(&self, label: LabelId) -> bool {
        self.get(label).is_some_and(|c| c.dynamic)
    }

    /// Clustering limits per class.
    pub fn cluster_config(&self, tolerance_m: f64) -> ClusterConfig {
        ClusterConfig {
            tolerance_m,
            classes: self
                .classes
                .iter()
                .map(|c| {
                    (
                        c.id,
                        ClassLimits {
                            min_points: c.min_points,
                            max_points: c.max_points,
                            max_extent_m: c.max_extent_m,
                        },
                    )
                })
                .collect(),
            ..ClusterConfig::default()
        }
    }

    pub fn classes(&self) -> &[ClassSpec] {
        &self.classes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(name: &str, id: u16) -> ClassSpec {
        ClassSpec {
            name: name.into(),
            id,
            colour: [1, 2, 3],
            matchable: true,
            object: true,
            dynamic: false,
            min_points: 5,
            max_points: 100,
            max_extent_m: 2.0,
        }
    }

    #[test]
    fn validation_names_the_entry() {
        let ok =
            ClassTable::new(vec![spec("chair", 3), ClassSpec { object: false, matchable: false, ..spec("ground", 0) }])
                .unwrap();
        assert!(ok.is_matchable(LabelId(3)) && !ok.is_matchable(LabelId(0)) && !ok.is_matchable(LabelId(9)));
        assert_eq!(ok.object_label(3), Some(LabelId(3)));
        assert_eq!(ok.object_label(0), None);
        let people =
            ClassTable::new(vec![ClassSpec { dynamic: true, matchable: false, ..spec("person", 10) }]).unwrap();
        assert_eq!(people.object_label(10), None, "a dynamic class is never an object");
        assert!(people.is_dynamic(LabelId(10)) && !ok.is_dynamic(LabelId(3)));
        assert_eq!(ok.by_name("chair").map(|c| c.id), Some(3));
        assert_eq!(ok.cluster_config(0.3).classes[&3].max_extent_m, 2.0);
        let err = ClassTable::new(vec![spec("chair", 3), spec("bench", 3)]).unwrap_err();
        assert_eq!(err.to_string(), "classes[1] (bench): id 3 is used twice");
        let err = ClassTable::new(vec![ClassSpec { min_points: 0, ..spec("tree", 4) }]).unwrap_err();
        assert!(err.to_string().starts_with("classes[0] (tree): min_points"));
        assert!(matches!(
            ClassTable::new(vec![spec("a", 1), spec("a", 2)]),
            Err(ClassTableError::DuplicateName { .. })
        ));
    }
}
