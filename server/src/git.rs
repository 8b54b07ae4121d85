//! Git hosting: one bare repository per project under `data_dir/git`,
//! served over smart HTTP by the real `git http-backend` (a CGI program;
//! [`GitHost::serve`] is the CGI bridge) and read with the real `git`.
//!
//! Pushes reach the server through two hooks every repository shares
//! (`core.hooksPath`, an absolute path):
//! - `pre-receive` checks the push options (`git push -o …`) before
//!   anything is written, so a typo never lands a commit without its
//!   pipeline; its script comes from the owner of the options' rules
//!   ([`crate::pipelines::pre_receive_hook`]);
//! - `post-receive` writes the ref updates and the push options to the file
//!   named by `FBKSD_PUSH_RECORD`, which the bridge sets per request and
//!   reads when `git http-backend` has finished ([`PushRecord`]).
//!
//! What a push started is told to the pusher as `remote:` lines: the bridge
//! adds them to git's answer on the side-band progress channel
//! ([`Pushed::respond`]).
//!
//! Size: git itself refuses packs above `receive.maxInputSize` with a
//! message the client prints; the bridge also caps the request body, which
//! it spools to disk rather than holding in memory. What an account's
//! repositories hold together is bounded too ([`RepositoryQuota`]): the
//! bridge tells `pre-receive` how much they hold, and the hook weighs what
//! the push brings (git keeps it in a quarantine until the hooks accept it,
//! so a refused push writes nothing).
//!
//! Processes: clients are served by at most [`MAX_SERVED`] git processes at
//! once, each caller (a user, a job, or all anonymous clients together) by
//! at most [`MAX_REQUESTS_PER_CALLER`], each request for at most
//! [`SERVE_TIME_LIMIT`]; the server's own reads (pages, pipelines' checks)
//! have [`MAX_READS`] processes of their own. A clone lasts as long as its
//! client reads, so slow anonymous clones would otherwise hold every
//! process, and pushes, runners' clones and project pages would wait
//! behind them.

use axum::body::Body;
use axum::http::{HeaderMap, Method, StatusCode};
use axum::response::{IntoResponse, Response};
use std::path::{Path, PathBuf};
use std::process::Stdio;
use tokio::io::{AsyncBufReadExt, AsyncReadExt, AsyncWriteExt, BufReader};
use tokio::process::Command;

const POST_RECEIVE: &str = r#"#!/bin/sh
# FBKSD: tell the server what was pushed (read when git http-backend ends).
[ -n "$FBKSD_PUSH_RECORD" ] || exit 0
{
    while read -r old new ref; do
        echo "ref $old $new $ref"
    done
    i=0
    while [ "$i" -lt "${GIT_PUSH_OPTION_COUNT:-0}" ]; do
        eval "echo \"option \$GIT_PUSH_OPTION_$i\""
        i=$((i + 1))
    done
} > "$FBKSD_PUSH_RECORD"
"#;

/// A branch or tag a push moved.
#[derive(Debug, Clone, PartialEq)]
pub struct RefUpdate {
    /// Previous commit (all zeros for a new ref).
    pub old: String,
    /// New commit (all zeros for a deletion).
    pub new: String,
    /// Full ref name, e.g. `refs/heads/main`.
    pub name: String,
}

/// What one push did: its ref updates and its push options.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PushRecord {
    /// Refs moved.
    pub updates: Vec<RefUpdate>,
    /// `git push -o` values, e.g. `FBKSD_RUN`.
    pub options: Vec<String>,
}

impl PushRecord {
    fn parse(text: &str) -> PushRecord {
        let mut record = PushRecord::default();
        for line in text.lines() {
            // Options come after every ref: a "ref" line among them is part
            // of an option value (the pre-receive hook refuses those anyway).
            if let (Some(rest), true) = (line.strip_prefix("ref "), record.options.is_empty()) {
                let mut parts = rest.splitn(3, ' ');
                if let (Some(old), Some(new), Some(name)) = (parts.next(), parts.next(), parts.next()) {
                    record.updates.push(RefUpdate { old: old.into(), new: new.into(), name: name.into() });
                }
            } else if let Some(option) = line.strip_prefix("option ") {
                record.options.push(option.to_string());
            }
        }
        record
    }
}

/// What a request to the bridge produced.
pub enum Served {
    /// A fetch, or a push that did not land: the answer for git.
    Answered(Response),
    /// A push that landed: what it did, and git's answer still to be sent.
    Pushed(Pushed),
}

/// A push that `git http-backend` accepted, before its answer is sent.
pub struct Pushed {
    /// What the push did.
    pub record: PushRecord,
    status: StatusCode,
    headers: HeaderMap,
    output: Vec<u8>,
}

