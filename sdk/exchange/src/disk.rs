//! How much room files take on disk: what a runner lets a checkout or a
//! build directory grow to, and what an account's repositories hold on
//! the server, are counted the same way.

use std::path::Path;

/// Bytes allocated under `dir` (a sparse file costs what it occupies,
/// folders their own blocks), symbolic links counted as links (never
/// followed), what cannot be read as nothing; stops counting past `cap`.
pub fn disk_usage(dir: &Path, cap: u64) -> u64 {
    let mut total = 0;
    let mut stack = vec![dir.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else { continue };
        for entry in entries.flatten() {
            let Ok(meta) = entry.path().symlink_metadata() else { continue };
            if meta.is_dir() {
                stack.push(entry.path());
            }
            total += std::os::unix::fs::MetadataExt::blocks(&meta) * 512;
            if total > cap {
                return total;
            }
        }
    }
    total
}
