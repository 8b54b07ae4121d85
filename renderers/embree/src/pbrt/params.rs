//! Parameter lists (`"float radius" 1`, `"rgb L" [1 1 1]`): typed lookup,
//! and an error for every parameter nobody asked for.

use super::{Loc, SceneError};
use crate::math::{vec3, Vec3};
use std::cell::Cell;

/// The values of one parameter.
#[derive(Debug, Clone, PartialEq)]
pub enum Values {
    /// Numbers.
    Nums(Vec<f64>),
    /// Strings.
    Strs(Vec<String>),
    /// Booleans.
    Bools(Vec<bool>),
}

/// One parameter: `"type name" value(s)`.
#[derive(Debug, Clone)]
pub struct Param {
    /// Declared type (`float`, `rgb`, `texture`, …).
    pub ty: String,
    /// Name.
    pub name: String,
    /// Values.
    pub values: Values,
    /// Where it was written.
    pub loc: Loc,
    used: Cell<bool>,
}

/// pbrt-v3 parameter types, and the pbrt-v4 types they are read as.
const V3_TYPES: &[(&str, &str)] =
    &[("color", "rgb"), ("point", "point3"), ("normal", "normal3"), ("vector", "vector3")];

/// The parameters of one directive, and what they belong to (for messages).
#[derive(Debug, Clone)]
pub struct ParamSet {
    params: Vec<Param>,
    /// Constructs read with a conversion (pbrt-v3 forms, repeated
    /// parameters), for warnings.
    pub upgrades: Vec<(Loc, String)>,
    /// E.g. `Shape "sphere"`.
    pub owner: String,
    /// Where the directive is.
    pub loc: Loc,
}

const TYPES: &[&str] = &[
    "integer",
    "float",
    "point2",
    "vector2",
    "point3",
    "vector3",
    "normal3",
    "rgb",
    "spectrum",
    "blackbody",
    "bool",
    "string",
    "texture",
];

/// A spectral parameter's value.
#[derive(Debug, Clone, PartialEq)]
pub enum SpectrumValue {
    /// An RGB triple (or a named metal's RGB approximation).
    Rgb(Vec3),
    /// A reference to a named texture.
    Texture(String),
}

impl ParamSet {
    /// An empty set.
    pub fn new(owner: String, loc: Loc) -> ParamSet {
        ParamSet { params: Vec::new(), upgrades: Vec::new(), owner, loc }
    }

    /// Adds a parameter; rejects unknown types and duplicates.
    pub fn push(&mut self, decl: &str, values: Values, loc: Loc) -> Result<(), SceneError> {
        let mut words = decl.split_whitespace();
        let (Some(ty), Some(name), None) = (words.next(), words.next(), words.next()) else {
            return Err(SceneError::at(&loc, format!("parameter declaration {decl:?} should be \"type name\"")));
        };
        let ty = match V3_TYPES.iter().find(|(v3, _)| *v3 == ty) {
            Some((v3, v4)) => {
                self.upgrades.push((loc.clone(), format!("pbrt-v3 parameter type \"{v3}\" read as \"{v4}\"")));
                *v4
            }
            None if TYPES.contains(&ty) => ty,
            None => return Err(SceneError::at(&loc, format!("unknown parameter type {ty:?} in {decl:?}"))),
        };
        if self.params.iter().any(|p| p.name == name) {
            // pbrt reads the first and lets the rest be (real scene files repeat parameters).
            self.upgrades.push((loc, format!("parameter {name:?} given twice for {}: the first is used", self.owner)));
            return Ok(());
        }
        let ok = match (&values, ty) {
            (Values::Strs(_), "string" | "texture" | "spectrum" | "bool") => true,
            (Values::Bools(_), "bool") => true,
            (Values::Nums(_), "string" | "texture" | "bool") => false,
            (Values::Nums(_), _) => true,
            _ => false,
        };
        if !ok {
            return Err(SceneError::at(&loc, format!("values of {decl:?} have the wrong kind for type {ty}")));
        }
        self.params.push(Param { ty: ty.into(), name: name.into(), values, loc, used: Cell::new(false) });
        Ok(())
    }

