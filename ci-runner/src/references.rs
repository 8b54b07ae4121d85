//! The references of the runner's scene pool, made once for the whole
//! service.
//!
//! At start ([`prepare`]) the runner asks each scene's renderer for the
//! scene's reference key (`fbksd-<renderer> reference --key`), and the
//! server for each key (with the scene's name). A reference beside the
//! scene with that key is kept when it is the one the server stores; else
//! the stored one is downloaded, checked against its SHA-256 and its
//! note's key, and written beside the scene; one not stored yet is made by
//! whichever runner claims its `reference` job first — this runner too,
//! which meanwhile claims nothing else (and only uploads a current one). So
//! a new runner renders no reference the service already has, and every
//! runner scores against the same image, the only one the server accepts
//! results against.
//!
//! Reference jobs ([`make_and_upload`]) run the renderer's `reference`
//! command on the host (no technique runs, so no sandbox) and upload the
//! reference, its note and its feature buffers under the names of
//! [`fbksd_exchange::runner_api`]. A ready runner takes them too (before
//! any other job): its reference is current, so it only uploads it.

use crate::api::Api;
use crate::job::{Failure, JobLog};
use fbksd_exchange::runner_api::{
    reference_buffer_file, Claim, ClaimRequest, ReferenceRequest, ReferenceState, ReferenceStatus, REFERENCE_IMAGE,
    REFERENCE_NOTE,
};
use fbksd_exchange::scenes::{ReferenceMethod, SceneMeta, FEATURE_BUFFERS};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// A scene of the pool and the key of its reference.
#[derive(Debug, Clone)]
pub struct SceneReference {
    /// Its directory relative to the scene root.
    pub rel: String,
    /// Its reference's key ([`fbksd_exchange::scenes::reference_key`]).
    pub key: String,
    /// Its metadata.
    pub meta: SceneMeta,
}

impl SceneReference {
    /// Whether the reference beside the scene is the one of its key.
    fn is_current(&self) -> bool {
        let note = self.meta.reference_note_file();
        self.meta.reference_file().is_file()
            && std::fs::read(note)
                .ok()
                .and_then(|n| fbksd_exchange::scenes::note_reference_key(&n).ok())
                .is_some_and(|k| k == self.key)
    }

    /// `sha256:<hex>` of the reference beside the scene, if there is one.
    fn local_hash(&self) -> Option<String> {
        let image = std::fs::read(self.meta.reference_file()).ok()?;
        Some(format!("sha256:{:x}", Sha256::digest(&image)))
    }

    /// "experimental/sphere (500×500, closed form sphere_time)", for people.
    fn describe(&self) -> String {
        let budget = match &self.meta.reference {
            ReferenceMethod::Render { spp } => format!("{spp} spp"),
            ReferenceMethod::ClosedForm { formula } => format!("closed form {formula}"),
        };
        format!("{} ({}×{}, {budget})", self.rel, self.meta.width, self.meta.height)
    }
}

/// The reference keys of the scenes `dirs` (relative to `root`), from
/// their renderers (one call per renderer).
pub async fn keys(root: &Path, dirs: &[String]) -> anyhow::Result<Vec<SceneReference>> {
    let mut scenes = Vec::new();
    for rel in dirs {
        let meta = SceneMeta::load(&root.join(rel)).map_err(|e| anyhow::anyhow!("scene pool: {e}"))?;
        scenes.push((rel.clone(), meta));
    }
    let mut renderers: Vec<&str> = scenes.iter().map(|(_, m)| m.renderer.as_str()).collect();
    renderers.sort();
    renderers.dedup();
    let mut keys = std::collections::BTreeMap::new();
    for renderer in renderers {
        let program =
            fbksd_exchange::scenes::renderer_program(renderer).map_err(|e| anyhow::anyhow!("scene pool: {e}"))?;
        let dirs: Vec<PathBuf> =
            scenes.iter().filter(|(_, m)| m.renderer == renderer).map(|(rel, _)| root.join(rel)).collect();
        let out = tokio::process::Command::new(&program).arg("reference").arg("--key").args(&dirs).output().await?;
        if !out.status.success() {
            anyhow::bail!(
                "scene pool: {} reference --key failed ({}): {}",
                program.display(),
                out.status,
                String::from_utf8_lossy(&out.stderr).trim()
            );
        }
        // One "<key> <dir>" line per scene, in order.
        for (line, dir) in String::from_utf8_lossy(&out.stdout).lines().zip(&dirs) {
            let key = line.split_whitespace().next().unwrap_or_default().to_string();
            keys.insert(dir.clone(), key);
        }
    }
    scenes
        .into_iter()
        .map(|(rel, meta)| {
            let key = keys.remove(&root.join(&rel)).filter(|k| k.starts_with("sha256:"));
            let key = key.ok_or_else(|| anyhow::anyhow!("scene pool: no reference key for {rel}"))?;
            Ok(SceneReference { rel, key, meta })
        })
        .collect()
}

