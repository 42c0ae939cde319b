//! The colour palettes of the segmenters in [`crate::perception::segmenters`]: many segmenters
//! publish their output as a colourised image (rgb8) in which every pixel of class id `k` is painted
//! `PALETTE[k]`; reading such an image back means mapping each colour to its id. The palette index
//! is the segmenter's pixel id exactly as in `segmenters.rs` (`classes[k]` ↔ `PALETTE[k]`), and
//! each list has the length of its class table.
//!
//! Where each palette comes from (copied value for value, in order, by a script reading the source
//! files, and checked by the tests below for length, anchors and colour collisions):
//! - [`ADE20K_150_PALETTE`]: `ADE20KDataset.METAINFO['palette']` of open-mmlab/mmsegmentation,
//!   `mmseg/datasets/ade.py` (release 1.2.2 as published on PyPI), in the order of its `classes`:
//!   0 = wall `[120, 120, 120]`, …, 149 = flag `[92, 0, 255]`.
//! - [`COCO_PANOPTIC_PALETTE`]: the `color` of every entry of `COCO_CATEGORIES` in
//!   facebookresearch/detectron2, `detectron2/data/datasets/builtin_meta.py` (last changed in
//!   commit ed104f3f; detectron2 took them from cocodataset/panopticapi
//!   `panoptic_coco_categories.json`), in list order, which is the contiguous id order 0–132
//!   (detectron2's `coco_panoptic_standard` metadata, `stuff_colors`): 0 = person
//!   `[220, 20, 60]`, …, 132 = rug-merged `[250, 141, 255]`.
//! - [`CITYSCAPES_PALETTE`]: the `color` of the label with `trainId` k, k = 0..=18, in
//!   mcordts/cityscapesScripts, `cityscapesscripts/helpers/labels.py` (last changed in commit
//!   9f0aa8d3): 0 = road `[128, 64, 128]`, 13 = car `[0, 0, 142]`, 18 = bicycle `[119, 11, 32]`.
//!
//! Collisions: within ADE20K-150, road (6) and skyscraper (48) share `[140, 140, 140]` in
//! mmsegmentation's palette, so that colour cannot be mapped back to one id (a reader must treat it
//! as ambiguous or choose one by configuration). COCO panoptic and Cityscapes have no shared colour
//! within their palette. Across palettes colours do repeat (detectron2's COCO palette reuses
//! Cityscapes colours: person, car, road, tree-merged/vegetation, …), so the segmenter must be
//! known before a colour is read.
//!
//! Only flat label images map back: overlays blended with the photo, or instance colours jittered
//! (as detectron2's `Visualizer` draws things), do not carry the palette's exact values.

