//! Colour label images back to pixel values. Many segmenters publish their output painted in
//! their dataset's palette (rgb8): a pixel of class `k` is `PALETTE[k]`. This map inverts it:
//!
//! ```text
//! id(colour) = k          if `[classes.palette]` assigns colour → k
//!            = k          else if the shipped palette has PALETTE[k] = colour (the smallest such k)
//!            = none       otherwise: counted and reported by colour, never guessed
//! ```
//!
//! The shipped palette is the segmenter's ([`crate::perception::palettes`]); for `identity` it is
//! `fusion.classes`' own colours (each class's id). A colour the palette gives to two ids (ADE20K's
//! road and skyscraper, `#8c8c8c`) reads as the smaller id and is listed in
//! [`ColourIds::ambiguous`]; `[classes.palette]` settles it. An entry `"none"` (or an ignore
//! value of the segmenter) marks a background colour: no class, and not unknown. Pixel values then
//! go through
//! [`crate::perception::label_map`] like those of a mono8/mono16 image.

use crate::perception::classes::ClassTable;
use crate::perception::label_map::{resolve, LabelMapError, LabelMapSpec, SegmenterClass, IDENTITY};
use crate::perception::palettes::palette;
use crate::perception::segmenters::{segmenter, NO_LABEL};

/// A `[classes.palette]` entry of this name paints pixels of no class (a background colour):
/// they are known, not counted as unknown.
pub const NO_CLASS_NAME: &str = "none";
use std::collections::{BTreeMap, HashMap};

/// An RGB colour.
pub type Rgb = [u8; 3];

/// `#rrggbb`.
pub fn hex(rgb: Rgb) -> String {
    format!("#{:02x}{:02x}{:02x}", rgb[0], rgb[1], rgb[2])
}

/// Parses `#rrggbb` (or `rrggbb`), case-insensitive.
pub fn parse_hex(text: &str) -> Option<Rgb> {
    let digits = text.strip_prefix('#').unwrap_or(text);
    if digits.len() != 6 || !digits.is_ascii() {
        return None;
    }
    let byte = |k: usize| u8::from_str_radix(&digits[k..k + 2], 16).ok();
    Some([byte(0)?, byte(2)?, byte(4)?])
}

/// What is wrong with `[classes.palette]`; names the key.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PaletteError {
    #[error("classes.palette.{key:?}: not a colour (\"#rrggbb\" expected)")]
    NotAColour { key: String },
    #[error("classes.palette: {0}")]
    Member(LabelMapError),
}

/// A validated colour → pixel value map.
#[derive(Clone, Debug, PartialEq)]
pub struct ColourIds {
    by_colour: HashMap<Rgb, u16>,
    ambiguous: BTreeMap<Rgb, Vec<u16>>,
}

impl ColourIds {
    /// The map of `spec` (its segmenter's palette and `[classes.palette]`) against the class table.
    pub fn new(spec: &LabelMapSpec, classes: &ClassTable) -> Result<Self, PaletteError> {
        let table = match spec.segmenter.as_str() {
            IDENTITY => None,
            name => segmenter(name),
        };
        let shipped: Vec<(u16, Rgb)> = match table {
            None => classes.classes().iter().map(|c| (c.id, c.colour)).collect(),
            Some(t) => palette(t.name)
                .unwrap_or_default()
                .iter()
                .enumerate()
                .filter_map(|(k, rgb)| Some((u16::try_from(k).ok()?, *rgb)))
                .collect(),
        };
        let mut by_colour: HashMap<Rgb, u16> = HashMap::new();
        let mut owners: BTreeMap<Rgb, Vec<u16>> = BTreeMap::new();
        for (id, rgb) in shipped {
            owners.entry(rgb).or_default().push(id);
            by_colour.entry(rgb).and_modify(|k| *k = (*k).min(id)).or_insert(id);
        }
        for (key, member) in &spec.palette {
            let rgb = parse_hex(key).ok_or_else(|| PaletteError::NotAColour { key: key.clone() })?;
            let no_class = match member {
                SegmenterClass::Name(name) => name == NO_CLASS_NAME,
                SegmenterClass::Id(id) => *id == NO_LABEL || table.is_some_and(|t| t.ignore.contains(id)),
            };
            let id = if no_class {
                NO_LABEL
            } else {
                resolve(&format!("palette.{key}"), member, table, classes).map_err(PaletteError::Member)?
            };
            by_colour.insert(rgb, id);
            owners.remove(&rgb);
        }
        let ambiguous = owners.into_iter().filter(|(_, ids)| ids.len() > 1).collect();
        Ok(Self { by_colour, ambiguous })
    }

