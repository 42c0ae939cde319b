//! The class tables of common semantic segmenters, shipped so that a robot can take a real
//! network's label images as they come (`[classes]` in a robot configuration,
//! [`crate::perception::label_map`]): for each, the class name of every pixel value (index =
//! pixel value) and default groups onto SGM's built-in classes (`fusion.classes`' default table:
//! ground, wall, tree, lamp_post, bench, trash_can, chair, table, bookshelf, car).
//!
//! Where each list comes from (copied name for name, in order, and checked by the tests below for
//! length, uniqueness and a few anchors):
//! - [`ADE20K_150`]: the 150 classes of the ADE20K SceneParsing benchmark (`objectInfo150`), in
//!   the order of mmsegmentation's `ADE20KDataset.METAINFO['classes']`
//!   (open-mmlab/mmsegmentation, `mmseg/datasets/ade.py`): 0 = wall, 1 = building, …,
//!   149 = flag. These are the ids a network trained with `reduce_zero_label = True` outputs; the
//!   raw ADEChallenge annotation PNGs are shifted by one (0 = "other", 1 = wall).
//! - [`COCO_PANOPTIC`]: the 133 classes of COCO panoptic (80 things, 53 stuff) in the order of
//!   detectron2's `COCO_CATEGORIES` (facebookresearch/detectron2,
//!   `detectron2/data/datasets/builtin_meta.py`), numbered contiguously 0–132 as detectron2's
//!   semantic heads output them: 0 = person, 56 = chair, 116 = tree-merged. Not COCO's sparse
//!   `category_id` (1–200; tree-merged is 184).
//! - [`CITYSCAPES`]: the 19 evaluated classes by `trainId` 0–18 (mcordts/cityscapesScripts,
//!   `cityscapesscripts/helpers/labels.py`): 0 = road, 8 = vegetation, 13 = car, 18 = bicycle;
//!   255 is the ignore value.
//!
//! A default group is a choice, not a fact of the dataset: every group can be replaced per
//! robot (`[classes.map]`).

/// One segmenter's class table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Segmenter {
    /// Its name in `classes.segmenter`.
    pub name: &'static str,
    /// Class name of every pixel value: `classes[id]`.
    pub classes: &'static [&'static str],
    /// Pixel values that mean "no class" by the dataset's convention (the ignore index); their
    /// points carry no class and are not counted as unknown.
    pub ignore: &'static [u16],
    /// Default groups: SGM class name ← segmenter class names.
    pub default_groups: &'static [(&'static str, &'static [&'static str])],
}

impl Segmenter {
    /// The pixel value of a class name.
    pub fn id(&self, name: &str) -> Option<u16> {
        self.classes.iter().position(|c| *c == name).and_then(|k| u16::try_from(k).ok())
    }

    /// The class name of a pixel value.
    pub fn name_of(&self, id: u16) -> Option<&'static str> {
        self.classes.get(usize::from(id)).copied()
    }
}

/// The pixel value every segmenter table treats as "no class": the ROS bridge's `NO_LABEL`
/// (a per-point label field's value for an unlabelled point) and the simulator's background.
pub const NO_LABEL: u16 = u16::MAX;

/// ADE20K-150 (see the module documentation). ADE has no trash can class but `ashcan` (138);
/// `pole` (93) is left out of lamp_post by default, since ADE's pole covers every kind of pole.
pub const ADE20K_150: Segmenter = Segmenter {
    name: "ade20k_150",
    classes: ADE20K_150_CLASSES,
    ignore: &[255, NO_LABEL],
    default_groups: &[
        (
            "ground",
            &["floor", "road", "sidewalk", "grass", "earth", "path", "field", "sand", "dirt track", "land", "rug"],
        ),
        ("wall", &["wall", "building", "house", "fence", "skyscraper"]),
        ("tree", &["tree", "palm"]),
        ("lamp_post", &["streetlight"]),
        ("bench", &["bench"]),
        ("trash_can", &["ashcan"]),
        ("chair", &["chair", "armchair", "seat", "swivel chair"]),
        ("table", &["table", "desk", "coffee table"]),
        ("bookshelf", &["bookcase", "shelf"]),
        ("car", &["car", "truck", "van", "bus"]),
    ],
};

