//! Scene information: a map from keys to typed values.
//!
//! Every renderer reports the standard keys (see [`keys`]); it may add any
//! other key. On the wire a `SceneInfo` is a JSON object whose values are
//! JSON booleans, integers, floats (always written with a fraction or an
//! exponent) or strings, so integer and float values keep their type.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt;

/// The standard keys every renderer reports.
pub mod keys {
    /// Image width in pixels (int).
    pub const WIDTH: &str = "width";
    /// Image height in pixels (int).
    pub const HEIGHT: &str = "height";
    /// The technique's budget in samples per pixel (int). Set by the manager.
    pub const MAX_SPP: &str = "max_spp";
    /// The technique's budget in samples: max_spp × width × height (int). Set by the manager.
    pub const MAX_SAMPLES: &str = "max_samples";
    /// Whether the scene has motion blur (bool).
    pub const HAS_MOTION_BLUR: &str = "has_motion_blur";
    /// Whether the scene has depth of field (bool).
    pub const HAS_DOF: &str = "has_dof";
    /// Shutter open time (float).
    pub const SHUTTER_OPEN: &str = "shutter_open";
    /// Shutter close time (float).
    pub const SHUTTER_CLOSE: &str = "shutter_close";
}

/// One value of scene information.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum SceneValue {
    /// A boolean.
    Bool(bool),
    /// An integer.
    Int(i64),
    /// A floating-point number.
    Float(f64),
    /// A string.
    String(String),
}

impl SceneValue {
    fn type_name(&self) -> &'static str {
        match self {
            SceneValue::Bool(_) => "bool",
            SceneValue::Int(_) => "int",
            SceneValue::Float(_) => "float",
            SceneValue::String(_) => "string",
        }
    }
}

impl fmt::Display for SceneValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SceneValue::Bool(b) => write!(f, "{b}"),
            SceneValue::Int(i) => write!(f, "{i}"),
            SceneValue::Float(x) => write!(f, "{x}"),
            SceneValue::String(s) => write!(f, "{s:?}"),
        }
    }
}

/// A missing key or a value of another type.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SceneInfoError {
    /// The key is not in the scene info.
    #[error("scene info has no key {key:?} (keys: {available})")]
    Missing {
        /// The key asked for.
        key: String,
        /// The keys present, comma-separated.
        available: String,
    },
    /// The key holds a value of another type.
    #[error("scene info key {key:?} is a {found} ({value}), not a {expected}")]
    WrongType {
        /// The key asked for.
        key: String,
        /// The type asked for.
        expected: &'static str,
        /// The type present.
        found: &'static str,
        /// The value present.
        value: String,
    },
}

/// A Rust type that a scene value can be read as.
pub trait FromSceneValue: Sized {
    /// Name of the type in error messages.
    const TYPE_NAME: &'static str;
    /// Converts, or `None` when the value has another type.
    fn from_scene_value(v: &SceneValue) -> Option<Self>;
}

impl FromSceneValue for i64 {
    const TYPE_NAME: &'static str = "int";
    fn from_scene_value(v: &SceneValue) -> Option<Self> {
        match v {
            SceneValue::Int(i) => Some(*i),
            _ => None,
        }
    }
}

impl FromSceneValue for f64 {
    const TYPE_NAME: &'static str = "float";
    /// Integers widen to floats; floats never narrow to integers.
    fn from_scene_value(v: &SceneValue) -> Option<Self> {
        match v {
            SceneValue::Float(x) => Some(*x),
            SceneValue::Int(i) => Some(*i as f64),
            _ => None,
        }
    }
}

impl FromSceneValue for f32 {
    const TYPE_NAME: &'static str = "float";
    fn from_scene_value(v: &SceneValue) -> Option<Self> {
        f64::from_scene_value(v).map(|x| x as f32)
    }
}

impl FromSceneValue for bool {
    const TYPE_NAME: &'static str = "bool";
    fn from_scene_value(v: &SceneValue) -> Option<Self> {
        match v {
            SceneValue::Bool(b) => Some(*b),
            _ => None,
        }
    }
}

impl FromSceneValue for String {
    const TYPE_NAME: &'static str = "string";
    fn from_scene_value(v: &SceneValue) -> Option<Self> {
        match v {
            SceneValue::String(s) => Some(s.clone()),
            _ => None,
        }
    }
}

/// Information about the scene being rendered.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct SceneInfo {
    values: BTreeMap<String, SceneValue>,
}

impl SceneInfo {
    /// An empty scene info.
    pub fn new() -> Self {
        Self::default()
    }

    /// Sets a value, replacing any previous one.
    pub fn set(&mut self, key: &str, value: impl Into<SceneValue>) -> &mut Self {
        self.values.insert(key.to_string(), value.into());
        self
    }

    /// The raw value of a key.
    pub fn value(&self, key: &str) -> Option<&SceneValue> {
        self.values.get(key)
    }

