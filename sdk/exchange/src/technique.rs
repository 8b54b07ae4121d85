//! A technique repository's `info.json`: the original FBKSD format
//! (`short_name`, `full_name`, `comment`, `citation`, `versions`, and the
//! online `technique_type`) plus `environment`, the image that builds it.
//!
//! [`TechniqueInfo::parse`] checks the schema and reports every problem with
//! the key it concerns, so a user can fix a repository from the message
//! alone; [`TechniqueInfo::check_repository`] checks that the build file the
//! environment needs is there.

use serde::{Deserialize, Serialize};

/// What a technique does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TechniqueType {
    /// Reconstructs an image from samples it does not choose.
    Denoiser,
    /// Chooses sample positions.
    Sampler,
    /// Chooses samples and reconstructs.
    Adaptive,
}

/// The environment (container image) a technique is built and run in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Environment {
    /// gcc, CMake and the C/C++ SDK: the repository needs a `CMakeLists.txt`.
    Cpp,
    /// Python 3, numpy and the Python SDK: each version's executable is a
    /// Python script in the repository.
    Python,
}

impl Environment {
    /// The name used in `info.json` and image tags.
    pub fn as_str(self) -> &'static str {
        match self {
            Environment::Cpp => "cpp",
            Environment::Python => "python",
        }
    }
}

/// One version of a technique (a variant with its own executable).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Version {
    /// Version name, e.g. `default`.
    pub name: String,
    /// What distinguishes it.
    #[serde(default)]
    pub comment: String,
    /// Program to run, relative to the install directory.
    pub executable: String,
}

/// A parsed and checked `info.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TechniqueInfo {
    /// Short name: lower-case letters, digits, `-` and `_`.
    pub short_name: String,
    /// Name shown on pages.
    pub full_name: String,
    /// One-paragraph description.
    pub comment: String,
    /// How to cite it.
    pub citation: String,
    /// Denoiser, sampler or adaptive.
    pub technique_type: TechniqueType,
    /// Where it is built and run.
    pub environment: Environment,
    /// At least one version.
    pub versions: Vec<Version>,
}

/// The file as written, before checks.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInfo {
    short_name: Option<String>,
    full_name: Option<String>,
    #[serde(default)]
    comment: String,
    #[serde(default)]
    citation: String,
    technique_type: Option<String>,
    environment: Option<String>,
    #[serde(default)]
    versions: Vec<Version>,
}

/// Whether `name` is a valid short name (also used for project names).
pub fn is_valid_short_name(name: &str) -> bool {
    (1..=64).contains(&name.len())
        && name.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-' || c == '_')
        && name.starts_with(|c: char| c.is_ascii_alphanumeric())
}

impl TechniqueInfo {
    /// Parses `info.json` text. `files` lists the repository's paths, to
    /// infer the environment when `info.json` does not name one (a
    /// `CMakeLists.txt` means `cpp`; Python scripts only mean `python`).
    pub fn parse(text: &str, files: &[String]) -> Result<TechniqueInfo, String> {
        let raw: RawInfo = serde_json::from_str(text).map_err(|e| format!("info.json: {e}"))?;
        // Where a key is written, so its error names the line as well as the key.
        let at = |key: &str| match text.lines().position(|line| line.contains(&format!("\"{key}\""))) {
            Some(i) => format!("info.json line {}", i + 1),
            None => "info.json".to_string(),
        };
        let short_name = raw.short_name.ok_or("info.json: \"short_name\" is missing")?;
        if !is_valid_short_name(&short_name) {
            return Err(format!(
                "{}: \"short_name\" {short_name:?} must be 1 to 64 lower-case letters, digits, '-' or '_', \
                 starting with a letter or digit",
                at("short_name")
            ));
        }
        let full_name = raw.full_name.unwrap_or_else(|| short_name.clone());
        if full_name.trim().is_empty() || full_name.chars().count() > 200 {
            return Err(format!("{}: \"full_name\" must be 1 to 200 characters", at("full_name")));
        }
        let technique_type = match raw.technique_type.as_deref().map(str::to_ascii_lowercase).as_deref() {
            Some("denoiser") => TechniqueType::Denoiser,
            Some("sampler") => TechniqueType::Sampler,
            Some("adaptive") => TechniqueType::Adaptive,
            Some(other) => {
                return Err(format!(
                    "{}: \"technique_type\" {other:?} is unknown: use \"denoiser\", \"sampler\" or \"adaptive\"",
                    at("technique_type")
                ))
            }
            None => {
                return Err("info.json: \"technique_type\" is missing: \"denoiser\", \"sampler\" or \"adaptive\"".into())
            }
        };
        let versions = if raw.versions.is_empty() {
            vec![Version { name: "default".into(), comment: String::new(), executable: short_name.clone() }]
        } else {
            raw.versions
        };
        for (i, v) in versions.iter().enumerate() {
            if v.name.trim().is_empty() || v.executable.trim().is_empty() {
                return Err(format!("{}: versions[{i}] needs a \"name\" and an \"executable\"", at("versions")));
            }
            if v.executable.starts_with('/') || v.executable.split('/').any(|part| part == "..") {
                return Err(format!(
                    "{}: versions[{i}].executable {:?} must be a path inside the install directory",
                    at("executable"),
                    v.executable
                ));
            }
        }
        let has = |path: &str| files.iter().any(|f| f == path);
        let environment = match raw.environment.as_deref() {
            Some(name) => Environment::named(name).ok_or_else(|| {
                format!(
                    "{}: \"environment\" {name:?} is unknown: use {} (their contents: /environments)",
                    at("environment"),
                    Environment::choices()
                )
            })?,
            None if has("CMakeLists.txt") => Environment::Cpp,
            None if versions.iter().all(|v| v.executable.ends_with(".py")) => Environment::Python,
            None => {
                return Err("info.json: say which environment builds this technique: \
                            \"environment\": \"cpp\" (CMake) or \"python\""
                    .into())
            }
        };
        let info = TechniqueInfo {
            short_name,
            full_name,
            comment: raw.comment,
            citation: raw.citation,
            technique_type,
            environment,
            versions,
        };
        info.check_repository(files)?;
        Ok(info)
    }