impl Pushed {
    /// git's answer, with `messages` (one line each) printed by the pusher's
    /// git as `remote:` lines.
    pub fn respond(self, messages: &[String]) -> Response {
        let mut response = Response::new(Body::from(with_remote_messages(self.output, messages)));
        *response.status_mut() = self.status;
        *response.headers_mut() = self.headers;
        // The body grew: its length is the new one, not git's.
        response.headers_mut().remove(axum::http::header::CONTENT_LENGTH);
        response
    }
}

/// Adds `messages` to a `git-receive-pack` answer as side-band channel 2
/// (progress) packets before its final flush packet, where git prints them
/// as `remote:` lines. An answer without side-band (clients older than
/// git 1.6) is returned as it was: it has no place for them.
fn with_remote_messages(output: Vec<u8>, messages: &[String]) -> Vec<u8> {
    // Walk the pkt-lines: 4 hex digits of length (header included), "0000" a flush.
    let (mut at, mut side_band) = (0, None);
    while at + 4 <= output.len() {
        let Some(length) =
            std::str::from_utf8(&output[at..at + 4]).ok().and_then(|h| usize::from_str_radix(h, 16).ok())
        else {
            return output;
        };
        if length == 0 && at + 4 == output.len() {
            break;
        }
        if length != 0 && (length < 5 || at + length > output.len()) {
            return output;
        }
        side_band.get_or_insert(length != 0 && matches!(output[at + 4], 1..=3));
        at += length.max(4);
    }
    if side_band != Some(true) || at + 4 != output.len() {
        return output;
    }
    let mut answer = output[..at].to_vec();
    for message in messages {
        for line in message.lines() {
            // A packet holds at most 65516 bytes of data; a char boundary keeps it text.
            let end = (0..=line.len().min(60_000)).rev().find(|&i| line.is_char_boundary(i)).unwrap_or(0);
            let line = &line[..end];
            answer.extend(format!("{:04x}", 4 + 1 + line.len() + 1).as_bytes());
            answer.push(2);
            answer.extend(line.as_bytes());
            answer.push(b'\n');
        }
    }
    answer.extend(b"0000");
    answer
}

/// The parts of a smart-HTTP request the CGI bridge passes on.
pub struct GitRequest<'a> {
    /// GET or POST.
    pub method: &'a Method,
    /// The path after `<name>.git/`, e.g. `info/refs`.
    pub rest: &'a str,
    /// The query string.
    pub query: &'a str,
    /// The request's headers.
    pub headers: &'a HeaderMap,
    /// Who asks, as counted against [`MAX_REQUESTS_PER_CALLER`]: a user's
    /// or a job's own key, or [`ANONYMOUS`].
    pub caller: &'a str,
    /// For a push: what the repository's owner may keep, checked by
    /// `pre-receive` against what the push brings.
    pub quota: Option<RepositoryQuota>,
}

/// What one account's repositories hold on disk together, and the most
/// they may. Checked per push against what was there when it began, so
/// pushes of one account at the same moment may each fit alone and pass
/// it together: by at most `max_push_bytes` for each push beside the
/// first (a caller has at most [`MAX_REQUESTS_PER_CALLER`] at once).
#[derive(Debug, Clone, Copy)]
pub struct RepositoryQuota {
    /// Bytes the account's repositories take on disk now.
    pub used_bytes: u64,
    /// The most they may hold.
    pub max_bytes: u64,
}

/// The caller that all anonymous clients are together.
pub const ANONYMOUS: &str = "anonymous";

/// The `WWW-Authenticate` challenge of a git request that must sign in.
pub const ASK_CREDENTIALS: &str = "Basic realm=\"FBKSD\", charset=\"UTF-8\"";

/// The server's repositories.
#[derive(Debug, Clone)]
pub struct GitHost {
    root: PathBuf,
    hooks: PathBuf,
    /// Request bodies and push records while a request lasts: beside the
    /// repositories, not among them (backups copy `git/`); what a crash
    /// left is removed at start.
    spool: PathBuf,
    max_push_bytes: u64,
    /// `git http-backend` processes serving clients ([`MAX_SERVED`]).
    serving: std::sync::Arc<tokio::sync::Semaphore>,
    /// Requests per caller ([`MAX_REQUESTS_PER_CALLER`]).
    callers: crate::slots::Slots,
    /// The server's own git reads ([`MAX_READS`]).
    reading: std::sync::Arc<tokio::sync::Semaphore>,
    counts: std::sync::Arc<Counts>,
}

/// Git processes started since the server started, and requests refused.
#[derive(Debug, Default)]
struct Counts {
    served: std::sync::atomic::AtomicU64,
    read: std::sync::atomic::AtomicU64,
    refused: std::sync::atomic::AtomicU64,
}

/// What git is doing, for operators ([`GitHost::activity`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Activity {
    /// `git http-backend` processes serving clients now.
    pub serving: usize,
    /// Git processes reading for the server now.
    pub reading: usize,
    /// Clients' requests served since start.
    pub served: u64,
    /// The server's own reads since start.
    pub read: u64,
    /// Clients' requests refused because their caller had as many running as it may.
    pub refused: u64,
}

