//! The runner API's messages: what a runner sends the server and what it
//! gets back. The server (`server/src/routes/runner.rs`) and the runner
//! (`ci-runner/src/api.rs`) serialise these same types.
//!
//! ```text
//! POST /api/v1/runners              Registration → RunnerCredentials
//! POST /api/v1/runners/jobs         ClaimRequest → 200 Claim | 204 none
//! POST /api/v1/runners/status       StatusReport → 204
//! POST /api/v1/runners/references   ReferenceRequest → ReferenceStatus
//!                                    (queues a reference job when none is
//!                                    stored, building or retried yet)
//! GET  /api/v1/runners/references/{key}/files/{name}  a stored reference's
//!                                    file (reference.exr, reference.json,
//!                                    reference-<buffer>.exr)
//! POST /api/v1/jobs/{id}/heartbeat  → Lease
//! POST /api/v1/jobs/{id}/log        text body (appended)
//! PUT  /api/v1/jobs/{id}/files/{*}  a file of the result set
//! GET  /api/v1/jobs/{id}/references/{sha256:hex}  204 if the server holds that
//!                                    reference's pixels, else 404: upload them
//!                                    as files/references/<hex>.fbpx
//! PUT  /api/v1/jobs/{id}/results    Upload
//! POST /api/v1/jobs/{id}/finish     Outcome → Finished
//! ```

use crate::record::FailureReason;
use crate::results::{IndexEntry, MetricInfo};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};
use std::fmt;

/// What a job does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JobKind {
    /// Sanity checks and a sandboxed build (every push).
    Build,
    /// Build, then benchmark on the scene pool (`FBKSD_RUN`).
    Benchmark,
    /// Publish a result (`FBKSD_PUBLISH`): done by the server at once.
    Publish,
    /// Make a scene's reference and upload it, for every runner to download
    /// ([`ReferenceTask`]).
    Reference,
    /// Make some runs of a published result set again with more seeds
    /// ([`MoreSeeds`]): a tie on the board that more seeds could settle.
    Seeds,
}

impl JobKind {
    /// The name as written in the API and the database.
    pub fn as_str(self) -> &'static str {
        match self {
            JobKind::Build => "build",
            JobKind::Benchmark => "benchmark",
            JobKind::Publish => "publish",
            JobKind::Reference => "reference",
            JobKind::Seeds => "seeds",
        }
    }

    /// The kind named `text`, if any.
    pub fn parse(text: &str) -> Option<JobKind> {
        [JobKind::Build, JobKind::Benchmark, JobKind::Publish, JobKind::Reference, JobKind::Seeds]
            .into_iter()
            .find(|k| k.as_str() == text)
    }
}

impl fmt::Display for JobKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Where a job is in its life: `queued` → `running` → `succeeded`,
/// `failed` or `cancelled` (a lost lease puts a running job back in the queue).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JobState {
    /// Waiting for a runner.
    Queued,
    /// A runner holds it.
    Running,
    /// Ended well.
    Succeeded,
    /// Ended with a [`FailureReason`].
    Failed,
    /// Stopped by its author or an administrator.
    Cancelled,
}

impl JobState {
    /// The name as written in the API and the database.
    pub fn as_str(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Running => "running",
            JobState::Succeeded => "succeeded",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
        }
    }

    /// The state named `text`, if any.
    pub fn parse(text: &str) -> Option<JobState> {
        [JobState::Queued, JobState::Running, JobState::Succeeded, JobState::Failed, JobState::Cancelled]
            .into_iter()
            .find(|s| s.as_str() == text)
    }

    /// Whether the job may still change (queued or running).
    pub fn is_live(self) -> bool {
        matches!(self, JobState::Queued | JobState::Running)
    }
}

impl fmt::Display for JobState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A runner's registration.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Registration {
    /// The server's registration token.
    pub registration_token: String,
    /// The runner's name, shown to administrators.
    pub name: String,
    /// What the machine is (cores, CPU model, …), kept with every result.
    #[serde(default)]
    pub machine: serde_json::Value,
}

/// A runner's identity on the server.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RunnerCredentials {
    /// Runner id.
    pub id: String,
    /// Runner token (`fbksdr_…`).
    pub token: String,
}

/// What a runner is doing before it takes jobs.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StatusReport {
    /// What it prepares, for people (e.g. "making reference 3 of 8: …"); `None` when ready.
    pub preparing: Option<String>,
    /// Its machine now, when it says it is ready (its class and calibration
    /// may have changed since it registered).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub machine: Option<serde_json::Value>,
}