/// Makes every scene's reference present, current and the service's
/// before the runner takes jobs: kept when it is the one the service
/// stores, else downloaded from the service, or made here for the service
/// as its reference job (a current one beside the scene is then only
/// uploaded). The server refuses results scored against any other image.
/// Tells the server what it waits for.
pub async fn prepare(root: &Path, scenes: &[SceneReference], api: &Api, runner_token: &str) -> anyhow::Result<()> {
    let mut missing: Vec<&SceneReference> = scenes.iter().collect();
    let mut total = None;
    let mut made = 0;
    while !missing.is_empty() {
        let mut building = Vec::new();
        for scene in missing {
            let request = ReferenceRequest {
                key: scene.key.clone(),
                scene: scene.rel.clone(),
                name: fbksd_exchange::results::path_safe_name(&scene.meta.name),
            };
            let status = api.request_reference(runner_token, &request).await?;
            match status.state {
                ReferenceState::Ready if scene.is_current() && scene.local_hash() == status.reference_hash => {}
                ReferenceState::Ready => {
                    install(api, runner_token, scene, &status).await?;
                    tracing::info!("reference of {} downloaded ({})", scene.rel, status.key);
                }
                ReferenceState::Building => building.push(scene),
                ReferenceState::Failed => anyhow::bail!(
                    "scene pool: the service's reference job {} for {} failed: {} (restart this runner to try again)",
                    status.job_id,
                    scene.rel,
                    status.message
                ),
            }
        }
        let total = *total.get_or_insert(building.len());
        missing = building;
        if missing.is_empty() {
            break;
        }
        let waiting = format!(
            "waiting for {} reference{} made by another runner: {}",
            missing.len(),
            if missing.len() == 1 { "" } else { "s" },
            missing.iter().map(|s| s.rel.as_str()).collect::<Vec<_>>().join(", ")
        );
        if let Err(e) = api.status(runner_token, Some(&waiting)).await {
            tracing::warn!("telling the server what this runner prepares: {e}");
        }
        // Take one of them if no runner has yet; nothing else meanwhile.
        let request = ClaimRequest {
            wait_seconds: 5,
            reference_keys: missing.iter().map(|s| s.key.clone()).collect(),
            references_only: true,
            runner_class: None,
            more_seeds: false,
        };
        if let Some(claim) = api.claim(runner_token, &request).await? {
            made += 1;
            let progress = Progress { runner_token, text: format!("making reference {made} of {total}") };
            let log = JobLog::default();
            let work = make_and_upload(api, &claim, root, scenes, &log, Some(&progress));
            crate::runner::drive(api, &claim, &log, work).await;
        }
    }
    // A kept or downloaded reference is still handed to its renderer, which
    // keeps it (it is current) and makes only the feature buffers it lacks.
    for scene in scenes {
        let program = fbksd_exchange::scenes::renderer_program(&scene.meta.renderer)
            .map_err(|e| anyhow::anyhow!("scene pool: the reference of {}: {e}", scene.rel))?;
        let dir = root.join(&scene.rel);
        let out = tokio::process::Command::new(&program).arg("reference").arg(&dir).output().await?;
        if !out.status.success() {
            anyhow::bail!(
                "scene pool: {} reference {} failed ({}): {}",
                program.display(),
                dir.display(),
                out.status,
                String::from_utf8_lossy(&out.stderr).trim()
            );
        }
    }
    Ok(())
}

/// What a runner still preparing tells the server while it makes a reference.
pub struct Progress<'a> {
    /// The runner's token.
    pub runner_token: &'a str,
    /// "making reference 1 of 3", completed with the scene.
    pub text: String,
}

