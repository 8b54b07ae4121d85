//! Metrics as external programs (thesis A.3): a directory holding an
//! `info.json` in the original IQA format —
//! `{"acronym", "name", "reference", "lower_is_better", "has_error_map",
//! "executable"}` — and the executable, called as
//! `<exe> [--map-file map.png] <reference.exr> <test.exr>`; it prints its
//! value on stdout as a JSON number, an object with a `"value"` field, or
//! the original's `{"<acronym>": value}`.
//! `fbksd iqa <METRIC>` exposes the built-in metrics the same way.

use crate::{IqaError, MetricInfo};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// How long an external metric may run on one pair of images.
pub const TIME_LIMIT: Duration = Duration::from_secs(600);

/// An external metric.
#[derive(Debug, Clone)]
pub struct ExternalMetric {
    /// What it is.
    pub info: MetricInfo,
    /// The program.
    pub executable: PathBuf,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct InfoFile {
    acronym: String,
    name: String,
    #[serde(default)]
    reference: String,
    lower_is_better: bool,
    has_error_map: bool,
    executable: String,
}

impl ExternalMetric {
    /// Loads a metric directory.
    pub fn load(dir: &Path) -> Result<ExternalMetric, IqaError> {
        let file = dir.join("info.json");
        let text =
            std::fs::read_to_string(&file).map_err(|e| IqaError::External(format!("{}: {e}", file.display())))?;
        let info: InfoFile =
            serde_json::from_str(&text).map_err(|e| IqaError::External(format!("{}: {e}", file.display())))?;
        if info.acronym.is_empty() || !info.acronym.chars().all(|c| c.is_ascii_alphanumeric() || "-_".contains(c)) {
            return Err(IqaError::External(format!(
                "{}: acronym {:?} must be letters, digits, - or _",
                file.display(),
                info.acronym
            )));
        }
        let executable = dir.join(&info.executable);
        if !executable.is_file() {
            return Err(IqaError::External(format!(
                "{}: executable {} does not exist",
                file.display(),
                executable.display()
            )));
        }
        Ok(ExternalMetric {
            info: MetricInfo {
                acronym: info.acronym,
                name: info.name,
                reference: info.reference,
                lower_is_better: info.lower_is_better,
                has_error_map: info.has_error_map,
            },
            executable,
        })
    }

    /// Runs the metric on two EXR files; writes its map when asked and it has one.
    pub fn run(&self, reference: &Path, test: &Path, map_file: Option<&Path>) -> Result<f64, IqaError> {
        let mut command = Command::new(&self.executable);
        if let (Some(map), true) = (map_file, self.info.has_error_map) {
            command.arg("--map-file").arg(map);
        }
        command.arg(reference).arg(test).stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped());
        let who = format!("metric {} ({})", self.info.acronym, self.executable.display());
        let mut child = command.spawn().map_err(|e| IqaError::External(format!("{who}: cannot start: {e}")))?;
        let deadline = Instant::now() + TIME_LIMIT;
        loop {
            if child.try_wait()?.is_some() {
                break;
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                return Err(IqaError::External(format!("{who}: still running after {TIME_LIMIT:?}; killed")));
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let output = child.wait_with_output()?;
        let stdout = String::from_utf8_lossy(&output.stdout);
        if !output.status.success() {
            return Err(IqaError::External(format!(
                "{who}: failed ({}): {}",
                output.status,
                String::from_utf8_lossy(&output.stderr).trim()
            )));
        }
        parse_value(&stdout).ok_or_else(|| {
            IqaError::External(format!(
                "{who}: expected a JSON number or {{\"value\": …}} on stdout, got {:?}",
                stdout.trim()
            ))
        })
    }
}

/// A value printed by a metric: a JSON number, an object with `"value"`,
/// or the original format `{"<acronym>": value}` (one key).
pub fn parse_value(stdout: &str) -> Option<f64> {
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).ok()?;
    match v {
        serde_json::Value::Number(n) => n.as_f64(),
        serde_json::Value::Object(o) if o.len() == 1 => o.values().next()?.as_f64(),
        serde_json::Value::Object(o) => o.get("value")?.as_f64(),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_are_numbers_or_objects() {
        assert_eq!(parse_value("0.25\n"), Some(0.25));
        assert_eq!(parse_value(r#"{"value": 3, "extra": 1}"#), Some(3.0));
        assert_eq!(parse_value(r#"{"My-MSE": 0.5}"#), Some(0.5), "the original format");
        assert_eq!(parse_value("nope"), None);
        assert_eq!(parse_value(r#"{"v": 1, "w": 2}"#), None);
        assert_eq!(parse_value(r#"{"v": "one"}"#), None);
    }
}