    /// Checks that the files the environment needs are in the repository.
    pub fn check_repository(&self, files: &[String]) -> Result<(), String> {
        let has = |path: &str| files.iter().any(|f| f == path);
        match self.environment {
            Environment::Cpp if !has("CMakeLists.txt") => {
                Err("the cpp environment builds with CMake: add a CMakeLists.txt at the repository's root".into())
            }
            Environment::Python => match self.versions.iter().find(|v| !has(&v.executable)) {
                Some(v) => Err(format!(
                    "version {:?} runs {:?}, which is not in the repository (the python environment installs \
                     the repository as it is)",
                    v.name, v.executable
                )),
                None => Ok(()),
            },
            _ => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn files(list: &[&str]) -> Vec<String> {
        list.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn the_shipped_techniques_parse() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../techniques");
        for (dir, env) in [("box-filter-cpp", Environment::Cpp), ("box-filter-python", Environment::Python)] {
            let text = std::fs::read_to_string(root.join(dir).join("info.json")).unwrap();
            let listing: Vec<String> = std::fs::read_dir(root.join(dir))
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            let info = TechniqueInfo::parse(&text, &listing).unwrap();
            assert_eq!(info.short_name, dir);
            assert_eq!(info.environment, env);
        }
    }

    #[test]
    fn each_problem_names_its_key() {
        let cmake = files(&["CMakeLists.txt"]);
        let cases = [
            ("{", "info.json: EOF"),
            (r#"{"full_name": "x", "technique_type": "sampler"}"#, "\"short_name\" is missing"),
            (r#"{"short_name": "Bad Name", "technique_type": "sampler"}"#, "\"short_name\" \"Bad Name\""),
            (r#"{"short_name": "a"}"#, "\"technique_type\" is missing"),
            (r#"{"short_name": "a", "technique_type": "filter"}"#, "\"filter\" is unknown"),
            (r#"{"short_name": "a", "technique_type": "sampler", "enviroment": "cpp"}"#, "unknown field `enviroment`"),
            (r#"{"short_name": "a", "technique_type": "sampler", "environment": "rust"}"#, "\"rust\" is unknown"),
            (
                r#"{"short_name": "a", "technique_type": "sampler", "versions": [{"name": "v", "executable": "../x"}]}"#,
                "must be a path inside",
            ),
        ];
        for (text, expected) in cases {
            let error = TechniqueInfo::parse(text, &cmake).unwrap_err();
            assert!(error.contains(expected), "{text}: {error}");
        }
        let error = TechniqueInfo::parse(r#"{"short_name": "a", "technique_type": "sampler"}"#, &[]).unwrap_err();
        assert!(error.contains("say which environment"), "{error}");
        // A key's problem names the line it is written on.
        let error = TechniqueInfo::parse("{\n  \"short_name\": \"a\",\n  \"technique_type\": \"filter\"\n}", &cmake)
            .unwrap_err();
        assert!(error.starts_with("info.json line 3: \"technique_type\""), "{error}");
        let error =
            TechniqueInfo::parse(r#"{"short_name": "a", "technique_type": "sampler", "environment": "cpp"}"#, &[])
                .unwrap_err();
        assert!(error.contains("CMakeLists.txt"), "{error}");
        let python =
            r#"{"short_name": "a", "technique_type": "DENOISER", "versions": [{"name": "v", "executable": "a.py"}]}"#;
        assert!(TechniqueInfo::parse(python, &[]).unwrap_err().contains("\"a.py\", which is not in the repository"));
        assert_eq!(TechniqueInfo::parse(python, &files(&["a.py"])).unwrap().environment, Environment::Python);
    }
}
