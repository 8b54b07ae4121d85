//! The sample layout: which components each sample carries, in which order,
//! and which random parameters the technique writes itself (INPUT).
//!
//! A [`SampleLayout`] is what a technique builds (names as strings, as in the
//! original C++ and Python APIs). [`SampleLayout::compile`] validates it and
//! yields a [`CompiledLayout`]: the element list plus a constant-time table
//! from element to offset inside a sample, which renderers use on their hot
//! path. Validation errors name the offending element and its position.
//!
//! Differences from the original, on purpose: numbered features are only the
//! enumerable ones (WORLD, NORMAL, TEXTURE_COLOR) with number 0 or 1, every
//! other number is an error (the original silently aliased `DEPTH[1]` to
//! `NORMAL_Z`); a duplicate element is an error; `WORLD_X_1`-style names are
//! rejected with a hint instead of being accepted and never filled.

use serde::{Deserialize, Serialize};
use std::fmt;

/// Whether the technique (INPUT) or the renderer (OUTPUT) writes an element.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum ElementIo {
    /// The renderer writes the value (all features, and random parameters by default).
    #[default]
    Output,
    /// The technique writes the value before the renderer sees the sample.
    Input,
}

macro_rules! named_enum {
    ($(#[$meta:meta])* $name:ident { $($(#[$vmeta:meta])* $variant:ident = $text:literal),+ $(,)? }) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        #[repr(u8)]
        pub enum $name { $($(#[$vmeta])* $variant),+ }

        impl $name {
            /// Every value, in declaration order.
            pub const ALL: &'static [$name] = &[$($name::$variant),+];
            /// The name used in layouts and scene files (e.g. `"IMAGE_X"`).
            pub fn name(self) -> &'static str {
                match self { $($name::$variant => $text),+ }
            }
            /// Looks a value up by its layout name.
            pub fn from_name(name: &str) -> Option<Self> {
                match name { $($text => Some($name::$variant),)+ _ => None }
            }
            /// Position in [`Self::ALL`].
            pub fn index(self) -> usize { self as usize }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result { f.write_str(self.name()) }
        }
    };
}

named_enum! {
    /// A random parameter: one dimension of a sample's position in the
    /// integration domain. IMAGE_X/IMAGE_Y are absolute pixel coordinates
    /// with a fractional part; the others lie in [0, 1).
    RandomParameter {
        /// Horizontal position on the image plane, in pixels.
        ImageX = "IMAGE_X",
        /// Vertical position on the image plane, in pixels.
        ImageY = "IMAGE_Y",
        /// First lens coordinate (depth of field).
        LensU = "LENS_U",
        /// Second lens coordinate (depth of field).
        LensV = "LENS_V",
        /// Time within the shutter interval, in [0, 1) (motion blur).
        Time = "TIME",
        /// First light-sampling coordinate.
        LightX = "LIGHT_X",
        /// Second light-sampling coordinate.
        LightY = "LIGHT_Y",
    }
}

named_enum! {
    /// A feature: a value the renderer computes for a sample.
    Feature {
        /// Sample radiance, red.
        ColorR = "COLOR_R",
        /// Sample radiance, green.
        ColorG = "COLOR_G",
        /// Sample radiance, blue.
        ColorB = "COLOR_B",
        /// Direct light incident at the first intersection, red.
        DirectLightR = "DIRECT_LIGHT_R",
        /// Direct light incident at the first intersection, green.
        DirectLightG = "DIRECT_LIGHT_G",
        /// Direct light incident at the first intersection, blue.
        DirectLightB = "DIRECT_LIGHT_B",
        /// Depth of the first intersection.
        Depth = "DEPTH",
        /// World position, x (numbered: intersection 0 or 1).
        WorldX = "WORLD_X",
        /// World position, y (numbered).
        WorldY = "WORLD_Y",
        /// World position, z (numbered).
        WorldZ = "WORLD_Z",
        /// Shading normal, x (numbered).
        NormalX = "NORMAL_X",
        /// Shading normal, y (numbered).
        NormalY = "NORMAL_Y",
        /// Shading normal, z (numbered).
        NormalZ = "NORMAL_Z",
        /// Texture value (albedo), red (numbered).
        TextureColorR = "TEXTURE_COLOR_R",
        /// Texture value (albedo), green (numbered).
        TextureColorG = "TEXTURE_COLOR_G",
        /// Texture value (albedo), blue (numbered).
        TextureColorB = "TEXTURE_COLOR_B",
        /// World position at the first non-specular intersection, x.
        WorldXNs = "WORLD_X_NS",
        /// World position at the first non-specular intersection, y.
        WorldYNs = "WORLD_Y_NS",
        /// World position at the first non-specular intersection, z.
        WorldZNs = "WORLD_Z_NS",
        /// Normal at the first non-specular intersection, x.
        NormalXNs = "NORMAL_X_NS",
        /// Normal at the first non-specular intersection, y.
        NormalYNs = "NORMAL_Y_NS",
        /// Normal at the first non-specular intersection, z.
        NormalZNs = "NORMAL_Z_NS",
        /// Albedo at the first non-specular intersection, red.
        TextureColorRNs = "TEXTURE_COLOR_R_NS",
        /// Albedo at the first non-specular intersection, green.
        TextureColorGNs = "TEXTURE_COLOR_G_NS",
        /// Albedo at the first non-specular intersection, blue.
        TextureColorBNs = "TEXTURE_COLOR_B_NS",
        /// Diffuse part of the sample radiance (roughness ≥ threshold), red.
        DiffuseColorR = "DIFFUSE_COLOR_R",
        /// Diffuse part of the sample radiance, green.
        DiffuseColorG = "DIFFUSE_COLOR_G",
        /// Diffuse part of the sample radiance, blue.
        DiffuseColorB = "DIFFUSE_COLOR_B",
    }
}

/// How many intersections a numbered feature can describe (numbers 0 and 1).
pub const MAX_FEATURE_NUMBER: u32 = 1;

/// The roughness threshold used when a layout does not set one.
pub const DEFAULT_ROUGHNESS_THRESHOLD: f32 = 0.1;

impl Feature {
    /// Whether the feature has one instance per intersection (numbers 0 and 1).
    pub fn is_numbered(self) -> bool {
        use Feature::*;
        matches!(
            self,
            WorldX | WorldY | WorldZ | NormalX | NormalY | NormalZ | TextureColorR | TextureColorG | TextureColorB
        )
    }
}

/// One validated element of a layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Element {
    /// A random parameter.
    Parameter(RandomParameter),
    /// A feature with its intersection number (0 unless numbered).
    Feature(Feature, u8),
}

impl Element {
    /// Index of this element in the constant-size lookup table.
    fn table_index(self) -> usize {
        match self {
            Element::Parameter(p) => p.index(),
            Element::Feature(f, n) => RandomParameter::ALL.len() + f.index() * 2 + n as usize,
        }
    }
}

impl fmt::Display for Element {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Element::Parameter(p) => write!(f, "{p}"),
            Element::Feature(feat, 0) => write!(f, "{feat}"),
            Element::Feature(feat, n) => write!(f, "{feat}[{n}]"),
        }
    }
}

