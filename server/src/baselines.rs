//! The baselines: the published techniques every submission is compared
//! with from the first day. `fbksd-server baselines [LIST]` submits each
//! technique repository listed in LIST (default
//! `sdk/techniques/baselines.txt`) under the `baselines` service account by
//! the path a researcher takes: a public project, `git push -o FBKSD_RUN`,
//! and `FBKSD_PUBLISH` of the result set the run made. It waits until every
//! one is on the board (or has failed, with its job's page named).
//!
//! Only the account is made in the database (verified without mail, exempt
//! from quotas, its jobs waiting while any user's is queued: see
//! [`crate::accounts::ensure_service_account`]); everything else goes
//! through the running server's HTTP API and git endpoint. A baseline
//! already published in the current season is skipped, so the command is
//! safe to run at every start; a new season re-runs them like any published
//! technique.

use crate::config::Config;
use anyhow::{anyhow, bail, Context};
use base64::Engine;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The service account's address.
pub const ACCOUNT: &str = "baselines@localhost.localdomain";

/// One listed technique repository; its project is named after its folder.
#[derive(Debug, Clone, PartialEq)]
pub struct Baseline {
    /// The project name.
    pub name: String,
    /// The repository's folder.
    pub dir: PathBuf,
}

/// Reads a list: one folder per line (relative to the list's folder, or
/// absolute), `#` comments. Each folder must hold an `info.json`, and its
/// name must be a valid project name.
pub fn read_list(list: &Path) -> anyhow::Result<Vec<Baseline>> {
    let text = std::fs::read_to_string(list).with_context(|| format!("baselines list {}", list.display()))?;
    let base = list.parent().unwrap_or(Path::new("."));
    let mut baselines = Vec::new();
    for (number, line) in text.lines().enumerate() {
        let entry = line.split('#').next().unwrap_or("").trim();
        if entry.is_empty() {
            continue;
        }
        let at = format!("{}:{}", list.display(), number + 1);
        let dir = base.join(entry);
        if !dir.join("info.json").is_file() {
            bail!("{at}: {} holds no info.json", dir.display());
        }
        let name = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        crate::projects::ProjectName::parse(&name).map_err(|e| anyhow!("{at}: {}", e.message))?;
        if baselines.iter().any(|b: &Baseline| b.name == name) {
            bail!("{at}: {name} is listed twice");
        }
        baselines.push(Baseline { name, dir });
    }
    Ok(baselines)
}

/// Submits every baseline of `list` to the server at `url` (default: the
/// configured bind address) and waits for each; an error names those that
/// failed.
pub async fn submit(config: &Config, list: &Path, url: Option<String>) -> anyhow::Result<()> {
    let baselines = read_list(list)?;
    let url = url.unwrap_or_else(|| local_url(&config.bind)).trim_end_matches('/').to_string();
    let pool = crate::db::connect(&config.database_url()).await.map_err(|e| anyhow!("database: {e}"))?;
    let email = crate::accounts::Email::parse(ACCOUNT).map_err(|e| anyhow!("{}", e.message))?;
    let account = crate::accounts::ensure_service_account(&pool, &email).await.map_err(|e| anyhow!("{}", e.message))?;
    crate::accounts::revoke_all_access_tokens(&pool, &account.id).await?;
    let (_, token) = crate::accounts::create_access_token(&pool, &account.id, "baselines")
        .await
        .map_err(|e| anyhow!("{}", e.message))?;
    let season = crate::results::current_season(&pool).await?;
    let api = Api { http: reqwest::Client::new(), url, token, season };

    let mut waiting = Vec::new();
    let mut failed = Vec::new();
    for baseline in &baselines {
        match api.start(baseline, &account.id).await {
            Ok(Some(job)) => waiting.push((baseline, job)),
            Ok(None) => println!("baselines: {} is on the board", baseline.name),
            Err(e) => failed.push(format!("{}: {e:#}", baseline.name)),
        }
    }
    for (baseline, job) in waiting {
        match api.publish_when_done(baseline, &job).await {
            Ok(page) => println!("baselines: {} published: {page}", baseline.name),
            Err(e) => failed.push(format!("{}: {e:#}", baseline.name)),
        }
    }
    // The token is this command's alone: it ends with it.
    crate::accounts::revoke_all_access_tokens(&pool, &account.id).await?;
    pool.close().await;
    if !failed.is_empty() {
        bail!("{} of {} baselines are not on the board:\n{}", failed.len(), baselines.len(), failed.join("\n"));
    }
    Ok(())
}

