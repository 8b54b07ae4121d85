//! Git hosting: one bare repository per project under `data_dir/git`,
//! served over smart HTTP by the real `git http-backend` (a CGI program;
//! [`GitHost::serve`] is the CGI bridge) and read with the real `git`.
//!
//! Pushes reach the server through two hooks every repository shares
//! (`core.hooksPath`):
//! - `pre-receive` refuses unknown push options (`git push -o …`) before
//!   anything is written, so a typo never lands a commit without its
//!   pipeline;
//! - `post-receive` writes the ref updates and the push options to the file
//!   named by `FBKSD_PUSH_RECORD`, which the bridge sets per request and
//!   reads when `git http-backend` has finished ([`PushRecord`]).
//!
//! Size: git itself refuses packs above `receive.maxInputSize` with a
//! message the client prints; the bridge also caps the request body.

use axum::body::Body;
use axum::http::{HeaderMap, Method, StatusCode};
use axum::response::{IntoResponse, Response};
use std::path::{Path, PathBuf};
use std::process::Stdio;
use tokio::io::{AsyncBufReadExt, AsyncReadExt, AsyncWriteExt, BufReader};
use tokio::process::Command;

/// The hooks every repository runs (see the module documentation).
const PRE_RECEIVE: &str = r#"#!/bin/sh
# FBKSD: refuse unknown push options before anything is written.
i=0
while [ "$i" -lt "${GIT_PUSH_OPTION_COUNT:-0}" ]; do
    eval "option=\$GIT_PUSH_OPTION_$i"
    case "$option" in
        FBKSD_RUN|FBKSD_RUN=*) ;;
        FBKSD_PUBLISH=*)
            key="${option#FBKSD_PUBLISH=}"
            if ! printf '%s' "$key" | grep -Eqi '^[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}$'; then
                echo "FBKSD: FBKSD_PUBLISH needs the UUID of one of your results (the key in its /results/<uuid> URL), not '$key'"
                exit 1
            fi ;;
        *)
            echo "FBKSD: unknown push option '$option': the server knows FBKSD_RUN and FBKSD_PUBLISH=<uuid>"
            exit 1 ;;
    esac
    i=$((i + 1))
