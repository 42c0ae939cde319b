//! From a segmenter's pixel values to SGM classes (section `[classes]` of a robot
//! configuration). SGM's class ids are those of `fusion.classes`: the team-wide wire label, the
//! same on every robot. A real segmenter numbers its own classes (ADE20K: 0 = wall, 1 =
//! building, …); this map translates, many to one:
//!
//! ```text
//! class(pixel) = c      if pixel ∈ group(c) for the SGM class c (one group at most)
//!              = none   if pixel is an ignore value of the segmenter (255, NO_LABEL)
//!                       or a class of its table that no group takes (ADE's sky, person)
//!              = unknown otherwise (beyond the table): counted and logged by Fusion
//! ```
//!
//! `group(c)` is the segmenter's shipped default group of `c`
//! ([`crate::perception::segmenters`]) unless `[classes.map]` has an entry for `c`, which then
//! replaces it. Segmenter `identity` (the default) is today's convention: the pixel value *is*
//! the `fusion.classes` id, each class's group is its own id, names in `[classes.map]` are
//! `fusion.classes` names. Colour label images (rgb8) are read back to pixel values through the
//! segmenter's palette ([`crate::perception::colour_ids`], `[classes.palette]`).

use crate::perception::classes::ClassTable;
use crate::perception::segmenters::{segmenter, Segmenter, NO_LABEL, SEGMENTERS};
use crate::scene_graph::LabelId;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The identity segmenter's name (the default).
pub const IDENTITY: &str = "identity";

/// The label Fusion gives a return that falls inside the image on a pixel of no SGM class
/// ([`Mapped::Ignored`], [`Mapped::Unknown`]): it takes part in the label vote as one class of
/// its own, as the simulator's background pixels ([`NO_LABEL`]) always did, and is never an
/// object.
pub const NO_CLASS: LabelId = LabelId(NO_LABEL);

/// How many distinct unknown pixel values [`UnknownLabels`] counts one by one.
pub const MAX_UNKNOWN_IDS: usize = 32;

/// Points whose pixel value was [`Mapped::Unknown`], per value: the first [`MAX_UNKNOWN_IDS`]
/// values one by one, the points of any further value summed in `other_points`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct UnknownLabels {
    /// All points of unknown pixel values.
    pub points: u64,
    /// Points per unknown pixel value, the first [`MAX_UNKNOWN_IDS`] values seen.
    pub ids: BTreeMap<u16, u64>,
    /// Points of the values seen after those.
    pub other_points: u64,
    /// Every value ever seen, one bit each (65 536 bits), so that each is reported once.
    #[serde(skip)]
    seen: Vec<u64>,
}

impl UnknownLabels {
    /// Counts one point of pixel value `id`; true the first time `id` is seen.
    pub fn add(&mut self, id: u16) -> bool {
        self.points += 1;
        if let Some(n) = self.ids.get_mut(&id) {
            *n += 1;
            return false;
        }
        if self.seen.is_empty() {
            self.seen = vec![0; 1 << 10];
        }
        let (word, bit) = (usize::from(id) / 64, 1u64 << (id % 64));
        let first = self.seen.get(word).is_some_and(|w| w & bit == 0);
        if let Some(w) = self.seen.get_mut(word) {
            *w |= bit;
        }
        if first && self.ids.len() < MAX_UNKNOWN_IDS {
            self.ids.insert(id, 1);
        } else {
            self.other_points += 1;
        }
        first
    }
}

/// `[classes]`: which segmenter labels the images, and groups that replace its defaults.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LabelMapSpec {
    /// `identity` (default: pixel value = `fusion.classes` id), `ade20k_150`, `coco_panoptic`
    /// or `cityscapes`.
    pub segmenter: String,
    /// SGM class name (of `fusion.classes`) ← segmenter class names or raw pixel values. An
    /// entry replaces the shipped default group of that class; `[]` maps nothing to it. Default
    /// empty (the shipped groups).
    pub map: BTreeMap<String, Vec<SegmenterClass>>,
    /// Colour label images: `"#rrggbb"` ← the segmenter class (name or pixel value) it paints,
    /// beside (or instead of) the segmenter's shipped palette (`fusion.classes` colours for
    /// `identity`). Default empty.
    pub palette: BTreeMap<String, SegmenterClass>,
}