/// What a runner can take, and how long the claim may wait on the server.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClaimRequest {
    /// Seconds (capped by the server).
    #[serde(default)]
    pub wait_seconds: u64,
    /// The reference keys ([`crate::scenes::reference_key`]) of the scenes
    /// this runner has: it is handed reference jobs of these keys only
    /// (before any other job).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub reference_keys: Vec<String>,
    /// Only reference jobs (a runner still preparing its scene pool).
    #[serde(default)]
    pub references_only: bool,
    /// The runner's class (fbksd-ci's machine `class`): a benchmark job of
    /// a season whose times come from another class is not handed to it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub runner_class: Option<String>,
    /// Whether it takes seeds jobs ([`JobKind::Seeds`]): runners from
    /// before them could not read the job, and would hold it until its
    /// lease ran out.
    #[serde(default)]
    pub more_seeds: bool,
}

/// A claimed job.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Claim {
    /// The job.
    pub job: ClaimedJob,
    /// The job token (`fbksdj_…`), valid for this attempt only.
    pub token: String,
    /// Clone URL of the technique's repository.
    pub repository: String,
    /// The commit to build.
    pub commit: String,
    /// Lease length: heartbeat well within it.
    pub lease_seconds: u64,
    /// The server's public URL.
    pub results_url: String,
    /// The reference to make, for a reference job.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference: Option<ReferenceTask>,
    /// The runs to make again, for a seeds job.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub more_seeds: Vec<MoreSeeds>,
}

/// A seeds job's run: scene `scene` (its name in the results) at `spp`,
/// made again with the sample seeds `first..end`. Upload those repeats
/// only (no files: the set keeps its first seed's image and log), as one
/// entry per run; the server adds them to the result set.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct MoreSeeds {
    /// Scene, as the result set names it.
    pub scene: String,
    /// Budget.
    pub spp: u64,
    /// The first seed to make.
    pub first: u32,
    /// One past the last seed to make.
    pub end: u32,
}

impl MoreSeeds {
    /// The seeds to make.
    pub fn seeds(&self) -> std::ops::Range<u32> {
        self.first..self.end
    }
}

/// A reference job's task: make the reference of `key` and upload its
/// files (`reference.exr`, `reference.json`, the feature buffers) with
/// `PUT /api/v1/jobs/{id}/files/{name}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReferenceTask {
    /// The reference's key ([`crate::scenes::reference_key`]).
    pub key: String,
    /// The scene, relative to the scene root (`experimental/sphere`).
    pub scene: String,
}

/// A stored reference's image, whatever the scene's metadata names it.
pub const REFERENCE_IMAGE: &str = "reference.exr";
/// A stored reference's note (what made it: its key's parts).
pub const REFERENCE_NOTE: &str = "reference.json";

/// A stored reference's file of the feature buffer `buffer`.
pub fn reference_buffer_file(buffer: &str) -> String {
    format!("reference-{buffer}.exr")
}

/// Whether `name` is one of a stored reference's files.
pub fn is_reference_file(name: &str) -> bool {
    name == REFERENCE_IMAGE
        || name == REFERENCE_NOTE
        || crate::scenes::FEATURE_BUFFERS.iter().any(|b| reference_buffer_file(b) == name)
}

/// A runner's ask for the reference of one of its scenes (at every start,
/// for every scene: the service's reference is the one results are scored
/// against).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferenceRequest {
    /// The reference's key ([`crate::scenes::reference_key`]).
    pub key: String,
    /// The scene, relative to the scene root.
    pub scene: String,
    /// The scene's name as result sets give it
    /// ([`crate::results::path_safe_name`] of its `scene.json` name): a
    /// result set may name this reference only for a scene some runner
    /// asked for it under. Required (empty only from runners older than it,
    /// which the server refuses with a message saying so).
    #[serde(default)]
    pub name: String,
}

/// Where a reference is on the service.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ReferenceState {
    /// A reference job is queued or running.
    Building,
    /// Stored: download its files.
    Ready,
    /// Its last job failed (asking again queues another).
    Failed,
}