/// At most this many git processes serve clients at once (pushes,
/// fetches, clones): each holds memory and a core, and a flood of them
/// must queue, not fork without bound.
pub const MAX_SERVED: usize = 16;

/// At most this many requests of one caller are served at once; more are
/// refused at once rather than queued (a queued request holds a
/// connection and its spooled body): 401 for anonymous clients (asked to
/// sign in, [`busy`]), 429 for others. A fetch or a push is two requests
/// one after the other, so one at a time is all a client needs.
pub const MAX_REQUESTS_PER_CALLER: usize = 4;

/// At most this many git processes read for the server at once (project
/// pages, pipelines' checks): apart from the clients', whose clones last
/// as long as their clients read.
pub const MAX_READS: usize = 8;

/// How long one client's request may take, from its first byte to the
/// end of its answer: its body's upload, then a clone's answer (cut at its
/// next chunk past the limit: a client that stops reading is closed
/// sooner, by the connection's idle limit). A clone of most techniques'
/// histories at 1 MiB/s fits well within it; a client slower than that, or
/// a history larger, is cut. A push, once its body is on disk, is git's
/// own work on a bounded pack and is not cut (killing `http-backend` would
/// leave `receive-pack` and its hooks running).
pub const SERVE_TIME_LIMIT: std::time::Duration = std::time::Duration::from_secs(15 * 60);

/// The largest fetch request body: a fetch's negotiation (the objects it
/// wants and has) is a few kilobytes even for long histories.
const FETCH_REQUEST_BYTES: u64 = 16 << 20;

/// How long one git read may take.
const GIT_TIME_LIMIT: std::time::Duration = std::time::Duration::from_secs(30);

/// Output bytes allowed per file of `ls-tree -r -l -z`: mode, type, a
/// 40-digit id, a size and a path of up to 4096 bytes.
const LS_TREE_LINE_BYTES: usize = 4200;

/// How much of a git command's output is read before it is stopped.
#[derive(Debug, Clone, Copy)]
struct Limit {
    /// Bytes.
    bytes: usize,
    /// NUL-ended records (`-z` output).
    records: usize,
}

impl Limit {
    /// For commands that answer a line.
    fn small() -> Limit {
        Limit { bytes: 64 << 10, records: usize::MAX }
    }
}

/// A git command that failed; the message includes its stderr.
#[derive(Debug, thiserror::Error)]
#[error("git {command}: {message}")]
pub struct GitError {
    command: String,
    message: String,
    /// Why, for callers that answer differently to a repository that is
    /// too big than to git failing.
    pub kind: GitErrorKind,
}

/// Why a git command failed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GitErrorKind {
    /// git failed or could not run.
    Failed,
    /// Its output passed the caller's cap (git was killed).
    TooLarge,
    /// It did not finish within [`GIT_TIME_LIMIT`].
    TimedOut,
}

/// One file of a commit, as `git ls-tree -r -l` lists it.
#[derive(Debug, Clone, PartialEq)]
pub struct TreeFile {
    /// Path from the repository's root.
    pub path: String,
    /// Git's mode: `100644`, `100755`, `120000` (a symbolic link), `160000` (a submodule).
    pub mode: String,
    /// `blob` or `commit` (a submodule).
    pub kind: String,
    /// The object id.
    pub id: String,
    /// Size in bytes (0 for a submodule).
    pub size: u64,
}

impl TreeFile {
    fn parse(line: &[u8]) -> Option<TreeFile> {
        let line = String::from_utf8_lossy(line);
        let (meta, path) = line.split_once('\t')?;
        let mut fields = meta.split_whitespace();
        let (mode, kind, id, size) = (fields.next()?, fields.next()?, fields.next()?, fields.next()?);
        Some(TreeFile {
            path: path.to_string(),
            mode: mode.into(),
            kind: kind.into(),
            id: id.into(),
            size: size.parse().unwrap_or(0),
        })
    }

    /// Whether git stores it as a symbolic link.
    pub fn is_symlink(&self) -> bool {
        self.mode == "120000"
    }
}