    /// The pixel value painted `rgb`, if the palette has it.
    pub fn id(&self, rgb: Rgb) -> Option<u16> {
        self.by_colour.get(&rgb).copied()
    }

    /// Colours the shipped palette gives to several ids (read as the smallest), unless
    /// `[classes.palette]` settles them.
    pub fn ambiguous(&self) -> &BTreeMap<Rgb, Vec<u16>> {
        &self.ambiguous
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::perception::classes::ClassSpec;

    fn classes() -> ClassTable {
        let class = |name: &str, id: u16, colour: Rgb| ClassSpec {
            name: name.into(),
            id,
            colour,
            matchable: true,
            object: true,
            dynamic: false,
            min_points: 5,
            max_points: 50_000,
            max_extent_m: 3.0,
        };
        ClassTable::new(vec![class("ground", 0, [10, 20, 30]), class("chair", 6, [200, 0, 0])]).unwrap()
    }

    fn spec(segmenter: &str, palette: &[(&str, SegmenterClass)]) -> LabelMapSpec {
        LabelMapSpec {
            segmenter: segmenter.into(),
            map: BTreeMap::new(),
            palette: palette.iter().map(|(k, v)| ((*k).to_string(), v.clone())).collect(),
        }
    }

    #[test]
    fn colours_parse_and_print() {
        assert_eq!(parse_hex("#8C8c8c"), Some([140, 140, 140]));
        assert_eq!(parse_hex("787878"), Some([120, 120, 120]));
        assert_eq!(parse_hex("#78787"), None);
        assert_eq!(parse_hex("#78787g"), None);
        assert_eq!(parse_hex("#ééé"), None);
        assert_eq!(hex([220, 20, 60]), "#dc143c");
    }

    /// ADE20K-150 painted in mmsegmentation's palette: wall, chair (19) and the road/skyscraper
    /// colour (read as road, listed as ambiguous until `[classes.palette]` settles it).
    #[test]
    fn a_shipped_palette_reads_back_to_ids() {
        let ade = ColourIds::new(&spec("ade20k_150", &[]), &classes()).unwrap();
        assert_eq!(ade.id([120, 120, 120]), Some(0));
        assert_eq!(ade.id([204, 70, 3]), Some(19), "chair");
        assert_eq!(ade.id([140, 140, 140]), Some(6));
        assert_eq!(ade.ambiguous().get(&[140, 140, 140]), Some(&vec![6, 48]));
        assert_eq!(ade.id([1, 2, 3]), None);
        let settled = spec("ade20k_150", &[("#8c8c8c", SegmenterClass::Name("skyscraper".into()))]);
        let ade = ColourIds::new(&settled, &classes()).unwrap();
        assert_eq!(ade.id([140, 140, 140]), Some(48));
        assert!(ade.ambiguous().is_empty());
        let identity = ColourIds::new(&spec("identity", &[]), &classes()).unwrap();
        assert_eq!((identity.id([200, 0, 0]), identity.id([10, 20, 30])), (Some(6), Some(0)));
        // A background colour: known, of no class.
        let black = [("#000000", SegmenterClass::Name("none".into())), ("#ffffff", SegmenterClass::Id(255))];
        let ade = ColourIds::new(&spec("ade20k_150", &black), &classes()).unwrap();
        assert_eq!((ade.id([0, 0, 0]), ade.id([255, 255, 255])), (Some(NO_LABEL), Some(NO_LABEL)));
    }

    #[test]
    fn bad_palette_entries_are_named() {
        let e = ColourIds::new(&spec("ade20k_150", &[("grey", SegmenterClass::Id(3))]), &classes()).unwrap_err();
        assert_eq!(e.to_string(), "classes.palette.\"grey\": not a colour (\"#rrggbb\" expected)");
        let e =
            ColourIds::new(&spec("ade20k_150", &[("#010203", SegmenterClass::Name("sofa bed".into()))]), &classes())
                .unwrap_err();
        assert!(e.to_string().contains("segmenter ade20k_150 has no class \"sofa bed\""), "{e}");
        let e = ColourIds::new(&spec("cityscapes", &[("#010203", SegmenterClass::Id(40))]), &classes()).unwrap_err();
        assert!(e.to_string().contains("id 40 is beyond segmenter cityscapes's ids 0–18"), "{e}");
    }
}