    /// Whether `name` is given.
    pub fn has(&self, name: &str) -> bool {
        self.params.iter().any(|p| p.name == name)
    }

    /// Renames parameter `from` to `to` (a pbrt-v3 name to pbrt-v4's);
    /// whether it was there.
    pub fn rename(&mut self, from: &str, to: &str) -> bool {
        if self.has(to) {
            return false;
        }
        match self.params.iter_mut().find(|p| p.name == from) {
            Some(p) => {
                p.name = to.into();
                true
            }
            None => false,
        }
    }

    /// Takes parameter `name` out of the list.
    pub fn remove(&mut self, name: &str) -> Option<Param> {
        let i = self.params.iter().position(|p| p.name == name)?;
        Some(self.params.remove(i))
    }

    /// Sets parameter `name` to type `ty` and these values, replacing any.
    pub fn set(&mut self, ty: &str, name: &str, values: Values) {
        let loc = self.remove(name).map_or_else(|| self.loc.clone(), |p| p.loc);
        self.params.push(Param { ty: ty.into(), name: name.into(), values, loc, used: Cell::new(false) });
    }

    /// Parameter `name` as written, without marking it read.
    pub fn get(&self, name: &str) -> Option<&Param> {
        self.params.iter().find(|p| p.name == name)
    }

    /// Marks `name` as read without reading it (a hint this renderer has
    /// no use for); whether it was given.
    pub fn ignore(&self, name: &str) -> bool {
        self.find(name).is_some()
    }

    /// Marks every parameter as read (a directive whose parameters are all hints).
    pub fn ignore_all(&self) -> Vec<String> {
        self.params.iter().filter(|p| !p.used.replace(true)).map(|p| format!("\"{} {}\"", p.ty, p.name)).collect()
    }

    /// The value of a constant numeric or RGB parameter, if it has one
    /// value or three equal ones (for checking a v3 default).
    pub fn constant(&self, name: &str) -> Option<f64> {
        let p = self.params.iter().find(|p| p.name == name)?;
        match &p.values {
            Values::Nums(v) if v.len() == 1 || (v.len() == 3 && v[0] == v[1] && v[1] == v[2]) => Some(v[0]),
            _ => None,
        }
    }

    fn find(&self, name: &str) -> Option<&Param> {
        let p = self.params.iter().find(|p| p.name == name)?;
        p.used.set(true);
        Some(p)
    }

    fn wrong_type(&self, p: &Param, want: &str) -> SceneError {
        SceneError::at(&p.loc, format!("parameter \"{} {}\" of {} should be {want}", p.ty, p.name, self.owner))
    }

    /// Numbers of a parameter declared with one of `types`.
    pub fn nums(&self, name: &str, types: &[&str]) -> Result<Option<&[f64]>, SceneError> {
        let Some(p) = self.find(name) else { return Ok(None) };
        match &p.values {
            Values::Nums(v) if types.contains(&p.ty.as_str()) => Ok(Some(v)),
            _ => Err(self.wrong_type(p, &types.join(" or "))),
        }
    }

    fn single(&self, name: &str, types: &[&str]) -> Result<Option<f64>, SceneError> {
        let Some(v) = self.nums(name, types)? else { return Ok(None) };
        let p = self.params.iter().find(|p| p.name == name).expect("found above");
        match v {
            [x] => Ok(Some(*x)),
            _ => Err(SceneError::at(
                &p.loc,
                format!("parameter {name:?} of {} takes one value, got {}", self.owner, v.len()),
            )),
        }
    }

    /// A float, or `default`.
    pub fn float(&self, name: &str, default: f32) -> Result<f32, SceneError> {
        let v = self.single(name, &["float"])?.map_or(default, |v| v as f32);
        if v.is_finite() {
            Ok(v)
        } else {
            Err(self.invalid(name, "must be finite"))
        }
    }

    /// An integer, or `default`.
    pub fn int(&self, name: &str, default: i64) -> Result<i64, SceneError> {
        match self.single(name, &["integer"])? {
            None => Ok(default),
            Some(v) if v.fract() == 0.0 => Ok(v as i64),
            Some(_) => Err(self.invalid(name, "must be a whole number")),
        }
    }