const TABLE_SIZE: usize = 7 + 28 * 2;

/// One entry of a layout as the technique wrote it: a name, a number and a
/// direction. This is also the wire form of a layout.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LayoutEntry {
    /// Element name, e.g. `"COLOR_R"`.
    pub name: String,
    /// Intersection number for numbered features; 0 otherwise.
    #[serde(default)]
    pub number: u32,
    /// INPUT or OUTPUT.
    #[serde(default)]
    pub io: ElementIo,
}

/// A sample layout as a technique builds it, before validation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SampleLayout {
    /// The elements, in memory order.
    pub entries: Vec<LayoutEntry>,
    /// Beckmann roughness at or above which an interaction counts as diffuse
    /// for the DIFFUSE_COLOR features.
    pub roughness_threshold: f32,
}

impl Default for SampleLayout {
    fn default() -> Self {
        SampleLayout { entries: Vec::new(), roughness_threshold: DEFAULT_ROUGHNESS_THRESHOLD }
    }
}

impl SampleLayout {
    /// An empty layout with the default roughness threshold.
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends an OUTPUT element.
    pub fn with(self, name: &str) -> Self {
        self.with_io(name, ElementIo::Output)
    }

    /// Appends an element with the given direction.
    pub fn with_io(mut self, name: &str, io: ElementIo) -> Self {
        self.entries.push(LayoutEntry { name: name.to_string(), number: 0, io });
        self
    }

    /// Appends a numbered OUTPUT feature (e.g. `("NORMAL_X", 1)`).
    pub fn with_number(mut self, name: &str, number: u32) -> Self {
        self.entries.push(LayoutEntry { name: name.to_string(), number, io: ElementIo::Output });
        self
    }

    /// Sets the roughness threshold for the DIFFUSE_COLOR features.
    pub fn with_roughness_threshold(mut self, threshold: f32) -> Self {
        self.roughness_threshold = threshold;
        self
    }