impl GitHost {
    /// Repositories under `data_dir/git` (an absolute path); writes the
    /// shared hooks (`pre_receive` is its script) and points every existing
    /// repository at them, which repairs repositories an older server gave a
    /// relative hooks path.
    pub fn open(data_dir: &Path, max_push_bytes: u64, pre_receive: &str) -> std::io::Result<GitHost> {
        if !data_dir.is_absolute() {
            return Err(std::io::Error::other(format!(
                "{} is relative: git resolves it inside each repository",
                data_dir.display()
            )));
        }
        let root = data_dir.join("git");
        let hooks = data_dir.join("git-hooks");
        let spool = data_dir.join("git-spool");
        std::fs::create_dir_all(&root)?;
        std::fs::create_dir_all(&hooks)?;
        std::fs::create_dir_all(&spool)?;
        // What a crash left (other instances may share the folder: only what is a day old).
        let day_ago = std::time::SystemTime::now() - std::time::Duration::from_secs(24 * 3600);
        for entry in std::fs::read_dir(&spool)?.flatten() {
            if entry.metadata().and_then(|m| m.modified()).is_ok_and(|t| t < day_ago) {
                let _ = std::fs::remove_file(entry.path());
            }
        }
        for (name, text) in [("pre-receive", pre_receive), ("post-receive", POST_RECEIVE)] {
            let path = hooks.join(name);
            std::fs::write(&path, text)?;
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755))?;
        }
        for entry in std::fs::read_dir(&root)? {
            let repository = entry?.path();
            let config = std::fs::read_to_string(repository.join("config")).unwrap_or_default();
            if repository.extension().is_none_or(|e| e != "git") {
                continue;
            }
            let hooks_path = format!("hooksPath = {}", hooks.display());
            for (key, value, line) in [
                ("core.hooksPath", hooks.to_string_lossy(), hooks_path.as_str()),
                ("uploadpack.allowFilter", "true".into(), "allowfilter = true"),
            ] {
                if config.lines().any(|l| l.trim().eq_ignore_ascii_case(line)) {
                    continue;
                }
                let set = std::process::Command::new("git")
                    .arg("-C")
                    .arg(&repository)
                    .args(["config", key, value.as_ref()])
                    .status()?;
                if !set.success() {
                    tracing::warn!("{}: cannot set {key}", repository.display());
                }
            }
        }
        Ok(GitHost {
            root,
            hooks,
            spool,
            max_push_bytes,
            serving: std::sync::Arc::new(tokio::sync::Semaphore::new(MAX_SERVED)),
            callers: crate::slots::Slots::new(MAX_REQUESTS_PER_CALLER, usize::MAX),
            reading: std::sync::Arc::new(tokio::sync::Semaphore::new(MAX_READS)),
            counts: Default::default(),
        })
    }

    /// What git is doing now, and has done since start.
    pub fn activity(&self) -> Activity {
        use std::sync::atomic::Ordering::Relaxed;
        Activity {
            serving: MAX_SERVED - self.serving.available_permits(),
            reading: MAX_READS - self.reading.available_permits(),
            served: self.counts.served.load(Relaxed),
            read: self.counts.read.load(Relaxed),
            refused: self.counts.refused.load(Relaxed),
        }
    }

    /// The largest push accepted, in bytes.
    pub fn max_push_bytes(&self) -> u64 {
        self.max_push_bytes
    }

    fn repository(&self, project_id: &str) -> PathBuf {
        self.root.join(format!("{project_id}.git"))
    }

    /// Bytes these projects' repositories take on disk.
    pub async fn repositories_bytes(&self, project_ids: Vec<String>) -> u64 {
        let roots: Vec<PathBuf> = project_ids.iter().map(|id| self.repository(id)).collect();
        let walk = move || roots.iter().map(|root| fbksd_exchange::disk::disk_usage(root, u64::MAX)).sum();
        tokio::task::spawn_blocking(walk).await.unwrap_or(0)
    }

    /// Runs git with at most [`MAX_READS`] at once, reading at most
    /// `limit` of its output within [`GIT_TIME_LIMIT`]. Output is
    /// streamed and git is killed at the cap: a repository's content decides
    /// how much `ls-tree -r` or `cat-file` would print (a few KB of nested
    /// trees name ~10¹⁰ paths), so nothing of it is read unbounded.
    async fn git(&self, args: &[&str], dir: Option<&Path>, limit: Limit) -> Result<Vec<u8>, GitError> {
        let error = |message: String| GitError { command: args.join(" "), message, kind: GitErrorKind::Failed };
        let _permit = self.reading.acquire().await.map_err(|e| error(e.to_string()))?;
        self.counts.read.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let mut command = Command::new("git");
        if let Some(dir) = dir {
            command.arg("-C").arg(dir);
        }
        let mut child = command
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .kill_on_drop(true)
            .spawn()
            .map_err(|e| error(format!("cannot run git: {e}")))?;
        let (Some(stdout), Some(stderr)) = (child.stdout.take(), child.stderr.take()) else {
            return Err(error("git has no pipes".into()));
        };
        let stderr = tokio::spawn(async move {
            let mut text = Vec::new();
            let _ = stderr.take(64 << 10).read_to_end(&mut text).await;
            String::from_utf8_lossy(&text).trim().to_string()
        });
        let mut output = Vec::new();
        let too_large = GitError {
            command: args.join(" "),
            message: format!("its output is larger than {} bytes or {} records", limit.bytes, limit.records),
            kind: GitErrorKind::TooLarge,
        };
        // Read in chunks, counting NUL-ended records as they come: `ls-tree
        // -r -z` is stopped at its first record past the cap, not after
        // megabytes of paths.
        let read = async {
            let (mut stdout, mut chunk, mut records) = (stdout, vec![0u8; 64 << 10], 0usize);
            loop {
                let n = stdout.read(&mut chunk).await?;
                if n == 0 {
                    return Ok::<bool, std::io::Error>(true);
                }
                records += chunk[..n].iter().filter(|b| **b == 0).count();
                if output.len() + n > limit.bytes || records > limit.records {
                    return Ok(false);
                }
                output.extend_from_slice(&chunk[..n]);
            }
        };
        match tokio::time::timeout(GIT_TIME_LIMIT, read).await {
            Err(_) => {
                return Err(GitError {
                    command: args.join(" "),
                    message: format!("did not finish within {} s", GIT_TIME_LIMIT.as_secs()),
                    kind: GitErrorKind::TimedOut,
                })
            }
            Ok(Err(e)) => return Err(error(format!("reading its output: {e}"))),
            Ok(Ok(false)) => return Err(too_large),
            Ok(Ok(true)) => {}
        }
        let status = tokio::time::timeout(GIT_TIME_LIMIT, child.wait())
            .await
            .map_err(|_| error("did not exit".into()))?
            .map_err(|e| error(e.to_string()))?;
        if !status.success() {
            return Err(error(stderr.await.unwrap_or_default()));
        }
        Ok(output)
    }

    /// Creates the bare repository of a new project.
    pub async fn create(&self, project_id: &str) -> Result<(), GitError> {
        let path = self.repository(project_id);
        let path_text = path.to_string_lossy().into_owned();
        self.git(&["init", "--quiet", "--bare", "--initial-branch=main", &path_text], None, Limit::small()).await?;
        let max = self.max_push_bytes.to_string();
        let hooks = self.hooks.to_string_lossy().into_owned();
        for (key, value) in [
            ("http.receivepack", "true"),
            ("receive.advertisePushOptions", "true"),
            ("receive.maxInputSize", max.as_str()),
            ("receive.fsckObjects", "true"),
            // Runners clone with `--filter=blob:none`: only the pinned commit's files.
            ("uploadpack.allowFilter", "true"),
            ("core.hooksPath", hooks.as_str()),
        ] {
            self.git(&["config", key, value], Some(&path), Limit::small()).await?;
        }
        Ok(())
    }

    /// Deletes a project's repository.
    pub async fn delete(&self, project_id: &str) {
        let path = self.repository(project_id);
        if let Err(e) = tokio::fs::remove_dir_all(&path).await {
            tracing::warn!("removing {}: {e}", path.display());
        }
    }

    /// The commit `rev` names (a branch, a tag or a hash), if any.
    pub async fn resolve(&self, project_id: &str, rev: &str) -> Option<String> {
        if rev.starts_with('-') {
            return None;
        }
        let spec = format!("{rev}^{{commit}}");
        let out = self
            .git(&["rev-parse", "--verify", "--quiet", &spec], Some(&self.repository(project_id)), Limit::small())
            .await;
        out.ok().map(|o| String::from_utf8_lossy(&o).trim().to_string())
    }

    /// Every file at `commit`, if there are at most `max_files`.
    pub async fn files(&self, project_id: &str, commit: &str, max_files: usize) -> Result<Vec<TreeFile>, GitError> {
        // `-l` adds each blob's size; a line is mode, type, id, size, then the path.
        let args = ["ls-tree", "-r", "-l", "--full-tree", "-z", commit];
        let limit = Limit { bytes: max_files * LS_TREE_LINE_BYTES, records: max_files };
        let out = match self.git(&args, Some(&self.repository(project_id)), limit).await {
            Err(GitError { kind: GitErrorKind::TooLarge, command, .. }) => {
                return Err(GitError {
                    command,
                    message: format!("the commit holds more than {max_files} files"),
                    kind: GitErrorKind::TooLarge,
                })
            }
            other => other?,
        };
        let entries: Vec<TreeFile> =
            out.split(|b| *b == 0).filter(|l| !l.is_empty()).filter_map(TreeFile::parse).collect();
        if entries.len() > max_files {
            return Err(GitError {
                command: args.join(" "),
                message: format!("the commit holds {} files, more than {max_files}", entries.len()),
                kind: GitErrorKind::TooLarge,
            });
        }
        Ok(entries)
    }

    /// The text of `file` (an entry of [`GitHost::files`]), at most `max`
    /// bytes: its size is checked before a byte of it is read, and a
    /// symbolic link is refused (its blob is the link's target, which the
    /// runner's checkout would resolve to something else).
    pub async fn read(&self, project_id: &str, file: &TreeFile, max: usize) -> Result<String, String> {
        if file.is_symlink() {
            return Err(format!("{} is a symbolic link: commit the file itself", file.path));
        }
        if file.kind != "blob" {
            return Err(format!("{} is not a file", file.path));
        }
        if file.size > max as u64 {
            return Err(format!("{} is {} bytes, larger than {max} bytes", file.path, file.size));
        }
        let bytes = self
            .git(
                &["cat-file", "blob", &file.id],
                Some(&self.repository(project_id)),
                Limit { bytes: max, records: usize::MAX },
            )
            .await
            .map_err(|e| format!("{}: {e}", file.path))?;
        String::from_utf8(bytes).map_err(|_| format!("{} is not UTF-8 text", file.path))
    }

    /// Answers one smart-HTTP request for a project's repository with
    /// `git http-backend`; `user` is who authenticated (for git's logs).
    pub async fn serve(&self, project_id: &str, request: GitRequest<'_>, body: Body, user: &str) -> Served {
        let GitRequest { method, rest, query, headers, caller, quota } = request;
        let plain = |status: StatusCode, text: String| Served::Answered((status, text).into_response());
        // Taken before the body is spooled: a caller's spooled bodies are bounded too.
        let Ok(slot) = self.callers.take(caller) else {
            self.counts.refused.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            return Served::Answered(busy(caller));
        };
        let is_push = rest == "git-receive-pack";
        // A push's body is capped beyond git's own pack limit (`receive.maxInputSize`),
        // which answers with a message the client prints; a fetch sends only its
        // negotiation (what it wants and has), which anyone may send for a public project.
        let cap =
            if is_push { self.max_push_bytes.saturating_mul(2).saturating_add(1 << 20) } else { FETCH_REQUEST_BYTES };
        let deadline = tokio::time::Instant::now() + SERVE_TIME_LIMIT;
        let spooled = tokio::time::timeout_at(deadline, spool(body, &self.spool, cap)).await;
        let Ok(spooled) = spooled else {
            let minutes = SERVE_TIME_LIMIT.as_secs() / 60;
            return plain(
                StatusCode::REQUEST_TIMEOUT,
                format!("the request took longer than {minutes} minutes to send\n"),
            );
        };
        let body = match spooled {
            Ok(spooled) => spooled,
            Err(Spool::TooLarge) if is_push => {
                return plain(
                    StatusCode::PAYLOAD_TOO_LARGE,
                    format!("push larger than the server's limit of {} bytes\n", self.max_push_bytes),
                )
            }
            Err(Spool::TooLarge) => {
                return plain(
                    StatusCode::PAYLOAD_TOO_LARGE,
                    format!("a fetch request is limited to {FETCH_REQUEST_BYTES} bytes\n"),
                )
            }
            Err(Spool::Broken(e)) => return plain(StatusCode::BAD_REQUEST, format!("the request broke off: {e}\n")),
            Err(Spool::Disk(e)) => {
                tracing::error!("spooling a git request: {e}");
                return plain(StatusCode::INTERNAL_SERVER_ERROR, "cannot store the request\n".into());
            }
        };
        // Only a push has hooks to report through.
        let record = match is_push.then(|| tempfile::NamedTempFile::new_in(&self.spool)).transpose() {
            Ok(r) => r,
            Err(_) => return plain(StatusCode::INTERNAL_SERVER_ERROR, "cannot create a temporary file\n".into()),
        };
        let header = |name: &str| headers.get(name).and_then(|v| v.to_str().ok()).unwrap_or("").to_string();
        let mut command = Command::new("git");
        command
            .arg("http-backend")
            .env_clear()
            .env("PATH", std::env::var_os("PATH").unwrap_or_default())
            .env("GIT_PROJECT_ROOT", &self.root)
            .env("GIT_HTTP_EXPORT_ALL", "1")
            .env("PATH_INFO", format!("/{project_id}.git/{rest}"))
            .env("REQUEST_METHOD", method.as_str())
            .env("QUERY_STRING", query)
            .env("CONTENT_TYPE", header("content-type"))
            .env("CONTENT_LENGTH", body.length.to_string())
            .env("HTTP_CONTENT_ENCODING", header("content-encoding"))
            .env("GIT_PROTOCOL", header("git-protocol"))
            .env("REMOTE_USER", user)
            .env("REMOTE_ADDR", "127.0.0.1")
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .kill_on_drop(true);
        if let Some(record) = &record {
            command.env("FBKSD_PUSH_RECORD", record.path());
        }
        if let Some(quota) = quota.filter(|_| is_push) {
            command
                .env("FBKSD_REPOSITORIES_BYTES", quota.used_bytes.to_string())
                .env("FBKSD_MAX_REPOSITORIES_BYTES", quota.max_bytes.to_string());
        }
        // Held until git ends: for a fetch, by the task that waits for it.
        let Ok(permit) = self.serving.clone().acquire_owned().await else {
            return plain(StatusCode::SERVICE_UNAVAILABLE, "the server is shutting down\n".into());
        };
        self.counts.served.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let mut child = match command.spawn() {
            Ok(c) => c,
            Err(e) => return plain(StatusCode::INTERNAL_SERVER_ERROR, format!("cannot run git http-backend: {e}\n")),
        };
        let (Some(mut stdin), Some(stdout), Some(mut stderr)) =
            (child.stdin.take(), child.stdout.take(), child.stderr.take())
        else {
            return plain(StatusCode::INTERNAL_SERVER_ERROR, "git http-backend has no pipes\n".into());
        };
        tokio::spawn(async move {
            // git may answer before reading everything (a refused pack): ignore EPIPE.
            if let Ok(mut file) = tokio::fs::File::open(body.file.path()).await {
                let _ = tokio::io::copy(&mut file, &mut stdin).await;
            }
            drop(body);
        });
        // Read to the end (git would block on a full pipe), keep the start.
        let stderr_task = tokio::spawn(async move {
            let (mut kept, mut chunk) = (Vec::new(), [0u8; 8192]);
            while let Ok(n @ 1..) = stderr.read(&mut chunk).await {
                kept.extend_from_slice(&chunk[..n.min((64usize << 10).saturating_sub(kept.len()))]);
            }
            String::from_utf8_lossy(&kept).into_owned()
        });

        // CGI headers, then the body.
        let mut reader = BufReader::new(stdout);
        let mut cgi_headers = HeaderMap::new();
        let mut status = StatusCode::OK;
        loop {
            let mut line = String::new();
            match reader.read_line(&mut line).await {
                Ok(0) | Err(_) => break,
                Ok(_) => {}
            }
            let line = line.trim_end();
            if line.is_empty() {
                break;
            }
            let Some((name, value)) = line.split_once(':') else { continue };
            let value = value.trim();
            if name.eq_ignore_ascii_case("status") {
                status = value.split(' ').next().and_then(|c| c.parse().ok()).unwrap_or(StatusCode::OK);
            } else if let (Ok(name), Ok(value)) =
                (axum::http::HeaderName::try_from(name), axum::http::HeaderValue::try_from(value))
            {
                cgi_headers.append(name, value);
            }
        }

        if !is_push {
            let mut response = Response::builder().status(status);
            if let Some(headers) = response.headers_mut() {
                *headers = cgi_headers;
            }
            // Fetches stream: a clone can be large.
            tokio::spawn(async move {
                let _held = (permit, slot);
                let _ = child.wait().await;
                let errors = stderr_task.await.unwrap_or_default();
                if !errors.trim().is_empty() {
                    tracing::debug!("git http-backend: {}", errors.trim());
                }
            });
            let stream = until(tokio_util::io::ReaderStream::new(reader), deadline);
            let response =
                response.body(Body::from_stream(stream)).unwrap_or_else(|_| StatusCode::BAD_GATEWAY.into_response());
            return Served::Answered(response);
        }

        // Pushes answer little; wait for the hooks to finish so the record is complete.
        // Its report-status is a few lines per ref; the cap only guards memory.
        let mut output = Vec::new();
        let _ = (&mut reader).take(16 << 20).read_to_end(&mut output).await;
        let exit = child.wait().await;
        drop((permit, slot));
        let errors = stderr_task.await.unwrap_or_default();
        if !errors.trim().is_empty() {
            tracing::debug!("git http-backend (push): {}", errors.trim());
        }
        let landed = match exit {
            Ok(s) if s.success() => record
                .and_then(|r| std::fs::read_to_string(r.path()).ok())
                .filter(|t| !t.is_empty())
                .map(|t| PushRecord::parse(&t)),
            _ => None,
        };
        let pushed = Pushed { record: landed.unwrap_or_default(), status, headers: cgi_headers, output };
        match pushed.record.updates.is_empty() {
            // Refused by a hook or by git: its answer says why.
            true => Served::Answered(pushed.respond(&[])),
            false => Served::Pushed(pushed),
        }
    }
}