impl Default for LabelMapSpec {
    fn default() -> Self {
        Self { segmenter: IDENTITY.into(), map: BTreeMap::new(), palette: BTreeMap::new() }
    }
}

/// One member of a group: a raw pixel value or a class name of the segmenter's table.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum SegmenterClass {
    Id(u16),
    Name(String),
}

impl std::fmt::Display for SegmenterClass {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Id(id) => write!(f, "{id}"),
            Self::Name(name) => write!(f, "{name:?}"),
        }
    }
}

/// What one pixel value means.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mapped {
    /// An SGM class (`fusion.classes` id).
    Class(LabelId),
    /// No class: an ignore value, or a segmenter class no group takes.
    Ignored,
    /// Beyond the segmenter's table and in no group.
    Unknown,
}

/// What is wrong with `[classes]`; names the key.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LabelMapError {
    #[error("classes.segmenter: unknown segmenter {name:?}; known: {known}")]
    UnknownSegmenter { name: String, known: String },
    #[error("classes.map.{class}: no class {class:?} in fusion.classes ({known})")]
    UnknownClass { class: String, known: String },
    #[error("classes.map.{class}: segmenter {segmenter} has no class {name:?}")]
    UnknownSegmenterClass { class: String, segmenter: String, name: String },
    #[error("classes.map.{class}: id {id} is mapped twice (already to {first}{origin})")]
    IdTwice { class: String, id: u16, first: String, origin: &'static str },
    #[error("classes.map.{class}: id {id} is beyond segmenter {segmenter}'s ids 0–{max}")]
    IdOutOfRange { class: String, id: u16, segmenter: String, max: u16 },
}

/// A validated `[classes]`: a dense lookup by pixel value.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelMap {
    segmenter: String,
    /// `lookup[pixel]`; pixels beyond are [`Mapped::Unknown`].
    lookup: Vec<Mapped>,
}

impl LabelMap {
    /// Builds the lookup of `spec` against the validated class table.
    pub fn new(spec: &LabelMapSpec, classes: &ClassTable) -> Result<Self, LabelMapError> {
        let table = match spec.segmenter.as_str() {
            IDENTITY => None,
            name => Some(segmenter(name).ok_or_else(|| LabelMapError::UnknownSegmenter {
                name: name.into(),
                known:
                    std::iter::once(IDENTITY).chain(SEGMENTERS.iter().map(|s| s.name)).collect::<Vec<_>>().join(", "),
            })?),
        };
        for class in spec.map.keys() {
            if classes.by_name(class).is_none() {
                let known = classes.classes().iter().map(|c| c.name.as_str()).collect::<Vec<_>>().join(", ");
                return Err(LabelMapError::UnknownClass { class: class.clone(), known });
            }
        }
        // Groups as pixel values: the shipped defaults not replaced, then `[classes.map]`'s
        // entries, so that a clash with a default is reported on the configured entry.
        let mut groups: Vec<(&str, Vec<u16>, bool)> = Vec::new();
        match table {
            None => {
                for c in classes.classes() {
                    if !spec.map.contains_key(&c.name) {
                        groups.push((&c.name, vec![c.id], false));
                    }
                }
            }
            Some(t) => {
                for (class, names) in t.default_groups {
                    if classes.by_name(class).is_some() && !spec.map.contains_key(*class) {
                        groups.push((class, names.iter().filter_map(|n| t.id(n)).collect(), false));
                    }
                }
            }
        }
        for (class, members) in &spec.map {
            let ids = members.iter().map(|m| resolve(class, m, table, classes)).collect::<Result<Vec<_>, _>>()?;
            groups.push((class, ids, true));
        }
        let mut owner: BTreeMap<u16, (&str, bool)> = BTreeMap::new();
        for (class, ids, configured) in &groups {
            for &id in ids {
                if let Some((first, first_configured)) = owner.get(&id) {
                    let origin =
                        if *first_configured { "" } else { "'s shipped default group; replace it in classes.map" };
                    return Err(LabelMapError::IdTwice {
                        class: class.to_string(),
                        id,
                        first: first.to_string(),
                        origin,
                    });
                }
                owner.insert(id, (class, *configured));
            }
        }
        let len = match table {
            Some(t) => t.classes.len(),
            None => 0,
        }
        .max(owner.keys().next_back().map_or(0, |&id| usize::from(id) + 1));
        let mut lookup = vec![if table.is_some() { Mapped::Ignored } else { Mapped::Unknown }; len];
        if let Some(t) = table {
            for &id in t.ignore {
                if let Some(slot) = lookup.get_mut(usize::from(id)) {
                    *slot = Mapped::Ignored;
                }
            }
        }
        for (id, (class, _)) in &owner {
            if let (Some(slot), Some(c)) = (lookup.get_mut(usize::from(*id)), classes.by_name(class)) {
                *slot = Mapped::Class(LabelId(c.id));
            }
        }
        Ok(Self { segmenter: spec.segmenter.clone(), lookup })
    }