/// `http://host:port` for a bind address; an unspecified host is this machine.
fn local_url(bind: &str) -> String {
    let (host, port) = bind.rsplit_once(':').unwrap_or((bind, "8096"));
    let host = match host {
        "" | "0.0.0.0" => "127.0.0.1",
        "[::]" => "[::1]",
        other => other,
    };
    format!("http://{host}:{port}")
}

/// The server's API as the baselines account.
struct Api {
    http: reqwest::Client,
    url: String,
    token: String,
    /// The leaderboard season a baseline must be published in.
    season: i64,
}

impl Api {
    async fn call(&self, request: reqwest::RequestBuilder) -> anyhow::Result<Value> {
        let response = request.bearer_auth(&self.token).send().await?;
        let status = response.status();
        let body: Value = response.json().await.unwrap_or(Value::Null);
        if !status.is_success() {
            bail!("{status}: {}", body["message"].as_str().unwrap_or("no message"));
        }
        Ok(body)
    }

    /// Pushes `baseline` with FBKSD_RUN unless it is on the current board;
    /// the benchmark job to wait for. A job an earlier start left (queued,
    /// running, or done but not yet published) is taken up, not repeated.
    async fn start(&self, baseline: &Baseline, account: &str) -> anyhow::Result<Option<String>> {
        let project = self.http.get(format!("{}/api/v1/projects/{}", self.url, baseline.name));
        match self.call(project).await {
            Ok(project) => {
                if project["owner_id"] != account {
                    bail!("the project name is taken by another account");
                }
                let results = project["results"].as_array().cloned().unwrap_or_default();
                let this_season = |r: &&Value| r["season"].as_i64() == Some(self.season);
                if results.iter().filter(this_season).any(|r| !r["published_at"].is_null()) {
                    return Ok(None);
                }
                let unpublished: Vec<&Value> = results.iter().filter(this_season).map(|r| &r["id"]).collect();
                let jobs = project["jobs"].as_array().cloned().unwrap_or_default();
                let left = jobs.iter().find(|j| {
                    j["kind"] == "benchmark"
                        && (matches!(j["state"].as_str(), Some("queued" | "running"))
                            || (j["state"] == "succeeded" && unpublished.contains(&&j["result_id"])))
                });
                if let Some(job) = left.and_then(|j| j["id"].as_str()) {
                    println!("baselines: {} takes up its job {}/jobs/{job}", baseline.name, self.url);
                    return Ok(Some(job.to_string()));
                }
            }
            Err(_) => {
                let body = json!({ "name": baseline.name, "visibility": "public" });
                self.call(self.http.post(format!("{}/api/v1/projects", self.url)).json(&body)).await?;
            }
        }
        let (dir, remote, token) =
            (baseline.dir.clone(), format!("{}/git/{}.git", self.url, baseline.name), self.token.clone());
        let output = tokio::task::spawn_blocking(move || push(&dir, &remote, &token)).await??;
        let job = output
            .split("/jobs/")
            .nth(1)
            .map(|rest| rest.chars().take_while(|c| c.is_ascii_hexdigit() || *c == '-').collect::<String>())
            .filter(|id| !id.is_empty())
            .ok_or_else(|| anyhow!("the push started no job:\n{output}"))?;
        println!("baselines: {} pushed with FBKSD_RUN: {}/jobs/{job}", baseline.name, self.url);
        Ok(Some(job))
    }

    /// Waits for the benchmark `job`, then publishes its result set; the result page.
    async fn publish_when_done(&self, baseline: &Baseline, job: &str) -> anyhow::Result<String> {
        let ended = loop {
            let state = self.call(self.http.get(format!("{}/api/v1/jobs/{job}", self.url))).await?;
            if !matches!(state["state"].as_str(), Some("queued" | "running")) {
                break state;
            }
            tokio::time::sleep(Duration::from_secs(3)).await;
        };
        let Some(result) = ended["result_id"].as_str().filter(|_| ended["state"] == "succeeded") else {
            bail!(
                "its benchmark ended {} ({}): {}/jobs/{job}",
                ended["state"].as_str().unwrap_or("?"),
                ended["message"].as_str().unwrap_or("").lines().next().unwrap_or(""),
                self.url
            );
        };
        let variables = json!({ "variables": { "FBKSD_PUBLISH": result } });
        let pipelines = format!("{}/api/v1/projects/{}/pipelines", self.url, baseline.name);
        self.call(self.http.post(pipelines).json(&variables)).await?;
        Ok(format!("{}/results/{result}", self.url))
    }
}

