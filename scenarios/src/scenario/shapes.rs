//! The built-in shapes of the object classes a scenario's world may name (`[world.objects]`
//! keys): each a few parts relative to the object's ground point. The simulator places them
//! (`sim::shapes::place`); validation checks the names against them.

/// One part of a class shape, relative to the object's ground point (yaw 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Part {
    Box { centre: [f64; 3], half: [f64; 3] },
    Cylinder { radius: f64, z0: f64, z1: f64 },
}

/// Class names with a built-in shape (for error messages).
pub const KNOWN_SHAPES: &str = "one of tree, lamp_post, bench, trash_can, chair, table, bookshelf, car";

const TREE: &[Part] =
    &[Part::Cylinder { radius: 0.25, z0: 0.0, z1: 2.5 }, Part::Cylinder { radius: 1.0, z0: 2.5, z1: 5.0 }];
const LAMP_POST: &[Part] = &[
    Part::Cylinder { radius: 0.1, z0: 0.0, z1: 4.5 },
    Part::Box { centre: [0.2, 0.0, 4.55], half: [0.35, 0.15, 0.1] },
];
const BENCH: &[Part] = &[
    Part::Box { centre: [0.0, 0.0, 0.225], half: [0.8, 0.25, 0.225] },
    Part::Box { centre: [0.0, -0.22, 0.7], half: [0.8, 0.04, 0.25] },
];
const TRASH_CAN: &[Part] = &[Part::Cylinder { radius: 0.3, z0: 0.0, z1: 1.0 }];
const CHAIR: &[Part] = &[
    Part::Box { centre: [0.0, 0.0, 0.225], half: [0.22, 0.22, 0.225] },
    Part::Box { centre: [0.0, -0.2, 0.7], half: [0.22, 0.03, 0.25] },
];
const TABLE: &[Part] = &[
    Part::Box { centre: [0.0, 0.0, 0.72], half: [0.7, 0.45, 0.03] },
    Part::Box { centre: [0.0, 0.0, 0.35], half: [0.08, 0.08, 0.35] },
];
const BOOKSHELF: &[Part] = &[Part::Box { centre: [0.0, 0.0, 1.0], half: [0.5, 0.18, 1.0] }];
const CAR: &[Part] = &[
    Part::Box { centre: [0.0, 0.0, 0.6], half: [2.2, 0.9, 0.4] },
    Part::Box { centre: [-0.3, 0.0, 1.25], half: [1.2, 0.8, 0.25] },
];

/// The built-in shape of a class.
pub fn shape_of(class: &str) -> Option<&'static [Part]> {
    Some(match class {
        "tree" => TREE,
        "lamp_post" => LAMP_POST,
        "bench" => BENCH,
        "trash_can" => TRASH_CAN,
        "chair" => CHAIR,
        "table" => TABLE,
        "bookshelf" => BOOKSHELF,
        "car" => CAR,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_matchable_default_class_has_a_shape() {
        for class in sgm_actors::config::default_classes() {
            if class.matchable {
                assert!(shape_of(&class.name).is_some(), "{}", class.name);
            }
        }
    }
}