/// ADE20K-150, mmsegmentation order: `ADE20K_150_PALETTE[k]` is the colour of pixel id `k`.
/// Road (6) and skyscraper (48) share `[140, 140, 140]`.
pub const ADE20K_150_PALETTE: [[u8; 3]; 150] = [
    [120, 120, 120], // 0 wall
    [180, 120, 120], // 1 building
    [6, 230, 230],   // 2 sky
    [80, 50, 50],    // 3 floor
    [4, 200, 3],     // 4 tree
    [120, 120, 80],  // 5 ceiling
    [140, 140, 140], // 6 road
    [204, 5, 255],   // 7 bed
    [230, 230, 230], // 8 windowpane
    [4, 250, 7],     // 9 grass
    [224, 5, 255],   // 10 cabinet
    [235, 255, 7],   // 11 sidewalk
    [150, 5, 61],    // 12 person
    [120, 120, 70],  // 13 earth
    [8, 255, 51],    // 14 door
    [255, 6, 82],    // 15 table
    [143, 255, 140], // 16 mountain
    [204, 255, 4],   // 17 plant
    [255, 51, 7],    // 18 curtain
    [204, 70, 3],    // 19 chair
    [0, 102, 200],   // 20 car
    [61, 230, 250],  // 21 water
    [255, 6, 51],    // 22 painting
    [11, 102, 255],  // 23 sofa
    [255, 7, 71],    // 24 shelf
    [255, 9, 224],   // 25 house
    [9, 7, 230],     // 26 sea
    [220, 220, 220], // 27 mirror
    [255, 9, 92],    // 28 rug
    [112, 9, 255],   // 29 field
    [8, 255, 214],   // 30 armchair
    [7, 255, 224],   // 31 seat
    [255, 184, 6],   // 32 fence
    [10, 255, 71],   // 33 desk
    [255, 41, 10],   // 34 rock
    [7, 255, 255],   // 35 wardrobe
    [224, 255, 8],   // 36 lamp
    [102, 8, 255],   // 37 bathtub
    [255, 61, 6],    // 38 railing
    [255, 194, 7],   // 39 cushion
    [255, 122, 8],   // 40 base
    [0, 255, 20],    // 41 box
    [255, 8, 41],    // 42 column
    [255, 5, 153],   // 43 signboard
    [6, 51, 255],    // 44 chest of drawers
    [235, 12, 255],  // 45 counter
    [160, 150, 20],  // 46 sand
    [0, 163, 255],   // 47 sink
    [140, 140, 140], // 48 skyscraper
    [250, 10, 15],   // 49 fireplace
    [20, 255, 0],    // 50 refrigerator
    [31, 255, 0],    // 51 grandstand
    [255, 31, 0],    // 52 path
    [255, 224, 0],   // 53 stairs
    [153, 255, 0],   // 54 runway
    [0, 0, 255],     // 55 case
    [255, 71, 0],    // 56 pool table
    [0, 235, 255],   // 57 pillow
    [0, 173, 255],   // 58 screen door
    [31, 0, 255],    // 59 stairway
    [11, 200, 200],  // 60 river
    [255, 82, 0],    // 61 bridge
    [0, 255, 245],   // 62 bookcase
    [0, 61, 255],    // 63 blind
    [0, 255, 112],   // 64 coffee table
    [0, 255, 133],   // 65 toilet
    [255, 0, 0],     // 66 flower
    [255, 163, 0],   // 67 book
    [255, 102, 0],   // 68 hill
    [194, 255, 0],   // 69 bench
    [0, 143, 255],   // 70 countertop
    [51, 255, 0],    // 71 stove
    [0, 82, 255],    // 72 palm
    [0, 255, 41],    // 73 kitchen island
    [0, 255, 173],   // 74 computer
    [10, 0, 255],    // 75 swivel chair
    [173, 255, 0],   // 76 boat
    [0, 255, 153],   // 77 bar
    [255, 92, 0],    // 78 arcade machine
    [255, 0, 255],   // 79 hovel
    [255, 0, 245],   // 80 bus
    [255, 0, 102],   // 81 towel
    [255, 173, 0],   // 82 light
    [255, 0, 20],    // 83 truck
    [255, 184, 184], // 84 tower
    [0, 31, 255],    // 85 chandelier
    [0, 255, 61],    // 86 awning
    [0, 71, 255],    // 87 streetlight
    [255, 0, 204],   // 88 booth
    [0, 255, 194],   // 89 television receiver
    [0, 255, 82],    // 90 airplane
    [0, 10, 255],    // 91 dirt track
    [0, 112, 255],   // 92 apparel
    [51, 0, 255],    // 93 pole
    [0, 194, 255],   // 94 land
    [0, 122, 255],   // 95 bannister
    [0, 255, 163],   // 96 escalator
    [255, 153, 0],   // 97 ottoman
    [0, 255, 10],    // 98 bottle
    [255, 112, 0],   // 99 buffet
    [143, 255, 0],   // 100 poster
    [82, 0, 255],    // 101 stage
    [163, 255, 0],   // 102 van
    [255, 235, 0],   // 103 ship
    [8, 184, 170],   // 104 fountain
    [133, 0, 255],   // 105 conveyer belt
    [0, 255, 92],    // 106 canopy
    [184, 0, 255],   // 107 washer
    [255, 0, 31],    // 108 plaything
    [0, 184, 255],   // 109 swimming pool
    [0, 214, 255],   // 110 stool
    [255, 0, 112],   // 111 barrel
    [92, 255, 0],    // 112 basket
    [0, 224, 255],   // 113 waterfall
    [112, 224, 255], // 114 tent
    [70, 184, 160],  // 115 bag
    [163, 0, 255],   // 116 minibike
    [153, 0, 255],   // 117 cradle
    [71, 255, 0],    // 118 oven
    [255, 0, 163],   // 119 ball
    [255, 204, 0],   // 120 food
    [255, 0, 143],   // 121 step
    [0, 255, 235],   // 122 tank
    [133, 255, 0],   // 123 trade name
    [255, 0, 235],   // 124 microwave
    [245, 0, 255],   // 125 pot
    [255, 0, 122],   // 126 animal
    [255, 245, 0],   // 127 bicycle
    [10, 190, 212],  // 128 lake
    [214, 255, 0],   // 129 dishwasher
    [0, 204, 255],   // 130 screen
    [20, 0, 255],    // 131 blanket
    [255, 255, 0],   // 132 sculpture
    [0, 153, 255],   // 133 hood
    [0, 41, 255],    // 134 sconce
    [0, 255, 204],   // 135 vase
    [41, 0, 255],    // 136 traffic light
    [41, 255, 0],    // 137 tray
    [173, 0, 255],   // 138 ashcan
    [0, 245, 255],   // 139 fan
    [71, 0, 255],    // 140 pier
    [122, 0, 255],   // 141 crt screen
    [0, 255, 184],   // 142 plate
    [0, 92, 255],    // 143 monitor
    [184, 255, 0],   // 144 bulletin board
    [0, 133, 255],   // 145 shower
    [255, 214, 0],   // 146 radiator
    [25, 194, 194],  // 147 glass
    [102, 255, 0],   // 148 clock
    [92, 0, 255],    // 149 flag
];