/// The answer to a caller with [`MAX_REQUESTS_PER_CALLER`] requests running.
/// Anonymous clients are asked to sign in: git sends the credentials it
/// has (a clone URL's token) only when asked, so a signed-in clone of a
/// public project starts anonymous, and must not wait behind strangers.
fn busy(caller: &str) -> Response {
    use axum::http::header::{RETRY_AFTER, WWW_AUTHENTICATE};
    if caller == ANONYMOUS {
        let text = format!(
            "the server is serving as many anonymous git requests as it does at once ({MAX_REQUESTS_PER_CALLER}): \
             sign in (any user name, a personal access token as the password) or try again in a minute\n"
        );
        let headers = [(WWW_AUTHENTICATE, ASK_CREDENTIALS), (RETRY_AFTER, "60")];
        return (StatusCode::UNAUTHORIZED, headers, text).into_response();
    }
    let text = format!(
        "you have {MAX_REQUESTS_PER_CALLER} git requests running on this server, the most one caller may: \
         let one finish and try again\n"
    );
    (StatusCode::TOO_MANY_REQUESTS, [(RETRY_AFTER, "60")], text).into_response()
}

/// `stream`, ended with an error at its first chunk past `deadline`: the
/// connection is then closed, git's pipe breaks and its process ends.
fn until<S>(
    stream: S,
    deadline: tokio::time::Instant,
) -> impl futures_util::Stream<Item = std::io::Result<axum::body::Bytes>>
where
    S: futures_util::Stream<Item = std::io::Result<axum::body::Bytes>>,
{
    use futures_util::StreamExt;
    stream.map(move |chunk| match tokio::time::Instant::now() < deadline {
        true => chunk,
        false => Err(std::io::Error::new(
            std::io::ErrorKind::TimedOut,
            format!("served for longer than {} s", SERVE_TIME_LIMIT.as_secs()),
        )),
    })
}