    /// Whether a key exists and can be read as `T`.
    pub fn has<T: FromSceneValue>(&self, key: &str) -> bool {
        self.values.get(key).and_then(T::from_scene_value).is_some()
    }

    /// Reads a key as `T`.
    pub fn get<T: FromSceneValue>(&self, key: &str) -> Result<T, SceneInfoError> {
        let value = self.values.get(key).ok_or_else(|| SceneInfoError::Missing {
            key: key.to_string(),
            available: self.values.keys().cloned().collect::<Vec<_>>().join(", "),
        })?;
        T::from_scene_value(value).ok_or_else(|| SceneInfoError::WrongType {
            key: key.to_string(),
            expected: T::TYPE_NAME,
            found: value.type_name(),
            value: value.to_string(),
        })
    }

    /// Image width, checked to be positive.
    pub fn width(&self) -> Result<u32, SceneInfoError> {
        self.positive_dimension(keys::WIDTH)
    }

    /// Image height, checked to be positive.
    pub fn height(&self) -> Result<u32, SceneInfoError> {
        self.positive_dimension(keys::HEIGHT)
    }

    fn positive_dimension(&self, key: &str) -> Result<u32, SceneInfoError> {
        let v = self.get::<i64>(key)?;
        u32::try_from(v).ok().filter(|v| *v > 0).ok_or_else(|| SceneInfoError::WrongType {
            key: key.to_string(),
            expected: "positive int below 2^32",
            found: "int",
            value: v.to_string(),
        })
    }

    /// All keys and values, sorted by key.
    pub fn iter(&self) -> impl Iterator<Item = (&str, &SceneValue)> {
        self.values.iter().map(|(k, v)| (k.as_str(), v))
    }

    /// This info with every item of `other` added (other wins on conflicts).
    pub fn merged(&self, other: &SceneInfo) -> SceneInfo {
        let mut out = self.clone();
        out.values.extend(other.values.iter().map(|(k, v)| (k.clone(), v.clone())));
        out
    }
}

impl From<bool> for SceneValue {
    fn from(v: bool) -> Self {
        SceneValue::Bool(v)
    }
}
impl From<i64> for SceneValue {
    fn from(v: i64) -> Self {
        SceneValue::Int(v)
    }
}
impl From<i32> for SceneValue {
    fn from(v: i32) -> Self {
        SceneValue::Int(v as i64)
    }
}
impl From<u32> for SceneValue {
    fn from(v: u32) -> Self {
        SceneValue::Int(v as i64)
    }
}
impl From<f64> for SceneValue {
    fn from(v: f64) -> Self {
        SceneValue::Float(v)
    }
}
impl From<f32> for SceneValue {
    fn from(v: f32) -> Self {
        SceneValue::Float(v as f64)
    }
}
impl From<&str> for SceneValue {
    fn from(v: &str) -> Self {
        SceneValue::String(v.to_string())
    }
}
impl From<String> for SceneValue {
    fn from(v: String) -> Self {
        SceneValue::String(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn info() -> SceneInfo {
        let mut i = SceneInfo::new();
        i.set("width", 640).set("has_dof", true).set("shutter_open", 0.25).set("name", "box");
        i
    }

    #[test]
    fn typed_access() {
        let i = info();
        assert_eq!(i.get::<i64>("width"), Ok(640));
        assert_eq!(i.get::<f64>("width"), Ok(640.0), "ints widen to floats");
        assert_eq!(i.get::<bool>("has_dof"), Ok(true));
        assert_eq!(i.get::<f32>("shutter_open"), Ok(0.25));
        assert_eq!(i.get::<String>("name"), Ok("box".into()));
        assert!(i.has::<i64>("width") && !i.has::<bool>("width") && !i.has::<i64>("nope"));
    }

    #[test]
    fn missing_key_lists_what_exists() {
        let e = info().get::<i64>("height").unwrap_err().to_string();
        assert!(e.contains("\"height\"") && e.contains("width"), "{e}");
    }

    #[test]
    fn wrong_type_says_both_types() {
        let e = info().get::<i64>("shutter_open").unwrap_err().to_string();
        assert!(e.contains("float") && e.contains("not a int") && e.contains("0.25"), "{e}");
    }

    #[test]
    fn json_keeps_int_and_float_apart() {
        let mut i = SceneInfo::new();
        i.set("a", 1).set("b", 1.0).set("c", false);
        let text = serde_json::to_string(&i).unwrap();
        assert_eq!(text, r#"{"a":1,"b":1.0,"c":false}"#);
        let back: SceneInfo = serde_json::from_str(&text).unwrap();
        assert_eq!(back, i);
    }

    #[test]
    fn dimensions_must_be_positive() {
        let mut i = SceneInfo::new();
        i.set("width", 0).set("height", -3);
        assert!(i.width().is_err() && i.height().is_err());
    }
}