/// Commits the folder's files (a fresh repository, so every push is a new
/// commit) and pushes them to `remote` with FBKSD_RUN; git's output. The
/// token travels in git's environment, never on a command line.
fn push(dir: &Path, remote: &str, token: &str) -> anyhow::Result<String> {
    let work = tempfile::tempdir()?;
    copy_sources(dir, work.path())?;
    let credentials = base64::engine::general_purpose::STANDARD.encode(format!("baselines:{token}"));
    let git = |args: &[&str]| -> anyhow::Result<String> {
        let out = std::process::Command::new("git")
            .args(["-c", "user.name=FBKSD baselines", "-c", &format!("user.email={ACCOUNT}")])
            .args(args)
            .current_dir(work.path())
            .env("GIT_CONFIG_COUNT", "1")
            .env("GIT_CONFIG_KEY_0", "http.extraHeader")
            .env("GIT_CONFIG_VALUE_0", format!("Authorization: Basic {credentials}"))
            .env("GIT_TERMINAL_PROMPT", "0")
            .output()
            .context("running git")?;
        let text = String::from_utf8_lossy(&out.stderr).into_owned() + &String::from_utf8_lossy(&out.stdout);
        if !out.status.success() {
            bail!("git {}: {text}", args.join(" "));
        }
        Ok(text)
    };
    git(&["init", "-q", "-b", "main"])?;
    git(&["add", "-A"])?;
    git(&["commit", "-q", "-m", &format!("{} as published by FBKSD", dir.display())])?;
    git(&["push", "--force", "-o", "FBKSD_RUN", remote, "HEAD:main"])
}

/// Copies a repository's files, leaving out build and cache folders. A
/// link is copied as the file it points to: baselines share code that way
/// in `sdk/techniques`, and each pushed repository stands alone.
fn copy_sources(from: &Path, to: &Path) -> anyhow::Result<()> {
    for entry in std::fs::read_dir(from).with_context(|| format!("reading {}", from.display()))? {
        let entry = entry?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') || name == "__pycache__" || name == "build" {
            continue;
        }
        let kind = std::fs::metadata(entry.path()).with_context(|| format!("{}", entry.path().display()))?.file_type();
        if kind.is_dir() {
            std::fs::create_dir_all(to.join(&name))?;
            copy_sources(&entry.path(), &to.join(&name))?;
        } else if kind.is_file() {
            std::fs::copy(entry.path(), to.join(&name))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_list_names_folders_relative_to_itself_and_refuses_bad_entries() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["nfor", "oidn"] {
            std::fs::create_dir(dir.path().join(name)).unwrap();
            std::fs::write(dir.path().join(name).join("info.json"), "{}").unwrap();
        }
        let list = dir.path().join("baselines.txt");
        std::fs::write(&list, "# the state of the art\nnfor\n\n oidn  # Intel's\n").unwrap();
        let read = read_list(&list).unwrap();
        assert_eq!(read.iter().map(|b| b.name.as_str()).collect::<Vec<_>>(), ["nfor", "oidn"]);
        assert_eq!(read[0].dir, dir.path().join("nfor"));

        std::fs::write(&list, "nfor\nmissing\n").unwrap();
        let e = read_list(&list).unwrap_err().to_string();
        assert!(e.contains("baselines.txt:2") && e.contains("missing") && e.contains("no info.json"), "{e}");
        std::fs::write(&list, "nfor\nnfor\n").unwrap();
        assert!(read_list(&list).unwrap_err().to_string().contains("listed twice"));
    }

    #[test]
    fn a_pushed_repository_holds_linked_files_as_files_and_no_caches() {
        let dir = tempfile::tempdir().unwrap();
        let (shared, repo, out) = (dir.path().join("shared"), dir.path().join("repo"), dir.path().join("out"));
        for d in [&shared, &repo.join("__pycache__"), &out] {
            std::fs::create_dir_all(d).unwrap();
        }
        std::fs::write(shared.join("splat.py"), "shared = 1\n").unwrap();
        std::fs::write(repo.join("mitchell.py"), "import splat\n").unwrap();
        std::fs::write(repo.join("__pycache__/splat.pyc"), "").unwrap();
        std::os::unix::fs::symlink("../shared/splat.py", repo.join("splat.py")).unwrap();
        copy_sources(&repo, &out).unwrap();
        assert!(!out.join("splat.py").is_symlink());
        assert_eq!(std::fs::read_to_string(out.join("splat.py")).unwrap(), "shared = 1\n");
        assert!(out.join("mitchell.py").is_file() && !out.join("__pycache__").exists());
    }

    #[test]
    fn the_local_url_reaches_an_unspecified_bind_address_on_this_machine() {
        assert_eq!(local_url("0.0.0.0:8096"), "http://127.0.0.1:8096");
        assert_eq!(local_url("127.0.0.1:9000"), "http://127.0.0.1:9000");
        assert_eq!(local_url("[::]:80"), "http://[::1]:80");
    }
}