/// The server's answer about one reference.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ReferenceStatus {
    /// The reference's key.
    pub key: String,
    /// The scene it was first asked for.
    pub scene: String,
    /// Building, ready or failed.
    pub state: ReferenceState,
    /// SHA-256 of `reference.exr` (`sha256:<hex>`), once ready.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_hash: Option<String>,
    /// The files stored, once ready.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub files: Vec<String>,
    /// The reference job that makes (or made) it.
    pub job_id: String,
    /// The job's message (why it failed).
    #[serde(default)]
    pub message: String,
}

/// The job a runner works on.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ClaimedJob {
    /// Job id.
    pub id: String,
    /// Project (technique) name.
    pub project: String,
    /// Build, benchmark, reference or seeds.
    pub kind: JobKind,
    /// Attempt number (1 for the first claim).
    pub attempts: i64,
    /// The leaderboard season it runs for.
    pub season: i64,
}

/// A lease, extended by a heartbeat.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Lease {
    /// Seconds from now.
    pub lease_seconds: u64,
}

/// How a runner says a job ended.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Outcome {
    /// `succeeded` or `failed`.
    pub state: JobState,
    /// Why, for failures.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<FailureReason>,
    /// What happened, for the user.
    #[serde(default)]
    pub message: String,
}

impl Outcome {
    /// A success.
    pub fn succeeded(message: impl Into<String>) -> Outcome {
        Outcome { state: JobState::Succeeded, reason: None, message: message.into() }
    }
    /// A failure.
    pub fn failed(reason: FailureReason, message: impl Into<String>) -> Outcome {
        Outcome { state: JobState::Failed, reason: Some(reason), message: message.into() }
    }
}

/// The server's answer to a job's end.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Finished {
    /// The result set a benchmark stored.
    pub result_id: Option<String>,
    /// Its private page.
    pub results_url: Option<String>,
}

/// A scene a result set was measured on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneProvenance {
    /// Scene name.
    pub name: String,
    /// Its tags (filters on the leaderboard).
    #[serde(default)]
    pub tags: Vec<String>,
    /// Hash of the scene files.
    pub scene_hash: String,
    /// Hash of the reference image.
    pub reference_hash: String,
}

/// What pins a result set: images, commit, runner, machine and limits.
/// Every field is optional so the server keeps whatever a runner knew.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// Digest of the environment image the technique ran in.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub image_digest: Option<String>,
    /// Every image used, by role (environment name, `renderer`).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub images: BTreeMap<String, ImageRef>,
    /// The technique's commit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub commit: Option<String>,
    /// The technique's version (`info.json`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub version: Option<String>,
    /// The runner's name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub runner: Option<String>,
    /// The runner's id.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub runner_id: Option<String>,
    /// The machine (cores, CPU model, …).
    #[serde(default, skip_serializing_if = "serde_json::Value::is_null")]
    pub machine: serde_json::Value,
    /// The sandbox's limits.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub limits: Option<SandboxLimits>,
    /// The runner's version.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fbksd_ci: Option<String>,
}

/// A container image: tag and content id.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImageRef {
    /// Tag, e.g. `fbksd-env-cpp:…`.
    pub tag: String,
    /// Image id (`sha256:…`).
    pub id: String,
}

/// The limits a technique ran under.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SandboxLimits {
    /// Wall time of one run, seconds.
    pub run_timeout_s: f64,
    /// Memory of one container, MiB.
    pub memory_mib: u64,
    /// Processes of one container.
    pub pids: i64,
}

/// What a runner uploads for a benchmark job.
///
/// Runs are `fbksd results` index entries, so a local results directory and
/// a server result set speak one format. A run's `image` names a file
/// uploaded with `PUT /api/v1/jobs/<id>/files/<name>`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Upload {
    /// One entry per (scene, spp), each with its repeats.
    pub runs: Vec<IndexEntry>,
    /// The metrics the values are in.
    pub metrics: Vec<MetricInfo>,
    /// The scenes.
    pub scenes: Vec<SceneProvenance>,
    /// What pins the runs.
    pub provenance: Provenance,
}