    /// Today's convention: pixel value = `fusion.classes` id.
    pub fn identity(classes: &ClassTable) -> Self {
        match Self::new(&LabelMapSpec::default(), classes) {
            Ok(map) => map,
            // A validated table has unique ids: the identity groups cannot clash.
            Err(_) => Self { segmenter: IDENTITY.into(), lookup: Vec::new() },
        }
    }

    /// What a pixel value means. [`NO_LABEL`] and the segmenter's ignore values are
    /// [`Mapped::Ignored`] unless a group takes them.
    pub fn get(&self, pixel: u16) -> Mapped {
        match self.lookup.get(usize::from(pixel)) {
            Some(m) => *m,
            None if pixel == NO_LABEL || self.ignores(pixel) => Mapped::Ignored,
            None => Mapped::Unknown,
        }
    }

    fn ignores(&self, pixel: u16) -> bool {
        segmenter(&self.segmenter).is_some_and(|t| t.ignore.contains(&pixel))
    }

    /// The smallest pixel value that means `class` (a simulator speaking this segmenter emits
    /// it), if any.
    pub fn pixel_of(&self, class: LabelId) -> Option<u16> {
        self.lookup.iter().position(|m| *m == Mapped::Class(class)).and_then(|k| u16::try_from(k).ok())
    }

    /// The segmenter's name, for logs.
    pub fn segmenter(&self) -> &str {
        &self.segmenter
    }
}