    /// A string, if given.
    pub fn string(&self, name: &str) -> Result<Option<String>, SceneError> {
        let Some(p) = self.find(name) else { return Ok(None) };
        match (&p.values, p.ty.as_str()) {
            (Values::Strs(v), "string") if v.len() == 1 => Ok(Some(v[0].clone())),
            _ => Err(self.wrong_type(p, "one string")),
        }
    }

    /// A boolean, or `default` (`true`, `false`, `"true"` or `"false"`).
    pub fn bool(&self, name: &str, default: bool) -> Result<bool, SceneError> {
        let Some(p) = self.find(name) else { return Ok(default) };
        match &p.values {
            Values::Bools(v) if v.len() == 1 && p.ty == "bool" => Ok(v[0]),
            Values::Strs(v) if v.len() == 1 && p.ty == "bool" && (v[0] == "true" || v[0] == "false") => {
                Ok(v[0] == "true")
            }
            _ => Err(self.wrong_type(p, "one bool")),
        }
    }

    /// Integers, if given.
    pub fn ints(&self, name: &str) -> Result<Option<Vec<i64>>, SceneError> {
        let Some(v) = self.nums(name, &["integer"])? else { return Ok(None) };
        if v.iter().any(|x| x.fract() != 0.0) {
            return Err(self.invalid(name, "must be whole numbers"));
        }
        Ok(Some(v.iter().map(|x| *x as i64).collect()))
    }

    /// Floats, if given.
    pub fn floats(&self, name: &str) -> Result<Option<Vec<f32>>, SceneError> {
        Ok(self.nums(name, &["float"])?.map(|v| v.iter().map(|x| *x as f32).collect()))
    }

    /// Triples (points, vectors, normals), if given.
    pub fn triples(&self, name: &str, types: &[&str]) -> Result<Option<Vec<Vec3>>, SceneError> {
        let Some(v) = self.nums(name, types)? else { return Ok(None) };
        if v.len() % 3 != 0 {
            return Err(self.invalid(name, &format!("needs a multiple of 3 values, got {}", v.len())));
        }
        Ok(Some(v.chunks_exact(3).map(|c| vec3(c[0] as f32, c[1] as f32, c[2] as f32)).collect()))
    }

    /// Pairs (texture coordinates), if given.
    pub fn pairs(&self, name: &str) -> Result<Option<Vec<[f32; 2]>>, SceneError> {
        let Some(v) = self.nums(name, &["point2", "float"])? else { return Ok(None) };
        if v.len() % 2 != 0 {
            return Err(self.invalid(name, &format!("needs a multiple of 2 values, got {}", v.len())));
        }
        Ok(Some(v.chunks_exact(2).map(|c| [c[0] as f32, c[1] as f32]).collect()))
    }

    /// A spectrum: `rgb`, a named `spectrum` (metals), `blackbody`, or a `texture` reference.
    pub fn spectrum(&self, name: &str) -> Result<Option<SpectrumValue>, SceneError> {
        let Some(p) = self.find(name) else { return Ok(None) };
        match (p.ty.as_str(), &p.values) {
            ("rgb", Values::Nums(v)) if v.len() == 3 => {
                let rgb = vec3(v[0] as f32, v[1] as f32, v[2] as f32);
                if !rgb.is_finite() || rgb.x < 0.0 || rgb.y < 0.0 || rgb.z < 0.0 {
                    return Err(self.invalid(name, "must be finite and not negative"));
                }
                Ok(Some(SpectrumValue::Rgb(rgb)))
            }
            ("spectrum", Values::Strs(v)) if v.len() == 1 => {
                named_spectrum(&v[0]).map(|rgb| Some(SpectrumValue::Rgb(rgb))).ok_or_else(|| {
                    SceneError::at(
                        &p.loc,
                        format!(
                            "unknown named spectrum {:?} (known: {})",
                            v[0],
                            NAMED.iter().map(|n| n.0).collect::<Vec<_>>().join(", ")
                        ),
                    )
                })
            }
            ("blackbody", Values::Nums(v)) if v.len() == 1 => Ok(Some(SpectrumValue::Rgb(blackbody_rgb(v[0] as f32)))),
            ("texture", Values::Strs(v)) if v.len() == 1 => Ok(Some(SpectrumValue::Texture(v[0].clone()))),
            ("float", Values::Nums(v)) if v.len() == 1 && v[0] >= 0.0 => {
                Ok(Some(SpectrumValue::Rgb(Vec3::splat(v[0] as f32))))
            }
            ("spectrum", Values::Nums(v)) => match sampled_spectrum_rgb(v) {
                Some(rgb) => Ok(Some(SpectrumValue::Rgb(rgb))),
                None => Err(self.invalid(
                    name,
                    "must be pairs of increasing wavelength (nm) and non-negative value, or a named spectrum",
                )),
            },
            _ => Err(self.wrong_type(p, "rgb [r g b], a named spectrum, blackbody T, or a texture")),
        }
    }

