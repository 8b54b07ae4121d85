//! Shared memory: files in the rendezvous directory mapped by every process.
//!
//! Two regions exist per technique session: the **ring** (`slot_count`
//! slots of `slot_bytes` each, holding tiles of samples) and the **result**
//! (`width × height × 3` floats, scanline RGB). Ownership of a slot moves
//! between processes only by control messages (see `sdk/PROTOCOL.md`), so at
//! any time exactly one process may touch a slot; the accessors here are
//! `unsafe` because that rule is kept by the protocol, not by the types.

use memmap2::{MmapOptions, MmapRaw};
use serde::{Deserialize, Serialize};
use std::fs::{File, OpenOptions};
use std::io;
use std::path::{Path, PathBuf};

/// A mapped shared-memory file.
#[derive(Debug)]
pub struct SharedRegion {
    map: MmapRaw,
    path: PathBuf,
}

// The region is plain memory; who may touch which bytes is decided by the protocol.
unsafe impl Send for SharedRegion {}
unsafe impl Sync for SharedRegion {}

/// Opening a region failed.
#[derive(Debug, thiserror::Error)]
pub enum ShmError {
    /// The file could not be created, opened or mapped.
    #[error("shared memory {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        source: io::Error,
    },
    /// The file has another size than announced.
    #[error("shared memory {path} has {actual} bytes, expected {expected}")]
    Size {
        /// The file.
        path: PathBuf,
        /// Announced size.
        expected: u64,
        /// Size on disk.
        actual: u64,
    },
    /// A name that would leave the rendezvous directory.
    #[error("shared memory name {0:?} is not a plain file name")]
    BadName(String),
}

impl SharedRegion {
    /// Creates a zero-filled file of `len` bytes (it must not exist) and maps it.
    pub fn create(path: &Path, len: u64) -> Result<Self, ShmError> {
        Self::map(create_file(path, len)?, path, len)
    }

    /// Opens and maps an existing file, checking its size.
    pub fn open(path: &Path, expected_len: u64) -> Result<Self, ShmError> {
        let io = |source| ShmError::Io { path: path.to_path_buf(), source };
        let file = OpenOptions::new().read(true).write(true).open(path).map_err(io)?;
        let actual = file.metadata().map_err(io)?.len();
        if actual != expected_len {
            return Err(ShmError::Size { path: path.to_path_buf(), expected: expected_len, actual });
        }
        Self::map(file, path, expected_len)
    }

    fn map(file: File, path: &Path, len: u64) -> Result<Self, ShmError> {
        if len == 0 {
            return Err(ShmError::Size { path: path.to_path_buf(), expected: 1, actual: 0 });
        }
        // Not populated: a process's peak RSS then counts only the pages it
        // really touched (peak memory is one of the benchmark's measures).
        let map = MmapOptions::new()
            .len(len as usize)
            .map_raw(&file)
            .map_err(|source| ShmError::Io { path: path.to_path_buf(), source })?;
        Ok(SharedRegion { map, path: path.to_path_buf() })
    }

    /// Size in bytes.
    pub fn len(&self) -> usize {
        self.map.len()
    }

    /// Whether the region is empty (never: regions have at least one byte).
    pub fn is_empty(&self) -> bool {
        self.map.len() == 0
    }

    /// The mapped file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// `count` floats starting at byte `offset`.
    ///
    /// # Safety
    /// The caller must own these bytes under the protocol: no other process
    /// writes them while the slice lives.
    pub unsafe fn floats(&self, offset: usize, count: usize) -> &[f32] {
        assert!(offset % 4 == 0 && offset + count * 4 <= self.len(), "range outside shared region");
        // SAFETY: in bounds and aligned (mappings are page-aligned); exclusivity by the caller.
        unsafe { std::slice::from_raw_parts(self.map.as_ptr().add(offset) as *const f32, count) }
    }

    /// `count` mutable floats starting at byte `offset`.
    ///
    /// # Safety
    /// As [`Self::floats`], and no other slice of these bytes may be alive.
    #[allow(clippy::mut_from_ref)]
    pub unsafe fn floats_mut(&self, offset: usize, count: usize) -> &mut [f32] {
        assert!(offset % 4 == 0 && offset + count * 4 <= self.len(), "range outside shared region");
        // SAFETY: in bounds and aligned; exclusivity by the caller.
        unsafe { std::slice::from_raw_parts_mut(self.map.as_mut_ptr().add(offset) as *mut f32, count) }
    }
}

/// Where and how large the tile ring is. Sent to both peers in the layout
/// reply; the file name is relative to the rendezvous directory so that
/// containers may mount the directory anywhere.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct RingSpec {
    /// Session number; the ring file is `ring-<session>.f32`.
    pub session: u64,
    /// Number of slots.
    pub slot_count: u32,
    /// Bytes per slot (a multiple of the page size).
    pub slot_bytes: u64,
}