/// COCO panoptic, contiguous ids (see the module documentation). COCO has no street lamp and
/// no trash can: lamp_post and trash_can have no default group.
pub const COCO_PANOPTIC: Segmenter = Segmenter {
    name: "coco_panoptic",
    classes: COCO_PANOPTIC_CLASSES,
    ignore: &[255, NO_LABEL],
    default_groups: &[
        (
            "ground",
            &[
                "road",
                "floor-wood",
                "floor-other-merged",
                "pavement-merged",
                "grass-merged",
                "dirt-merged",
                "sand",
                "gravel",
                "rug-merged",
                "playingfield",
            ],
        ),
        (
            "wall",
            &[
                "wall-brick",
                "wall-stone",
                "wall-tile",
                "wall-wood",
                "wall-other-merged",
                "building-other-merged",
                "house",
                "fence-merged",
            ],
        ),
        ("tree", &["tree-merged"]),
        ("bench", &["bench"]),
        ("chair", &["chair"]),
        ("table", &["dining table", "table-merged"]),
        ("bookshelf", &["shelf"]),
        ("car", &["car", "truck", "bus"]),
    ],
};

/// Cityscapes trainIds (see the module documentation). Cityscapes has no bench, trash can,
/// chair, table or bookshelf: outdoors it yields trees, poles and cars only. Its `pole` covers
/// street-light poles and sign poles alike.
pub const CITYSCAPES: Segmenter = Segmenter {
    name: "cityscapes",
    classes: CITYSCAPES_CLASSES,
    ignore: &[255, NO_LABEL],
    default_groups: &[
        ("ground", &["road", "sidewalk", "terrain"]),
        ("wall", &["building", "wall", "fence"]),
        ("tree", &["vegetation"]),
        ("lamp_post", &["pole"]),
        ("car", &["car", "truck", "bus"]),
    ],
};

/// The shipped tables, by `classes.segmenter` name (`identity` is not a table: see
/// [`crate::perception::label_map`]).
pub const SEGMENTERS: &[&Segmenter] = &[&ADE20K_150, &COCO_PANOPTIC, &CITYSCAPES];

/// A shipped table by name.
pub fn segmenter(name: &str) -> Option<&'static Segmenter> {
    SEGMENTERS.iter().copied().find(|s| s.name == name)
}