    /// A float or a float texture reference.
    pub fn float_or_texture(&self, name: &str) -> Result<Option<SpectrumValue>, SceneError> {
        let Some(p) = self.find(name) else { return Ok(None) };
        match (p.ty.as_str(), &p.values) {
            ("float", Values::Nums(v)) if v.len() == 1 && v[0].is_finite() => {
                Ok(Some(SpectrumValue::Rgb(Vec3::splat(v[0] as f32))))
            }
            ("texture", Values::Strs(v)) if v.len() == 1 => Ok(Some(SpectrumValue::Texture(v[0].clone()))),
            _ => Err(self.wrong_type(p, "one float or a float texture")),
        }
    }

    /// An error about parameter `name`, at its location.
    pub fn invalid(&self, name: &str, what: &str) -> SceneError {
        let loc = self.params.iter().find(|p| p.name == name).map_or(&self.loc, |p| &p.loc);
        SceneError::at(loc, format!("parameter {name:?} of {} {what}", self.owner))
    }

    /// Fails on the first parameter that was never looked up.
    pub fn check_unused(&self) -> Result<(), SceneError> {
        match self.params.iter().find(|p| !p.used.get()) {
            None => Ok(()),
            Some(p) => Err(SceneError::at(
                &p.loc,
                format!(
                    "unused parameter \"{} {}\" for {} (not supported by this renderer, or misspelt)",
                    p.ty, p.name, self.owner
                ),
            )),
        }
    }
}

/// RGB approximations of pbrt's named spectra: metals (reflectance-weighted
/// averages over the sRGB primaries' bands) and glasses.
const NAMED: &[(&str, [f32; 3])] = &[
    ("metal-Au-eta", [0.143, 0.374, 1.442]),
    ("metal-Au-k", [3.983, 2.385, 1.603]),
    ("metal-Ag-eta", [0.155, 0.116, 0.138]),
    ("metal-Ag-k", [4.828, 3.122, 2.147]),
    ("metal-Cu-eta", [0.200, 0.924, 1.102]),
    ("metal-Cu-k", [3.912, 2.452, 2.142]),
    ("metal-Al-eta", [1.657, 0.880, 0.521]),
    ("metal-Al-k", [9.224, 6.270, 4.837]),
    ("metal-CuZn-eta", [0.444, 0.527, 1.094]),
    ("metal-CuZn-k", [3.695, 2.765, 1.829]),
    // Magnesium oxide and titanium dioxide (rutile) barely absorb: their
    // "k" is nearly zero.
    ("metal-MgO-eta", [1.732, 1.738, 1.757]),
    ("metal-MgO-k", [0.0, 0.0, 0.0]),
    ("metal-TiO2-eta", [2.583, 2.652, 2.858]),
    ("metal-TiO2-k", [0.0, 0.0, 0.0]),
    // Glasses: the index at the helium d line (587.6 nm), the same in every
    // channel; dispersion is not rendered.
    ("glass-BK7", [1.5168, 1.5168, 1.5168]),
    ("glass-BAF10", [1.6700, 1.6700, 1.6700]),
    ("glass-FK51A", [1.4866, 1.4866, 1.4866]),
    ("glass-LASF9", [1.8503, 1.8503, 1.8503]),
    ("glass-F5", [1.6727, 1.6727, 1.6727]),
    ("glass-F10", [1.7283, 1.7283, 1.7283]),
    ("glass-F11", [1.7847, 1.7847, 1.7847]),
];