done
exit 0
"#;

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
            if let Some(rest) = line.strip_prefix("ref ") {
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
pub struct Served {
    /// The HTTP answer for git.
    pub response: Response,
    /// For a push that `git http-backend` accepted: what it did.
    pub push: Option<PushRecord>,
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
}

/// The server's repositories.
#[derive(Debug, Clone)]
pub struct GitHost {
    root: PathBuf,
    hooks: PathBuf,
    max_push_bytes: u64,
}

/// A git command that failed; the message includes its stderr.
#[derive(Debug, thiserror::Error)]
#[error("git {command}: {message}")]
pub struct GitError {
    command: String,
    message: String,
}

impl GitHost {
    /// Repositories under `data_dir/git`; writes the shared hooks.
    pub fn open(data_dir: &Path, max_push_bytes: u64) -> std::io::Result<GitHost> {
        let root = data_dir.join("git");
        let hooks = data_dir.join("git-hooks");
        std::fs::create_dir_all(&root)?;
        std::fs::create_dir_all(&hooks)?;
        for (name, text) in [("pre-receive", PRE_RECEIVE), ("post-receive", POST_RECEIVE)] {
            let path = hooks.join(name);
            std::fs::write(&path, text)?;
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755))?;
        }
        Ok(GitHost { root, hooks, max_push_bytes })
    }

    /// The largest push accepted, in bytes.
    pub fn max_push_bytes(&self) -> u64 {
        self.max_push_bytes
    }

    fn repository(&self, project_id: &str) -> PathBuf {
        self.root.join(format!("{project_id}.git"))
    }

    async fn git(&self, args: &[&str], dir: Option<&Path>) -> Result<Vec<u8>, GitError> {
        let mut command = Command::new("git");
        if let Some(dir) = dir {
            command.arg("-C").arg(dir);
        }
        let output = command
            .args(args)
            .stdin(Stdio::null())
            .output()
            .await
            .map_err(|e| GitError { command: args.join(" "), message: format!("cannot run git: {e}") })?;
        if !output.status.success() {
            return Err(GitError {
                command: args.join(" "),
                message: String::from_utf8_lossy(&output.stderr).trim().to_string(),
            });
        }
        Ok(output.stdout)
    }

    /// Creates the bare repository of a new project.
    pub async fn create(&self, project_id: &str) -> Result<(), GitError> {
        let path = self.repository(project_id);
        let path_text = path.to_string_lossy().into_owned();
        self.git(&["init", "--quiet", "--bare", "--initial-branch=main", &path_text], None).await?;
        let max = self.max_push_bytes.to_string();
        let hooks = self.hooks.to_string_lossy().into_owned();
        for (key, value) in [
            ("http.receivepack", "true"),
            ("receive.advertisePushOptions", "true"),
            ("receive.maxInputSize", max.as_str()),
            ("receive.fsckObjects", "true"),
            ("core.hooksPath", hooks.as_str()),
        ] {
            self.git(&["config", key, value], Some(&path)).await?;
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
        let out = self.git(&["rev-parse", "--verify", "--quiet", &spec], Some(&self.repository(project_id))).await;
        out.ok().map(|o| String::from_utf8_lossy(&o).trim().to_string())
    }

    /// Every file path at `commit`.
    pub async fn files(&self, project_id: &str, commit: &str) -> Result<Vec<String>, GitError> {
        let out = self.git(&["ls-tree", "-r", "--name-only", "-z", commit], Some(&self.repository(project_id))).await?;
        Ok(out.split(|b| *b == 0).filter(|p| !p.is_empty()).map(|p| String::from_utf8_lossy(p).into_owned()).collect())
    }

    /// The text of `path` at `commit` (at most `max` bytes), if the file exists.
    pub async fn read(&self, project_id: &str, commit: &str, path: &str, max: usize) -> Result<Option<String>, String> {
        let spec = format!("{commit}:{path}");
        match self.git(&["cat-file", "blob", &spec], Some(&self.repository(project_id))).await {
            Ok(bytes) if bytes.len() > max => Err(format!("{path} is larger than {max} bytes")),
            Ok(bytes) => String::from_utf8(bytes).map(Some).map_err(|_| format!("{path} is not UTF-8 text")),
            Err(_) => Ok(None),
        }
    }

    /// Answers one smart-HTTP request for a project's repository with
    /// `git http-backend`; `user` is who authenticated (for git's logs).
    pub async fn serve(&self, project_id: &str, request: GitRequest<'_>, body: Body, user: &str) -> Served {
        let GitRequest { method, rest, query, headers } = request;
        let plain = |status: StatusCode, text: String| Served { response: (status, text).into_response(), push: None };
        let is_push = rest == "git-receive-pack";
        // A cap on the body beyond git's own pack limit (`receive.maxInputSize`),
        // which answers with a message the client prints.
        let cap = (self.max_push_bytes as usize).saturating_mul(2).saturating_add(1 << 20);
        let body = match axum::body::to_bytes(body, cap).await {
            Ok(b) => b,
            Err(_) => {
                return plain(
                    StatusCode::PAYLOAD_TOO_LARGE,
                    format!("push larger than the server's limit of {} bytes\n", self.max_push_bytes),
                )
            }
        };
        // Only a push has hooks to report through.
        let record = match is_push.then(|| tempfile::NamedTempFile::new_in(&self.root)).transpose() {
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
            .env("CONTENT_LENGTH", body.len().to_string())
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
            let _ = stdin.write_all(&body).await;
        });
        let stderr_task = tokio::spawn(async move {
            let mut text = String::new();
            let _ = stderr.read_to_string(&mut text).await;
            text
        });

        // CGI headers, then the body.
        let mut reader = BufReader::new(stdout);
        let mut response = Response::builder();
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
            } else {
                response = response.header(name, value);
            }
        }
        response = response.status(status);

        if !is_push {
            // Fetches stream: a clone can be large.
            tokio::spawn(async move {
                let _ = child.wait().await;
                let errors = stderr_task.await.unwrap_or_default();
                if !errors.trim().is_empty() {
                    tracing::debug!("git http-backend: {}", errors.trim());
                }
            });
            let stream = tokio_util::io::ReaderStream::new(reader);
            let response =
                response.body(Body::from_stream(stream)).unwrap_or_else(|_| StatusCode::BAD_GATEWAY.into_response());
            return Served { response, push: None };
        }

        // Pushes answer little; wait for the hooks to finish so the record is complete.
        let mut output = Vec::new();
        let _ = reader.read_to_end(&mut output).await;
        let exit = child.wait().await;
        let errors = stderr_task.await.unwrap_or_default();
        if !errors.trim().is_empty() {
            tracing::debug!("git http-backend (push): {}", errors.trim());
        }
        let push = match exit {
            Ok(s) if s.success() => record
                .and_then(|r| std::fs::read_to_string(r.path()).ok())
                .filter(|t| !t.is_empty())
                .map(|t| PushRecord::parse(&t)),
            _ => None,
        };
        let response = response.body(Body::from(output)).unwrap_or_else(|_| StatusCode::BAD_GATEWAY.into_response());
        Served { response, push }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_records_parse() {
        let record = PushRecord::parse(
            "ref 0000 abcd refs/heads/main\nref abcd 0000 refs/heads/old\noption FBKSD_RUN\noption FBKSD_PUBLISH=x\n",
        );
        assert_eq!(record.updates.len(), 2);
        assert_eq!(record.updates[0].name, "refs/heads/main");
        assert_eq!(record.options, ["FBKSD_RUN", "FBKSD_PUBLISH=x"]);
    }
}