/// A request body on disk: git reads it from there, so a request never
/// sits in memory whole (ten anonymous fetch requests of the cap's size
/// would otherwise hold ten times `2 × max_push_bytes` before any git
/// process slot is asked for).
struct Spooled {
    file: tempfile::NamedTempFile,
    length: u64,
}

/// Why a body could not be spooled.
enum Spool {
    TooLarge,
    Broken(axum::Error),
    Disk(std::io::Error),
}

/// Writes `body` to a temporary file in `dir`, refusing it once it passes `cap` bytes.
async fn spool(body: Body, dir: &Path, cap: u64) -> Result<Spooled, Spool> {
    use futures_util::StreamExt;
    let file = tempfile::NamedTempFile::new_in(dir).map_err(Spool::Disk)?;
    let mut out = tokio::fs::File::from_std(file.reopen().map_err(Spool::Disk)?);
    let mut chunks = body.into_data_stream();
    let mut length = 0u64;
    while let Some(chunk) = chunks.next().await {
        let chunk = chunk.map_err(Spool::Broken)?;
        length += chunk.len() as u64;
        if length > cap {
            return Err(Spool::TooLarge);
        }
        out.write_all(&chunk).await.map_err(Spool::Disk)?;
    }
    out.flush().await.map_err(Spool::Disk)?;
    Ok(Spooled { file, length })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn remote_messages_go_before_the_final_flush_on_the_progress_band() {
        // A side-band answer: band 1 holding report-status, then the flush.
        let report = b"000eunpack ok\n0019ok refs/heads/main\n0000";
        let mut answer = format!("{:04x}", 4 + 1 + report.len()).into_bytes();
        answer.push(1);
        answer.extend(report);
        answer.extend(b"0000");
        let with = with_remote_messages(answer.clone(), &["FBKSD: build queued".into()]);
        let expected_tail = b"0019\x02FBKSD: build queued\n0000";
        assert_eq!(&with[..answer.len() - 4], &answer[..answer.len() - 4]);
        assert_eq!(&with[answer.len() - 4..], expected_tail);
        // Without side-band (bare report-status pkt-lines) nothing can be added.
        let plain = b"000eunpack ok\n0000".to_vec();
        assert_eq!(with_remote_messages(plain.clone(), &["x".into()]), plain);
    }

    #[tokio::test]
    async fn an_answer_served_past_its_time_limit_is_cut_at_its_next_chunk() {
        use futures_util::StreamExt;
        let chunks = || futures_util::stream::iter([Ok(axum::body::Bytes::from("PACK")), Ok("more".into())]);
        let later = tokio::time::Instant::now() + std::time::Duration::from_secs(3600);
        let served: Vec<_> = until(chunks(), later).collect().await;
        assert!(served.iter().all(|c| c.is_ok()), "{served:?}");
        let passed = tokio::time::Instant::now();
        let cut: Vec<_> = until(chunks(), passed).collect().await;
        assert!(cut.iter().all(|c| c.as_ref().is_err_and(|e| e.kind() == std::io::ErrorKind::TimedOut)), "{cut:?}");
    }

    #[test]
    fn push_records_parse() {
        let record = PushRecord::parse(
            "ref 0000 abcd refs/heads/main\nref abcd 0000 refs/heads/old\noption FBKSD_RUN\noption FBKSD_PUBLISH=x\n",
        );
        assert_eq!(record.updates.len(), 2);
        assert_eq!(record.updates[0].name, "refs/heads/main");
        assert_eq!(record.options, ["FBKSD_RUN", "FBKSD_PUBLISH=x"]);
        // A "ref" line among the options is part of an option's value, never an update.
        let record =
            PushRecord::parse("ref 0000 abcd refs/heads/main\noption FBKSD_RUN=x\nref 0000 ef01 refs/heads/evil\n");
        assert_eq!(record.updates.len(), 1);
    }
}