/// COCO panoptic, contiguous ids 0–132 (detectron2's `COCO_CATEGORIES` order).
pub const COCO_PANOPTIC_PALETTE: [[u8; 3]; 133] = [
    [220, 20, 60],   // 0 person
    [119, 11, 32],   // 1 bicycle
    [0, 0, 142],     // 2 car
    [0, 0, 230],     // 3 motorcycle
    [106, 0, 228],   // 4 airplane
    [0, 60, 100],    // 5 bus
    [0, 80, 100],    // 6 train
    [0, 0, 70],      // 7 truck
    [0, 0, 192],     // 8 boat
    [250, 170, 30],  // 9 traffic light
    [100, 170, 30],  // 10 fire hydrant
    [220, 220, 0],   // 11 stop sign
    [175, 116, 175], // 12 parking meter
    [250, 0, 30],    // 13 bench
    [165, 42, 42],   // 14 bird
    [255, 77, 255],  // 15 cat
    [0, 226, 252],   // 16 dog
    [182, 182, 255], // 17 horse
    [0, 82, 0],      // 18 sheep
    [120, 166, 157], // 19 cow
    [110, 76, 0],    // 20 elephant
    [174, 57, 255],  // 21 bear
    [199, 100, 0],   // 22 zebra
    [72, 0, 118],    // 23 giraffe
    [255, 179, 240], // 24 backpack
    [0, 125, 92],    // 25 umbrella
    [209, 0, 151],   // 26 handbag
    [188, 208, 182], // 27 tie
    [0, 220, 176],   // 28 suitcase
    [255, 99, 164],  // 29 frisbee
    [92, 0, 73],     // 30 skis
    [133, 129, 255], // 31 snowboard
    [78, 180, 255],  // 32 sports ball
    [0, 228, 0],     // 33 kite
    [174, 255, 243], // 34 baseball bat
    [45, 89, 255],   // 35 baseball glove
    [134, 134, 103], // 36 skateboard
    [145, 148, 174], // 37 surfboard
    [255, 208, 186], // 38 tennis racket
    [197, 226, 255], // 39 bottle
    [171, 134, 1],   // 40 wine glass
    [109, 63, 54],   // 41 cup
    [207, 138, 255], // 42 fork
    [151, 0, 95],    // 43 knife
    [9, 80, 61],     // 44 spoon
    [84, 105, 51],   // 45 bowl
    [74, 65, 105],   // 46 banana
    [166, 196, 102], // 47 apple
    [208, 195, 210], // 48 sandwich
    [255, 109, 65],  // 49 orange
    [0, 143, 149],   // 50 broccoli
    [179, 0, 194],   // 51 carrot
    [209, 99, 106],  // 52 hot dog
    [5, 121, 0],     // 53 pizza
    [227, 255, 205], // 54 donut
    [147, 186, 208], // 55 cake
    [153, 69, 1],    // 56 chair
    [3, 95, 161],    // 57 couch
    [163, 255, 0],   // 58 potted plant
    [119, 0, 170],   // 59 bed
    [0, 182, 199],   // 60 dining table
    [0, 165, 120],   // 61 toilet
    [183, 130, 88],  // 62 tv
    [95, 32, 0],     // 63 laptop
    [130, 114, 135], // 64 mouse
    [110, 129, 133], // 65 remote
    [166, 74, 118],  // 66 keyboard
    [219, 142, 185], // 67 cell phone
    [79, 210, 114],  // 68 microwave
    [178, 90, 62],   // 69 oven
    [65, 70, 15],    // 70 toaster
    [127, 167, 115], // 71 sink
    [59, 105, 106],  // 72 refrigerator
    [142, 108, 45],  // 73 book
    [196, 172, 0],   // 74 clock
    [95, 54, 80],    // 75 vase
    [128, 76, 255],  // 76 scissors
    [201, 57, 1],    // 77 teddy bear
    [246, 0, 122],   // 78 hair drier
    [191, 162, 208], // 79 toothbrush
    [255, 255, 128], // 80 banner
    [147, 211, 203], // 81 blanket
    [150, 100, 100], // 82 bridge
    [168, 171, 172], // 83 cardboard
    [146, 112, 198], // 84 counter
    [210, 170, 100], // 85 curtain
    [92, 136, 89],   // 86 door-stuff
    [218, 88, 184],  // 87 floor-wood
    [241, 129, 0],   // 88 flower
    [217, 17, 255],  // 89 fruit
    [124, 74, 181],  // 90 gravel
    [70, 70, 70],    // 91 house
    [255, 228, 255], // 92 light
    [154, 208, 0],   // 93 mirror-stuff
    [193, 0, 92],    // 94 net
    [76, 91, 113],   // 95 pillow
    [255, 180, 195], // 96 platform
    [106, 154, 176], // 97 playingfield
    [230, 150, 140], // 98 railroad
    [60, 143, 255],  // 99 river
    [128, 64, 128],  // 100 road
    [92, 82, 55],    // 101 roof
    [254, 212, 124], // 102 sand
    [73, 77, 174],   // 103 sea
    [255, 160, 98],  // 104 shelf
    [255, 255, 255], // 105 snow
    [104, 84, 109],  // 106 stairs
    [169, 164, 131], // 107 tent
    [225, 199, 255], // 108 towel
    [137, 54, 74],   // 109 wall-brick
    [135, 158, 223], // 110 wall-stone
    [7, 246, 231],   // 111 wall-tile
    [107, 255, 200], // 112 wall-wood
    [58, 41, 149],   // 113 water-other
    [183, 121, 142], // 114 window-blind
    [255, 73, 97],   // 115 window-other
    [107, 142, 35],  // 116 tree-merged
    [190, 153, 153], // 117 fence-merged
    [146, 139, 141], // 118 ceiling-merged
    [70, 130, 180],  // 119 sky-other-merged
    [134, 199, 156], // 120 cabinet-merged
    [209, 226, 140], // 121 table-merged
    [96, 36, 108],   // 122 floor-other-merged
    [96, 96, 96],    // 123 pavement-merged
    [64, 170, 64],   // 124 mountain-merged
    [152, 251, 152], // 125 grass-merged
    [208, 229, 228], // 126 dirt-merged
    [206, 186, 171], // 127 paper-merged
    [152, 161, 64],  // 128 food-other-merged
    [116, 112, 0],   // 129 building-other-merged
    [0, 114, 143],   // 130 rock-merged
    [102, 102, 156], // 131 wall-other-merged
    [250, 141, 255], // 132 rug-merged
];