impl RingSpec {
    /// The ring's file name in the rendezvous directory.
    pub fn file_name(&self) -> String {
        format!("ring-{}.f32", self.session)
    }
    /// Total size in bytes.
    pub fn total_bytes(&self) -> u64 {
        self.slot_count as u64 * self.slot_bytes
    }
    /// How many samples of `sample_size` floats fit in one slot.
    pub fn slot_samples(&self, sample_size: usize) -> u64 {
        self.slot_bytes / (sample_size as u64 * 4)
    }
}

/// The tile ring: `slot_count` equal slots in one shared region.
#[derive(Debug)]
pub struct Ring {
    region: SharedRegion,
    spec: RingSpec,
}

impl Ring {
    /// Creates the ring file in `dir` without mapping it (manager side:
    /// the manager never touches sample data, so it never maps the ring).
    ///
    /// `shared`: the file opens to every user (mode 0666) for a renderer and
    /// a technique that run as other users. The mode is set on the open
    /// file, never by path: someone who can write the directory could swap
    /// the name for a link to another file between creation and a `chmod`.
    pub fn create_file(dir: &Path, spec: RingSpec, shared: bool) -> Result<PathBuf, ShmError> {
        use std::os::unix::fs::PermissionsExt;
        let path = dir.join(spec.file_name());
        let file = create_file(&path, spec.total_bytes())?;
        if shared {
            file.set_permissions(std::fs::Permissions::from_mode(0o666))
                .map_err(|source| ShmError::Io { path: path.clone(), source })?;
        }
        Ok(path)
    }

    /// Maps an existing ring (renderer and technique side).
    pub fn open(dir: &Path, spec: RingSpec) -> Result<Self, ShmError> {
        Ok(Ring { region: SharedRegion::open(&dir.join(spec.file_name()), spec.total_bytes())?, spec })
    }

    /// The ring's geometry.
    pub fn spec(&self) -> RingSpec {
        self.spec
    }

    /// The first `floats` floats of slot `slot`.
    ///
    /// # Safety
    /// The caller must own the slot under the protocol.
    pub unsafe fn slot(&self, slot: u32, floats: usize) -> &[f32] {
        assert!(slot < self.spec.slot_count && floats as u64 * 4 <= self.spec.slot_bytes, "slot out of range");
        // SAFETY: forwarded to the caller.
        unsafe { self.region.floats(slot as usize * self.spec.slot_bytes as usize, floats) }
    }

    /// The first `floats` floats of slot `slot`, writable.
    ///
    /// # Safety
    /// The caller must own the slot under the protocol and hold no other slice of it.
    #[allow(clippy::mut_from_ref)]
    pub unsafe fn slot_mut(&self, slot: u32, floats: usize) -> &mut [f32] {
        assert!(slot < self.spec.slot_count && floats as u64 * 4 <= self.spec.slot_bytes, "slot out of range");
        // SAFETY: forwarded to the caller.
        unsafe { self.region.floats_mut(slot as usize * self.spec.slot_bytes as usize, floats) }
    }
}

/// Creates a zero-filled file of `len` bytes, which must not exist yet,
/// open for reading and writing.
pub fn create_file(path: &Path, len: u64) -> Result<File, ShmError> {
    let io = |source| ShmError::Io { path: path.to_path_buf(), source };
    let file = OpenOptions::new().read(true).write(true).create_new(true).open(path).map_err(io)?;
    file.set_len(len).map_err(io)?;
    Ok(file)
}

/// Rejects names that are not a single path component.
pub fn plain_file_name(name: &str) -> Result<&str, ShmError> {
    if name.is_empty() || name.contains('/') || name == "." || name == ".." {
        return Err(ShmError::BadName(name.to_string()));
    }
    Ok(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_mappings_see_the_same_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let spec = RingSpec { session: 7, slot_count: 2, slot_bytes: 4096 };
        Ring::create_file(dir.path(), spec, false).unwrap();
        let a = Ring::open(dir.path(), spec).unwrap();
        let b = Ring::open(dir.path(), spec).unwrap();
        unsafe {
            a.slot_mut(1, 3).copy_from_slice(&[1.0, 2.0, 3.0]);
            assert_eq!(b.slot(1, 3), &[1.0, 2.0, 3.0]);
            assert_eq!(b.slot(0, 3), &[0.0, 0.0, 0.0]);
        }
    }

    #[test]
    fn size_mismatch_is_reported() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r");
        SharedRegion::create(&path, 100).unwrap();
        let e = SharedRegion::open(&path, 200).unwrap_err().to_string();
        assert!(e.contains("100") && e.contains("200"), "{e}");
    }

    #[test]
    fn names_must_stay_inside() {
        assert!(plain_file_name("../x").is_err());
        assert!(plain_file_name("ring-1.f32").is_ok());
    }
}