    /// Validates the layout and builds its lookup table.
    pub fn compile(&self) -> Result<CompiledLayout, LayoutError> {
        if self.entries.is_empty() {
            return Err(LayoutError::Empty);
        }
        if !(self.roughness_threshold >= 0.0 && self.roughness_threshold.is_finite()) {
            return Err(LayoutError::BadRoughness(self.roughness_threshold));
        }
        let mut elements = Vec::with_capacity(self.entries.len());
        let mut table = [NOT_PRESENT; TABLE_SIZE];
        for (position, entry) in self.entries.iter().enumerate() {
            let element = parse_entry(entry).map_err(|problem| LayoutError::Element {
                position,
                name: entry.name.clone(),
                number: entry.number,
                problem,
            })?;
            let slot = &mut table[element.table_index()];
            if *slot != NOT_PRESENT {
                return Err(LayoutError::Element {
                    position,
                    name: entry.name.clone(),
                    number: entry.number,
                    problem: format!("duplicate: already at position {}", *slot),
                });
            }
            *slot = position as u16;
            elements.push((element, entry.io));
        }
        Ok(CompiledLayout { elements, table, roughness_threshold: self.roughness_threshold, source: self.clone() })
    }
}

fn parse_entry(entry: &LayoutEntry) -> Result<Element, String> {
    if let Some(p) = RandomParameter::from_name(&entry.name) {
        if entry.number != 0 {
            return Err(format!("random parameters are not numbered (got number {})", entry.number));
        }
        return Ok(Element::Parameter(p));
    }
    if let Some(f) = Feature::from_name(&entry.name) {
        if entry.io == ElementIo::Input {
            return Err("features are always OUTPUT; only random parameters can be INPUT".into());
        }
        if entry.number > 0 && !f.is_numbered() {
            return Err(format!(
                "{} is not numbered; only WORLD_*, NORMAL_* and TEXTURE_COLOR_* take a number",
                f.name()
            ));
        }
        if entry.number > MAX_FEATURE_NUMBER {
            return Err(format!("number {} out of range 0..={MAX_FEATURE_NUMBER}", entry.number));
        }
        return Ok(Element::Feature(f, entry.number as u8));
    }
    // Help with the one misspelling the original accepted silently.
    if let Some(base) = entry.name.strip_suffix("_1").or_else(|| entry.name.strip_suffix("_0")) {
        if Feature::from_name(base).is_some_and(Feature::is_numbered) {
            return Err(format!(
                "unknown name; write ({base:?}, {}) for a numbered feature",
                &entry.name[base.len() + 1..]
            ));
        }
    }
    Err("unknown name (see the element list in sdk/PROTOCOL.md)".into())
}

const NOT_PRESENT: u16 = u16::MAX;

/// An invalid layout. Every variant names what was wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LayoutError {
    /// The layout has no element.
    #[error("the sample layout is empty")]
    Empty,
    /// The roughness threshold is negative or not finite.
    #[error("roughness threshold must be a finite number ≥ 0, got {0}")]
    BadRoughness(f32),
    /// One element is unknown, duplicated, wrongly numbered or wrongly INPUT.
    #[error("layout element {position} ({name:?}, number {number}): {problem}")]
    Element {
        /// Position of the element in the layout (0-based).
        position: usize,
        /// The name as given.
        name: String,
        /// The number as given.
        number: u32,
        /// What is wrong with it.
        problem: String,
    },
}

/// A validated layout with a constant-time element → offset table.
#[derive(Debug, Clone, PartialEq)]
pub struct CompiledLayout {
    elements: Vec<(Element, ElementIo)>,
    table: [u16; TABLE_SIZE],
    roughness_threshold: f32,
    source: SampleLayout,
}