/// The most an upload may hold. Generous for any scene pool (ten scenes
/// at five budgets and three seeds are 150 runs), and small enough that
/// storing one stays quick: the runs go into the database in one
/// transaction.
pub mod limits {
    /// Entries (scene, spp) in `runs`.
    pub const RUNS: usize = 4096;
    /// Repeats (seeds) of one entry.
    pub const REPEATS: usize = 256;
    /// Repeats over all entries.
    pub const ALL_REPEATS: usize = 65_536;
    /// Scenes.
    pub const SCENES: usize = 256;
    /// Metrics.
    pub const METRICS: usize = 64;
    /// Tags of one scene.
    pub const TAGS: usize = 32;
    /// Bytes of a scene's name.
    pub const SCENE_NAME: usize = 100;
    /// Samples per pixel of one run.
    pub const SPP: u64 = 1 << 20;
}

/// Whether `name` is a file name a job may upload or an upload may point
/// at: relative, letters, digits, `.`, `-`, `_` and `/` between non-empty
/// parts, no `..`, at most 200 bytes. Everything the server joins to one of
/// its folders passes this first, so nothing names a file outside it.
pub fn is_upload_file_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 200
        && name.split('/').all(|p| !p.is_empty() && p != "." && p != "..")
        && name.chars().all(|c| c.is_ascii_alphanumeric() || "._-/".contains(c))
}

/// Whether `hash` is `sha256:` and 64 lower-case hex digits.
pub fn is_sha256(hash: &str) -> bool {
    hash.strip_prefix("sha256:")
        .is_some_and(|hex| hex.len() == 64 && hex.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b)))
}

/// A name (scene, tag, metric): 1 to `max` letters, digits, `.`, `-`, `_`,
/// not starting with `.`, as [`crate::results::path_safe_name`] makes them.
pub fn is_plain_name(name: &str, max: usize) -> bool {
    !name.is_empty()
        && name.len() <= max
        && !name.starts_with('.')
        && name.chars().all(|c| c.is_ascii_alphanumeric() || "._-".contains(c))
}

/// Text shown to people: at most `max` characters, no control characters
/// but line breaks and tabs.
fn is_plain_text(text: &str, max: usize) -> bool {
    text.chars().count() <= max && !text.chars().any(|c| c.is_control() && !"\n\r\t".contains(c))
}