/// Pixel value → class name.
const ADE20K_150_CLASSES: &[&str] = &[
    "wall",
    "building",
    "sky",
    "floor",
    "tree",
    "ceiling",
    "road",
    "bed",
    "windowpane",
    "grass",
    "cabinet",
    "sidewalk",
    "person",
    "earth",
    "door",
    "table",
    "mountain",
    "plant",
    "curtain",
    "chair",
    "car",
    "water",
    "painting",
    "sofa",
    "shelf",
    "house",
    "sea",
    "mirror",
    "rug",
    "field",
    "armchair",
    "seat",
    "fence",
    "desk",
    "rock",
    "wardrobe",
    "lamp",
    "bathtub",
    "railing",
    "cushion",
    "base",
    "box",
    "column",
    "signboard",
    "chest of drawers",
    "counter",
    "sand",
    "sink",
    "skyscraper",
    "fireplace",
    "refrigerator",
    "grandstand",
    "path",
    "stairs",
    "runway",
    "case",
    "pool table",
    "pillow",
    "screen door",
    "stairway",
    "river",
    "bridge",
    "bookcase",
    "blind",
    "coffee table",
    "toilet",
    "flower",
    "book",
    "hill",
    "bench",
    "countertop",
    "stove",
    "palm",
    "kitchen island",
    "computer",
    "swivel chair",
    "boat",
    "bar",
    "arcade machine",
    "hovel",
    "bus",
    "towel",
    "light",
    "truck",
    "tower",
    "chandelier",
    "awning",
    "streetlight",
    "booth",
    "television receiver",
    "airplane",
    "dirt track",
    "apparel",
    "pole",
    "land",
    "bannister",
    "escalator",
    "ottoman",
    "bottle",
    "buffet",
    "poster",
    "stage",
    "van",
    "ship",
    "fountain",
    "conveyer belt",
    "canopy",
    "washer",
    "plaything",
    "swimming pool",
    "stool",
    "barrel",
    "basket",
    "waterfall",
    "tent",
    "bag",
    "minibike",
    "cradle",
    "oven",
    "ball",
    "food",
    "step",
    "tank",
    "trade name",
    "microwave",
    "pot",
    "animal",
    "bicycle",
    "lake",
    "dishwasher",
    "screen",
    "blanket",
    "sculpture",
    "hood",
    "sconce",
    "vase",
    "traffic light",
    "tray",
    "ashcan",
    "fan",
    "pier",
    "crt screen",
    "plate",
    "monitor",
    "bulletin board",
    "shower",
    "radiator",
    "glass",
    "clock",
    "flag",
];
/// Pixel value → class name.
const COCO_PANOPTIC_CLASSES: &[&str] = &[
    "person",
    "bicycle",
    "car",
    "motorcycle",
    "airplane",
    "bus",
    "train",
    "truck",
    "boat",
    "traffic light",
    "fire hydrant",
    "stop sign",
    "parking meter",
    "bench",
    "bird",
    "cat",
    "dog",
    "horse",
    "sheep",
    "cow",
    "elephant",
    "bear",
    "zebra",
    "giraffe",
    "backpack",
    "umbrella",
    "handbag",
    "tie",
    "suitcase",
    "frisbee",
    "skis",
    "snowboard",
    "sports ball",
    "kite",
    "baseball bat",
    "baseball glove",
    "skateboard",
    "surfboard",
    "tennis racket",
    "bottle",
    "wine glass",
    "cup",
    "fork",
    "knife",
    "spoon",
    "bowl",
    "banana",
    "apple",
    "sandwich",
    "orange",
    "broccoli",
    "carrot",
    "hot dog",
    "pizza",
    "donut",
    "cake",
    "chair",
    "couch",
    "potted plant",
    "bed",
    "dining table",
    "toilet",
    "tv",
    "laptop",
    "mouse",
    "remote",
    "keyboard",
    "cell phone",
    "microwave",
    "oven",
    "toaster",
    "sink",
    "refrigerator",
    "book",
    "clock",
    "vase",
    "scissors",
    "teddy bear",
    "hair drier",
    "toothbrush",
    "banner",
    "blanket",
    "bridge",
    "cardboard",
    "counter",
    "curtain",
    "door-stuff",
    "floor-wood",
    "flower",
    "fruit",
    "gravel",
    "house",
    "light",
    "mirror-stuff",
    "net",
    "pillow",
    "platform",
    "playingfield",
    "railroad",
    "river",
    "road",
    "roof",
    "sand",
    "sea",
    "shelf",
    "snow",
    "stairs",
    "tent",
    "towel",
    "wall-brick",
    "wall-stone",
    "wall-tile",
    "wall-wood",
    "water-other",
    "window-blind",
    "window-other",
    "tree-merged",
    "fence-merged",
    "ceiling-merged",
    "sky-other-merged",
    "cabinet-merged",
    "table-merged",
    "floor-other-merged",
    "pavement-merged",
    "mountain-merged",
    "grass-merged",
    "dirt-merged",
    "paper-merged",
    "food-other-merged",
    "building-other-merged",
    "rock-merged",
    "wall-other-merged",
    "rug-merged",
];
/// Pixel value → class name.
const CITYSCAPES_CLASSES: &[&str] = &[
    "road",
    "sidewalk",
    "building",
    "wall",
    "fence",
    "pole",
    "traffic light",
    "traffic sign",
    "vegetation",
    "terrain",
    "sky",
    "person",
    "rider",
    "car",
    "truck",
    "bus",
    "train",
    "motorcycle",
    "bicycle",
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_have_the_published_length_unique_names_and_anchors() {
        for (s, n) in [(&ADE20K_150, 150), (&COCO_PANOPTIC, 133), (&CITYSCAPES, 19)] {
            assert_eq!(s.classes.len(), n, "{}", s.name);
            for (k, c) in s.classes.iter().enumerate() {
                assert!(!c.is_empty() && c.trim() == *c, "{} {k}: {c:?}", s.name);
                assert_eq!(s.id(c), Some(k as u16), "{} {c:?} is unique", s.name);
            }
        }
        let anchors: [(&Segmenter, &str, u16); 14] = [
            (&ADE20K_150, "wall", 0),
            (&ADE20K_150, "building", 1),
            (&ADE20K_150, "armchair", 30),
            (&ADE20K_150, "streetlight", 87),
            (&ADE20K_150, "ashcan", 138),
            (&ADE20K_150, "flag", 149),
            (&COCO_PANOPTIC, "person", 0),
            (&COCO_PANOPTIC, "chair", 56),
            (&COCO_PANOPTIC, "toothbrush", 79),
            (&COCO_PANOPTIC, "tree-merged", 116),
            (&COCO_PANOPTIC, "rug-merged", 132),
            (&CITYSCAPES, "road", 0),
            (&CITYSCAPES, "car", 13),
            (&CITYSCAPES, "bicycle", 18),
        ];
        for (s, name, id) in anchors {
            assert_eq!(s.id(name), Some(id), "{} {name}", s.name);
            assert_eq!(s.name_of(id), Some(name));
        }
    }

    #[test]
    fn default_groups_name_classes_of_their_table_once() {
        for s in SEGMENTERS {
            let mut seen = Vec::new();
            for (sgm, group) in s.default_groups {
                for name in *group {
                    let id = s.id(name).unwrap_or_else(|| panic!("{}: {sgm} ← {name:?} is no class", s.name));
                    assert!(!seen.contains(&id), "{}: {name:?} is in two groups", s.name);
                    seen.push(id);
                }
            }
        }
        assert_eq!(segmenter("cityscapes"), Some(&CITYSCAPES));
        assert_eq!(segmenter("identity"), None);
    }
}