/// A group member as a pixel value.
pub(crate) fn resolve(
    class: &str,
    member: &SegmenterClass,
    table: Option<&Segmenter>,
    classes: &ClassTable,
) -> Result<u16, LabelMapError> {
    match (member, table) {
        (SegmenterClass::Id(id), Some(t)) if usize::from(*id) >= t.classes.len() => Err(LabelMapError::IdOutOfRange {
            class: class.into(),
            id: *id,
            segmenter: t.name.into(),
            max: u16::try_from(t.classes.len().saturating_sub(1)).unwrap_or(u16::MAX),
        }),
        (SegmenterClass::Id(id), _) => Ok(*id),
        (SegmenterClass::Name(name), table) => {
            let id = match table {
                Some(t) => t.id(name),
                None => classes.by_name(name).map(|c| c.id),
            };
            id.ok_or_else(|| LabelMapError::UnknownSegmenterClass {
                class: class.into(),
                segmenter: table.map_or(IDENTITY, |t| t.name).into(),
                name: name.clone(),
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::perception::classes::ClassSpec;
    use proptest::prelude::*;

    /// SGM's built-in table (as `actors::config::default_classes`).
    fn builtin() -> ClassTable {
        let names = ["ground", "wall", "tree", "lamp_post", "bench", "trash_can", "chair", "table", "bookshelf", "car"];
        ClassTable::new(
            names
                .iter()
                .enumerate()
                .map(|(id, name)| ClassSpec {
                    name: (*name).into(),
                    id: id as u16,
                    colour: [0, 0, 0],
                    matchable: id >= 2,
                    object: id >= 2,
                    dynamic: false,
                    min_points: 5,
                    max_points: 50_000,
                    max_extent_m: 3.0,
                })
                .collect(),
        )
        .expect("valid")
    }

    fn spec(segmenter: &str, map: &[(&str, Vec<SegmenterClass>)]) -> LabelMapSpec {
        LabelMapSpec {
            segmenter: segmenter.into(),
            map: map.iter().map(|(k, v)| ((*k).to_string(), v.clone())).collect(),
            palette: BTreeMap::new(),
        }
    }

    fn name(n: &str) -> SegmenterClass {
        SegmenterClass::Name(n.into())
    }

    fn error(s: &LabelMapSpec) -> String {
        LabelMap::new(s, &builtin()).expect_err("refused").to_string()
    }

    #[test]
    fn shipped_tables_map_their_default_groups() {
        let classes = builtin();
        let id = |n: &str| Mapped::Class(LabelId(classes.by_name(n).expect(n).id));
        let ade = LabelMap::new(&spec("ade20k_150", &[]), &classes).expect("valid");
        assert_eq!(ade.get(30), id("chair"), "ADE armchair");
        assert_eq!(ade.get(19), id("chair"), "ADE chair");
        assert_eq!(ade.get(138), id("trash_can"), "ADE ashcan");
        assert_eq!(ade.get(0), id("wall"), "ADE wall");
        assert_eq!(ade.get(2), Mapped::Ignored, "ADE sky");
        assert_eq!(ade.get(255), Mapped::Ignored);
        assert_eq!(ade.get(NO_LABEL), Mapped::Ignored);
        assert_eq!(ade.get(150), Mapped::Unknown);
        assert_eq!(ade.pixel_of(LabelId(6)), Some(19), "a simulator's chair is ADE's chair");
        let coco = LabelMap::new(&spec("coco_panoptic", &[]), &classes).expect("valid");
        assert_eq!(coco.get(56), id("chair"), "COCO chair");
        assert_eq!(coco.get(116), id("tree"), "COCO tree-merged");
        assert_eq!(coco.get(0), Mapped::Ignored, "COCO person");
        assert_eq!(coco.get(184), Mapped::Unknown, "COCO's sparse category_id of tree-merged");
        let city = LabelMap::new(&spec("cityscapes", &[]), &classes).expect("valid");
        assert_eq!(city.get(13), id("car"), "Cityscapes car");
        assert_eq!(city.get(8), id("tree"), "Cityscapes vegetation");
        assert_eq!(city.get(255), Mapped::Ignored);
        assert_eq!(city.get(19), Mapped::Unknown);
    }

    #[test]
    fn an_entry_replaces_the_default_group() {
        let classes = builtin();
        let map = spec("ade20k_150", &[("chair", vec![name("chair"), SegmenterClass::Id(31)])]);
        let ade = LabelMap::new(&map, &classes).expect("valid");
        assert_eq!(ade.get(31), Mapped::Class(LabelId(6)), "seat by id");
        assert_eq!(ade.get(30), Mapped::Ignored, "armchair left the group");
        let none = LabelMap::new(&spec("ade20k_150", &[("car", vec![])]), &classes).expect("valid");
        assert_eq!(none.get(20), Mapped::Ignored, "an empty group maps nothing");
        let identity = LabelMap::new(&spec("identity", &[("chair", vec![SegmenterClass::Id(40)])]), &classes);
        let identity = identity.expect("valid");
        assert_eq!(identity.get(40), Mapped::Class(LabelId(6)));
        assert_eq!(identity.get(6), Mapped::Unknown);
    }

    #[test]
    fn errors_name_the_entry() {
        assert_eq!(
            error(&spec("ade20k", &[])),
            "classes.segmenter: unknown segmenter \"ade20k\"; known: identity, ade20k_150, coco_panoptic, cityscapes"
        );
        assert_eq!(
            error(&spec("ade20k_150", &[("sofa", vec![name("sofa")])])),
            "classes.map.sofa: no class \"sofa\" in fusion.classes (ground, wall, tree, lamp_post, bench, \
             trash_can, chair, table, bookshelf, car)"
        );
        assert_eq!(
            error(&spec("ade20k_150", &[("chair", vec![name("stool ")])])),
            "classes.map.chair: segmenter ade20k_150 has no class \"stool \""
        );
        assert_eq!(
            error(&spec("ade20k_150", &[("chair", vec![name("chair"), name("bench")])])),
            "classes.map.chair: id 69 is mapped twice (already to bench's shipped default group; replace it in \
             classes.map)"
        );
        assert_eq!(
            error(&spec("ade20k_150", &[("bench", vec![name("bench")]), ("chair", vec![SegmenterClass::Id(69)])])),
            "classes.map.chair: id 69 is mapped twice (already to bench)"
        );
        assert_eq!(
            error(&spec("cityscapes", &[("chair", vec![name("bicycle"), SegmenterClass::Id(18)])])),
            "classes.map.chair: id 18 is mapped twice (already to chair)"
        );
        assert_eq!(
            error(&spec("cityscapes", &[("car", vec![SegmenterClass::Id(19)])])),
            "classes.map.car: id 19 is beyond segmenter cityscapes's ids 0–18"
        );
        assert_eq!(
            error(&spec("identity", &[("chair", vec![name("sofa")])])),
            "classes.map.chair: segmenter identity has no class \"sofa\""
        );
    }

    #[test]
    fn unknown_ids_are_counted_each_reported_once_and_bounded() {
        let mut unknown = UnknownLabels::default();
        assert!(unknown.add(150));
        assert!(!unknown.add(150));
        for id in 0..40u16 {
            unknown.add(1000 + id);
        }
        assert!(!unknown.add(1039), "seen beyond the kept ones: still reported once");
        assert_eq!(unknown.points, 43);
        assert_eq!(unknown.ids.len(), MAX_UNKNOWN_IDS);
        assert_eq!(unknown.ids[&150], 2);
        assert_eq!(unknown.ids.values().sum::<u64>() + unknown.other_points, unknown.points);
        assert_eq!(unknown.other_points, 10, "9 values beyond the 32 kept, one of them twice");
    }

    proptest! {
        /// `identity` is today's convention: a pixel value is its own class if `fusion.classes`
        /// has it, and Fusion's object classes come out as `ClassTable::object_label` gave them.
        #[test]
        fn identity_is_the_class_table(pixel in any::<u16>()) {
            let classes = builtin();
            let map = LabelMap::identity(&classes);
            let mapped = map.get(pixel);
            match classes.get(LabelId(pixel)) {
                Some(_) => prop_assert_eq!(mapped, Mapped::Class(LabelId(pixel))),
                None if pixel == NO_LABEL => prop_assert_eq!(mapped, Mapped::Ignored),
                None => prop_assert_eq!(mapped, Mapped::Unknown),
            }
            let object = match mapped { Mapped::Class(l) => classes.object_label(l.0), _ => None };
            prop_assert_eq!(object, classes.object_label(pixel));
        }
    }
}