impl Upload {
    /// Checks the upload's consistency against the files uploaded before it,
    /// and every field the server stores or shows against its form and
    /// [`limits`]; the message names the first problem and where it is.
    pub fn check(&self, files: &BTreeSet<String>) -> Result<(), String> {
        if self.runs.is_empty() {
            return Err("results: \"runs\" is empty".into());
        }
        let too_many =
            |what: &str, n: usize, max: usize| (n > max).then(|| format!("{n} {what}; at most {max} are stored"));
        let all_repeats: usize = self.runs.iter().map(|r| r.repeats.len()).sum();
        let counts = [
            too_many("runs", self.runs.len(), limits::RUNS),
            too_many("repeats in all", all_repeats, limits::ALL_REPEATS),
            too_many("scenes", self.scenes.len(), limits::SCENES),
            too_many("metrics", self.metrics.len(), limits::METRICS),
        ];
        if let Some(problem) = counts.into_iter().flatten().next() {
            return Err(format!("results: {problem}"));
        }
        for (i, metric) in self.metrics.iter().enumerate() {
            let at = format!("results: metrics[{i}]");
            if !is_plain_name(&metric.acronym, 32) || metric.acronym.contains('.') {
                return Err(format!("{at}: acronym {:?} must be 1 to 32 letters, digits, - or _", metric.acronym));
            }
            if !is_plain_text(&metric.name, 200) || !is_plain_text(&metric.reference, 2000) {
                return Err(format!(
                    "{at} ({}): name or reference too long or with control characters",
                    metric.acronym
                ));
            }
        }
        for (i, scene) in self.scenes.iter().enumerate() {
            let at = format!("results: scenes[{i}]");
            if !is_plain_name(&scene.name, limits::SCENE_NAME) {
                let max = limits::SCENE_NAME;
                return Err(format!("{at}: name {:?} must be 1 to {max} letters, digits, . - or _", scene.name));
            }
            let at = format!("{at} ({})", scene.name);
            if let Some(problem) = too_many("tags", scene.tags.len(), limits::TAGS) {
                return Err(format!("{at}: {problem}"));
            }
            if let Some(tag) = scene.tags.iter().find(|t| !is_plain_name(t, 40)) {
                return Err(format!("{at}: tag {tag:?} must be 1 to 40 letters, digits, . - or _"));
            }
            for (field, hash) in [("scene_hash", &scene.scene_hash), ("reference_hash", &scene.reference_hash)] {
                if !is_sha256(hash) {
                    return Err(format!("{at}: {field} {hash:?} is not sha256:<64 lower-case hex digits>"));
                }
            }
        }
        let scenes: BTreeSet<&str> = self.scenes.iter().map(|s| s.name.as_str()).collect();
        let metrics: BTreeSet<&str> = self.metrics.iter().map(|m| m.acronym.as_str()).collect();
        let file = |at: &str, field: &str, name: &str| {
            if is_upload_file_name(name) {
                Ok(())
            } else {
                Err(format!("{at}: {field} {name:?} is not a relative path of letters, digits, . - _ and / (no ..)"))
            }
        };
        let mut seen = BTreeSet::new();
        for (i, run) in self.runs.iter().enumerate() {
            let at = format!("results: runs[{i}] ({} at {} spp)", run.scene, run.spp);
            if !scenes.contains(run.scene.as_str()) {
                return Err(format!("{at}: scene {:?} is not in \"scenes\"", run.scene));
            }
            if run.spp == 0 || run.spp > limits::SPP {
                return Err(format!("{at}: spp must be 1 to {}", limits::SPP));
            }
            if !seen.insert((run.scene.as_str(), run.spp)) {
                return Err(format!("{at}: appears twice"));
            }
            if let Some(problem) = too_many("repeats", run.repeats.len(), limits::REPEATS) {
                return Err(format!("{at}: {problem}"));
            }
            if !run.log.is_empty() {
                file(&at, "log", &run.log)?;
            }
            for (metric, value) in &run.metrics {
                if !metrics.contains(metric.as_str()) {
                    return Err(format!("{at}: metric {metric:?} is not in \"metrics\""));
                }
                if !value.is_finite() {
                    return Err(format!("{at}: {metric} is {value}; only finite values are stored"));
                }
            }
            if !run.technique_ms.is_finite() || !run.render_ms.is_finite() {
                return Err(format!("{at}: times must be finite"));
            }
            if let Some(image) = &run.image {
                file(&at, "image", image)?;
                if !files.contains(image) {
                    return Err(format!("{at}: image {image:?} was not uploaded"));
                }
            }
            let mut seeds = BTreeSet::new();
            for (k, repeat) in run.repeats.iter().enumerate() {
                let at = format!("{at}: repeats[{k}]");
                if !seeds.insert(repeat.seed) {
                    return Err(format!("{at}: seed {} appears twice", repeat.seed));
                }
                if !repeat.log.is_empty() {
                    file(&at, "log", &repeat.log)?;
                }
                if let Some(image) = &repeat.image {
                    file(&at, "image", image)?;
                }
                for (metric, value) in &repeat.metrics {
                    if !metrics.contains(metric.as_str()) {
                        return Err(format!("{at}: metric {metric:?} is not in \"metrics\""));
                    }
                    if !value.is_finite() {
                        return Err(format!("{at}: {metric} is {value}; only finite values are stored"));
                    }
                }
                let times = [repeat.technique_ms, repeat.render_ms, repeat.wall_ms, repeat.cpu_ms, repeat.waiting_ms];
                if times.iter().any(|t| !t.is_finite() || *t < 0.0) {
                    return Err(format!("{at}: times must be finite and not negative"));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for s in [JobState::Queued, JobState::Running, JobState::Succeeded, JobState::Failed, JobState::Cancelled] {
            assert_eq!(JobState::parse(s.as_str()), Some(s));
            assert_eq!(serde_json::to_value(s).unwrap(), s.as_str());
        }
        for k in [JobKind::Build, JobKind::Benchmark, JobKind::Publish, JobKind::Reference, JobKind::Seeds] {
            assert_eq!(JobKind::parse(k.as_str()), Some(k));
            assert_eq!(serde_json::to_value(k).unwrap(), k.as_str());
        }
        assert_eq!(JobState::parse("canceled"), None);
    }

    #[test]
    fn an_outcome_reads_as_the_server_documents_it() {
        let o: Outcome = serde_json::from_str(r#"{"state":"failed","reason":"build_failed","message":"x"}"#).unwrap();
        assert_eq!((o.state, o.reason), (JobState::Failed, Some(FailureReason::BuildFailed)));
        let bad = serde_json::from_str::<Outcome>(r#"{"state":"done"}"#).unwrap_err().to_string();
        assert!(bad.contains("unknown variant `done`"), "{bad}");
    }
}