/// A reference job: makes the claimed reference here (or keeps the current
/// one) and uploads its files; the success message.
pub async fn make_and_upload(
    api: &Api,
    claim: &Claim,
    root: &Path,
    scenes: &[SceneReference],
    log: &JobLog,
    progress: Option<&Progress<'_>>,
) -> Result<String, Failure> {
    let task = claim.reference.as_ref().ok_or_else(|| Failure::infrastructure("a reference job without its task"))?;
    // Another runner may have the scene: this one gives the job back.
    let scene = scenes.iter().find(|s| s.key == task.key).ok_or_else(|| {
        Failure::infrastructure(format!("this runner has no scene whose reference is {} ({})", task.key, task.scene))
    })?;
    let status = format!("{}: {}", progress.map_or("making reference", |p| p.text.as_str()), scene.describe());
    tracing::info!("{status}");
    log.line(format!("[fbksd-ci] {status}"));
    let program = fbksd_exchange::scenes::renderer_program(&scene.meta.renderer).map_err(Failure::infrastructure)?;
    let dir = root.join(&scene.rel);
    let mut child = tokio::process::Command::new(&program)
        .arg("reference")
        .arg(&dir)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .kill_on_drop(true)
        .spawn()
        .map_err(|e| Failure::infrastructure(format!("{}: {e}", program.display())))?;
    let output = async {
        let (mut out, mut err) = (child.stdout.take().unwrap(), child.stderr.take().unwrap());
        let (mut a, mut b) = (Vec::new(), Vec::new());
        let _ = tokio::join!(
            tokio::io::AsyncReadExt::read_to_end(&mut out, &mut a),
            tokio::io::AsyncReadExt::read_to_end(&mut err, &mut b)
        );
        a.extend(b);
        (child.wait().await, a)
    };
    tokio::pin!(output);
    let (exit, printed) = loop {
        if let Some(p) = progress {
            if let Err(e) = api.status(p.runner_token, Some(&status)).await {
                tracing::warn!("telling the server what this runner prepares: {e}");
            }
        }
        tokio::select! {
            done = &mut output => break done,
            () = tokio::time::sleep(Duration::from_secs(5)) => {}
        }
    };
    log.line(String::from_utf8_lossy(&printed).trim_end());
    let exit = exit.map_err(|e| Failure::infrastructure(format!("{}: {e}", program.display())))?;
    if !exit.success() {
        return Err(Failure::infrastructure(format!(
            "{} reference {} failed ({exit})",
            program.display(),
            dir.display()
        )));
    }
    if !scene.is_current() {
        return Err(Failure::infrastructure(format!(
            "{} made a reference of {} whose note is not of key {}",
            program.display(),
            scene.rel,
            scene.key
        )));
    }
    let mut files = vec![(REFERENCE_IMAGE.to_string(), scene.meta.reference_file())];
    for buffer in FEATURE_BUFFERS {
        let file = scene.meta.feature_buffer_file(buffer);
        if file.is_file() {
            files.push((reference_buffer_file(buffer), file));
        }
    }
    // The note last: the server takes the reference whole or not at all.
    files.push((REFERENCE_NOTE.to_string(), scene.meta.reference_note_file()));
    for (name, path) in files {
        let bytes = std::fs::read(&path).map_err(|e| Failure::infrastructure(format!("{}: {e}", path.display())))?;
        api.put_file(claim, &name, bytes).await?;
    }
    Ok(format!("the reference of {} ({})", scene.rel, task.key))
}

/// Downloads the stored reference of `scene`, checks it, and writes it
/// beside the scene (each file whole: written aside, then renamed; the
/// note, which makes the reference current, last).
async fn install(
    api: &Api,
    runner_token: &str,
    scene: &SceneReference,
    status: &ReferenceStatus,
) -> anyhow::Result<()> {
    let image = api.reference_file(runner_token, &scene.key, REFERENCE_IMAGE).await?;
    let hash = format!("sha256:{:x}", Sha256::digest(&image));
    if status.reference_hash.as_deref() != Some(hash.as_str()) {
        anyhow::bail!(
            "scene pool: the reference of {} downloaded as {hash}, but the service stores {:?}",
            scene.rel,
            status.reference_hash
        );
    }
    let note = api.reference_file(runner_token, &scene.key, REFERENCE_NOTE).await?;
    let made = fbksd_exchange::scenes::note_reference_key(&note)
        .map_err(|e| anyhow::anyhow!("scene pool: the downloaded note of {}: {e}", scene.rel))?;
    if made != scene.key {
        anyhow::bail!("scene pool: the downloaded note of {} describes {made}, not {}", scene.rel, scene.key);
    }
    write_whole(&scene.meta.reference_file(), &image)?;
    for buffer in FEATURE_BUFFERS {
        let name = reference_buffer_file(buffer);
        let file = scene.meta.feature_buffer_file(buffer);
        if status.files.contains(&name) {
            let bytes = api.reference_file(runner_token, &scene.key, &name).await?;
            write_whole(&file, &bytes)?;
        } else {
            // Made with a reference this one replaces: the renderer makes it again.
            let _ = std::fs::remove_file(&file);
        }
    }
    write_whole(&scene.meta.reference_note_file(), &note)
}

fn write_whole(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    // Its own name: two runners may share a scene folder.
    let tmp = path.with_extension(format!("download-{}", std::process::id()));
    std::fs::write(&tmp, bytes).map_err(|e| anyhow::anyhow!("{}: {e}", tmp.display()))?;
    std::fs::rename(&tmp, path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}