impl CompiledLayout {
    /// Number of floats per sample.
    pub fn sample_size(&self) -> usize {
        self.elements.len()
    }
    /// The elements in memory order with their direction.
    pub fn elements(&self) -> &[(Element, ElementIo)] {
        &self.elements
    }
    /// Offset of a random parameter in a sample, if present.
    pub fn parameter_offset(&self, p: RandomParameter) -> Option<usize> {
        self.offset(Element::Parameter(p))
    }
    /// Offset of a (numbered) feature in a sample, if present.
    pub fn feature_offset(&self, f: Feature, number: u8) -> Option<usize> {
        if number as u32 > MAX_FEATURE_NUMBER {
            return None;
        }
        self.offset(Element::Feature(f, number))
    }
    /// Offset of an element in a sample, if present.
    pub fn offset(&self, element: Element) -> Option<usize> {
        match self.table[element.table_index()] {
            NOT_PRESENT => None,
            i => Some(i as usize),
        }
    }
    /// Whether a random parameter is present and INPUT.
    pub fn is_input(&self, p: RandomParameter) -> bool {
        self.parameter_offset(p).is_some_and(|i| self.elements[i].1 == ElementIo::Input)
    }
    /// Per random parameter (by [`RandomParameter::index`]), the offset of
    /// its value in a sample when the technique gives it (INPUT).
    pub fn input_offsets(&self) -> [Option<usize>; 7] {
        std::array::from_fn(|d| {
            let p = RandomParameter::ALL[d];
            self.parameter_offset(p).filter(|_| self.is_input(p))
        })
    }
    /// Whether any element is INPUT.
    pub fn has_input(&self) -> bool {
        self.elements.iter().any(|(_, io)| *io == ElementIo::Input)
    }
    /// Number of INPUT elements.
    pub fn input_size(&self) -> usize {
        self.elements.iter().filter(|(_, io)| *io == ElementIo::Input).count()
    }
    /// Whether a feature (any number) is requested: lets renderers skip work.
    pub fn wants(&self, f: Feature) -> bool {
        (0..=MAX_FEATURE_NUMBER as u8).any(|n| self.feature_offset(f, n).is_some())
    }
    /// Roughness threshold for the DIFFUSE_COLOR features.
    pub fn roughness_threshold(&self) -> f32 {
        self.roughness_threshold
    }
    /// The layout as the technique wrote it (its wire form).
    pub fn source(&self) -> &SampleLayout {
        &self.source
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(layout: SampleLayout) -> String {
        layout.compile().unwrap_err().to_string()
    }

    #[test]
    fn offsets_follow_memory_order() {
        let l = SampleLayout::new()
            .with("COLOR_R")
            .with_io("IMAGE_X", ElementIo::Input)
            .with_number("NORMAL_X", 1)
            .with("NORMAL_X")
            .compile()
            .unwrap();
        assert_eq!(l.sample_size(), 4);
        assert_eq!(l.feature_offset(Feature::ColorR, 0), Some(0));
        assert_eq!(l.parameter_offset(RandomParameter::ImageX), Some(1));
        assert_eq!(l.feature_offset(Feature::NormalX, 1), Some(2));
        assert_eq!(l.feature_offset(Feature::NormalX, 0), Some(3));
        assert_eq!(l.feature_offset(Feature::Depth, 0), None);
        assert!(l.is_input(RandomParameter::ImageX));
        assert!(!l.is_input(RandomParameter::ImageY));
        assert_eq!(l.input_size(), 1);
        assert!(l.wants(Feature::NormalX));
        assert!(!l.wants(Feature::NormalY));
    }

    #[test]
    fn every_element_has_a_distinct_table_slot() {
        let mut layout = SampleLayout::new();
        for p in RandomParameter::ALL {
            layout = layout.with(p.name());
        }
        for f in Feature::ALL {
            layout = layout.with(f.name());
            if f.is_numbered() {
                layout = layout.with_number(f.name(), 1);
            }
        }
        let compiled = layout.compile().unwrap();
        assert_eq!(compiled.sample_size(), 7 + 28 + 9);
        for (i, (e, _)) in compiled.elements().iter().enumerate() {
            assert_eq!(compiled.offset(*e), Some(i), "{e}");
        }
    }

    #[test]
    fn unknown_name_is_named() {
        let e = err(SampleLayout::new().with("COLOR_R").with("COLOUR_G"));
        assert!(e.contains("element 1") && e.contains("COLOUR_G") && e.contains("unknown"), "{e}");
    }

    #[test]
    fn suffix_one_names_get_a_hint() {
        let e = err(SampleLayout::new().with("WORLD_X_1"));
        assert!(e.contains("(\"WORLD_X\", 1)"), "{e}");
    }

    #[test]
    fn duplicates_are_rejected() {
        let e = err(SampleLayout::new().with("COLOR_R").with("COLOR_G").with("COLOR_R"));
        assert!(e.contains("element 2") && e.contains("duplicate") && e.contains("position 0"), "{e}");
    }

    #[test]
    fn numbers_only_on_enumerable_features_and_in_range() {
        assert!(err(SampleLayout::new().with_number("DEPTH", 1)).contains("not numbered"));
        assert!(err(SampleLayout::new().with_number("WORLD_X", 2)).contains("out of range"));
        assert!(err(SampleLayout::new().with_number("IMAGE_X", 1)).contains("not numbered"));
        assert!(err(SampleLayout::new().with_number("COLOR_R_NS", 1)).contains("unknown"));
    }

    #[test]
    fn features_cannot_be_input() {
        assert!(err(SampleLayout::new().with_io("COLOR_R", ElementIo::Input)).contains("always OUTPUT"));
    }

    #[test]
    fn empty_and_bad_roughness() {
        assert_eq!(SampleLayout::new().compile().unwrap_err(), LayoutError::Empty);
        assert!(err(SampleLayout::new().with("COLOR_R").with_roughness_threshold(-1.0)).contains("roughness"));
        assert!(err(SampleLayout::new().with("COLOR_R").with_roughness_threshold(f32::NAN)).contains("roughness"));
    }
}