fn named_spectrum(name: &str) -> Option<Vec3> {
    NAMED.iter().find(|n| n.0 == name).map(|n| Vec3::from_array(n.1))
}

/// The sRGB primaries' dominant wavelengths (nm): where spectra are read as RGB.
const PRIMARIES_NM: [f64; 3] = [611.0, 549.0, 464.0];

/// An inline sampled spectrum (`"spectrum eta" [λ₀ v₀ λ₁ v₁ …]`) as RGB:
/// its values at the primaries' wavelengths, interpolated linearly (held
/// constant past the ends), as the named spectra are approximated.
fn sampled_spectrum_rgb(v: &[f64]) -> Option<Vec3> {
    if v.len() < 2 || v.len() % 2 != 0 {
        return None;
    }
    let pairs: Vec<(f64, f64)> = v.chunks_exact(2).map(|c| (c[0], c[1])).collect();
    if pairs.windows(2).any(|w| w[1].0 <= w[0].0) || pairs.iter().any(|p| !(p.1 >= 0.0) || !p.0.is_finite()) {
        return None;
    }
    let at = |nm: f64| {
        let i = pairs.partition_point(|p| p.0 < nm);
        match (pairs.get(i.wrapping_sub(1)), pairs.get(i)) {
            (Some(a), Some(b)) => a.1 + (b.1 - a.1) * (nm - a.0) / (b.0 - a.0),
            (Some(a), None) => a.1,
            (None, Some(b)) => b.1,
            (None, None) => 0.0,
        }
    };
    let [r, g, b] = PRIMARIES_NM.map(|nm| at(nm) as f32);
    Some(vec3(r, g, b))
}

/// The colour of a blackbody at `t` kelvin, normalised to a maximum of 1
/// (pbrt's `blackbody` is normalised the same way), in linear sRGB.
pub fn blackbody_rgb(t: f32) -> Vec3 {
    // Planck's law sampled at the sRGB primaries' dominant wavelengths.
    let planck = |lambda_nm: f32| {
        let l = lambda_nm as f64 * 1e-9;
        let (c, h, kb) = (299_792_458.0f64, 6.626_070_15e-34f64, 1.380_649e-23f64);
        (2.0 * h * c * c) / (l.powi(5) * ((h * c / (l * kb * t as f64)).exp() - 1.0))
    };
    let rgb = PRIMARIES_NM.map(|nm| planck(nm as f32));
    let max = rgb.iter().cloned().fold(0.0, f64::max);
    if !(max > 0.0) || !max.is_finite() {
        return Vec3::ZERO;
    }
    vec3((rgb[0] / max) as f32, (rgb[1] / max) as f32, (rgb[2] / max) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sampled_spectrum_is_read_at_the_primaries() {
        // Linear from 400 nm (1) to 700 nm (4): 611 → 3.11, 549 → 2.49, 464 → 1.64.
        let rgb = sampled_spectrum_rgb(&[400.0, 1.0, 700.0, 4.0]).unwrap();
        assert!((rgb.x - 3.11).abs() < 1e-5 && (rgb.y - 2.49).abs() < 1e-5 && (rgb.z - 1.64).abs() < 1e-5, "{rgb:?}");
        // Past the ends the end values hold.
        assert_eq!(sampled_spectrum_rgb(&[620.0, 2.0, 630.0, 3.0]).unwrap(), vec3(2.0, 2.0, 2.0));
        assert!(sampled_spectrum_rgb(&[500.0, 1.0, 400.0, 1.0]).is_none(), "wavelengths must increase");
        assert!(sampled_spectrum_rgb(&[500.0, 1.0, 600.0]).is_none(), "pairs");
    }
}