/// Cityscapes, by `trainId` 0–18.
pub const CITYSCAPES_PALETTE: [[u8; 3]; 19] = [
    [128, 64, 128],  // 0 road
    [244, 35, 232],  // 1 sidewalk
    [70, 70, 70],    // 2 building
    [102, 102, 156], // 3 wall
    [190, 153, 153], // 4 fence
    [153, 153, 153], // 5 pole
    [250, 170, 30],  // 6 traffic light
    [220, 220, 0],   // 7 traffic sign
    [107, 142, 35],  // 8 vegetation
    [152, 251, 152], // 9 terrain
    [70, 130, 180],  // 10 sky
    [220, 20, 60],   // 11 person
    [255, 0, 0],     // 12 rider
    [0, 0, 142],     // 13 car
    [0, 0, 70],      // 14 truck
    [0, 60, 100],    // 15 bus
    [0, 80, 100],    // 16 train
    [0, 0, 230],     // 17 motorcycle
    [119, 11, 32],   // 18 bicycle
];

/// The palette of a shipped segmenter table, by its name in `classes.segmenter`
/// (`ade20k_150`, `coco_panoptic`, `cityscapes`); `None` for any other name.
pub fn palette(segmenter: &str) -> Option<&'static [[u8; 3]]> {
    match segmenter {
        "ade20k_150" => Some(&ADE20K_150_PALETTE),
        "coco_panoptic" => Some(&COCO_PANOPTIC_PALETTE),
        "cityscapes" => Some(&CITYSCAPES_PALETTE),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::super::segmenters::{Segmenter, ADE20K_150, CITYSCAPES, COCO_PANOPTIC, SEGMENTERS};
    use super::*;

    /// Every pair of ids (lower first) that share a colour.
    fn collisions(p: &[[u8; 3]]) -> Vec<(usize, usize)> {
        let mut pairs = Vec::new();
        for (i, a) in p.iter().enumerate() {
            for (j, b) in p.iter().enumerate().skip(i + 1) {
                if a == b {
                    pairs.push((i, j));
                }
            }
        }
        pairs
    }

    #[test]
    fn palettes_have_the_length_of_their_class_table() {
        assert_eq!(ADE20K_150_PALETTE.len(), ADE20K_150.classes.len());
        assert_eq!(COCO_PANOPTIC_PALETTE.len(), COCO_PANOPTIC.classes.len());
        assert_eq!(CITYSCAPES_PALETTE.len(), CITYSCAPES.classes.len());
        for s in SEGMENTERS {
            let p = palette(s.name).unwrap_or_else(|| panic!("{} has no palette", s.name));
            assert_eq!(p.len(), s.classes.len(), "{}", s.name);
        }
        assert_eq!(palette("identity"), None);
        assert_eq!(palette("ADE20K_150"), None);
    }

    #[test]
    fn anchors_match_the_sources() {
        let anchors: [(&Segmenter, &str, [u8; 3]); 14] = [
            (&ADE20K_150, "wall", [120, 120, 120]),
            (&ADE20K_150, "road", [140, 140, 140]),
            (&ADE20K_150, "tree", [4, 200, 3]),
            (&ADE20K_150, "skyscraper", [140, 140, 140]),
            (&ADE20K_150, "flag", [92, 0, 255]),
            (&COCO_PANOPTIC, "person", [220, 20, 60]),
            (&COCO_PANOPTIC, "car", [0, 0, 142]),
            (&COCO_PANOPTIC, "chair", [153, 69, 1]),
            (&COCO_PANOPTIC, "tree-merged", [107, 142, 35]),
            (&COCO_PANOPTIC, "rug-merged", [250, 141, 255]),
            (&CITYSCAPES, "road", [128, 64, 128]),
            (&CITYSCAPES, "vegetation", [107, 142, 35]),
            (&CITYSCAPES, "car", [0, 0, 142]),
            (&CITYSCAPES, "bicycle", [119, 11, 32]),
        ];
        for (s, name, colour) in anchors {
            let id = s.id(name).unwrap_or_else(|| panic!("{}: {name:?} is no class", s.name));
            let p = palette(s.name).unwrap_or_else(|| panic!("{} has no palette", s.name));
            assert_eq!(p[usize::from(id)], colour, "{} {name} ({id})", s.name);
        }
    }

    #[test]
    fn shared_colours_are_exactly_the_documented_ones() {
        assert_eq!(collisions(&ADE20K_150_PALETTE), vec![(6, 48)]);
        assert_eq!(ADE20K_150.name_of(6), Some("road"));
        assert_eq!(ADE20K_150.name_of(48), Some("skyscraper"));
        assert_eq!(ADE20K_150_PALETTE[6], [140, 140, 140]);
        assert_eq!(collisions(&COCO_PANOPTIC_PALETTE), Vec::<(usize, usize)>::new());
        assert_eq!(collisions(&CITYSCAPES_PALETTE), Vec::<(usize, usize)>::new());
    }
}
