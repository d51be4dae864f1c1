//! The one way a file or directory appears under its final name: written under a temporary
//! sibling name, synced, renamed, and the parent directory synced so that the rename itself is
//! durable. A reader therefore sees either nothing or the complete file; a killed run leaves at
//! most a temporary file (`NAME.tmp-<pid>`), which [`AtomicFile`] removes when dropped without
//! [`AtomicFile::commit`].
//!
//! Every output scanflow writes goes through here: meshes and point clouds, synthetic truths,
//! store cells and manifests, checkpoints and tile meshes in the work directory, and the store
//! directory itself ([`commit_dir`]).

use std::ffi::OsString;
use std::fs::File;
use std::path::{Path, PathBuf};

use crate::error::{IoContext, Result};

/// `path` with `suffix` appended to its file name.
pub fn with_suffix(path: &Path, suffix: &str) -> PathBuf {
    let mut s: OsString = path.as_os_str().to_owned();
    s.push(suffix);
    PathBuf::from(s)
}

/// The temporary name this process writes `path` under: `path` + `.tmp-<pid>`.
pub fn temp_name(path: &Path) -> PathBuf {
    with_suffix(path, &format!(".tmp-{}", std::process::id()))
}

/// Sync the directory holding `path`, so that a rename into it is durable. Best effort: some
/// platforms and file systems cannot open or sync a directory, which is no reason to fail.
pub fn sync_parent_dir(path: &Path) {
    #[cfg(unix)]
    {
        let parent = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        if let Ok(d) = File::open(parent) {
            let _ = d.sync_all();
        }
    }
    #[cfg(not(unix))]
    {
        let _ = path;
    }
}

/// Whether a file is synced before it is renamed into place.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Durability {
    /// Synced, renamed, parent directory synced: the file survives a crash once committed.
    Synced,
    /// Renamed without syncing: for files inside a directory that is itself synced and
    /// committed as a whole later (store cells), where a sync per file would cost a disk
    /// round trip per cell for no gain.
    Renamed,
}

/// A file being written under its temporary name; see the [module docs](self).
#[derive(Debug)]
pub struct AtomicFile {
    final_path: PathBuf,
    tmp_path: PathBuf,
    file: Option<File>,
}

impl AtomicFile {
    /// Create the temporary file for `path` (`path.tmp-<pid>`), truncating a stale one.
    pub fn create(path: &Path) -> Result<AtomicFile> {
        let tmp_path = temp_name(path);
        let file = File::create(&tmp_path).with_path(&tmp_path)?;
        Ok(AtomicFile {
            final_path: path.to_path_buf(),
            tmp_path,
            file: Some(file),
        })
    }

    /// The name the file gets on commit.
    pub fn path(&self) -> &Path {
        &self.final_path
    }

    /// The temporary name it is written under (the name errors while writing refer to).
    pub fn tmp_path(&self) -> &Path {
        &self.tmp_path
    }

    /// The open temporary file.
    pub fn file(&mut self) -> &mut File {
        self.file
            .as_mut()
            .unwrap_or_else(|| unreachable!("the file is open until commit consumes it"))
    }

    /// Sync the file, rename it to its final name and sync the directory.
    pub fn commit(self) -> Result<()> {
        self.commit_with(Durability::Synced)
    }

    /// As [`AtomicFile::commit`], with the sync chosen by `durability`.
    pub fn commit_with(mut self, durability: Durability) -> Result<()> {
        let file = self.file.take();
        if let Some(f) = file {
            if durability == Durability::Synced {
                f.sync_all().with_path(&self.tmp_path)?;
            }
            drop(f);
        }
        std::fs::rename(&self.tmp_path, &self.final_path).with_path(&self.final_path)?;
        self.tmp_path = PathBuf::new();
        if durability == Durability::Synced {
            sync_parent_dir(&self.final_path);
        }
        Ok(())
    }
}

/// Writes go to the temporary file; wrap it in a `BufWriter` for small writes.
impl std::io::Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.file().write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file().flush()
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if !self.tmp_path.as_os_str().is_empty() {
            self.file = None;
            let _ = std::fs::remove_file(&self.tmp_path);
        }
    }
}

/// Write `bytes` to `path` atomically (temporary name, then rename), with `durability`.
pub fn write(path: &Path, bytes: &[u8], durability: Durability) -> Result<()> {
    use std::io::Write;
    let mut f = AtomicFile::create(path)?;
    let tmp = f.tmp_path().to_path_buf();
    f.file().write_all(bytes).with_path(&tmp)?;
    f.commit_with(durability)
}

/// Rename the finished directory `tmp` to `path` and sync the parent, so that a directory
/// (a store) appears under its name only when complete.
pub fn commit_dir(tmp: &Path, path: &Path) -> Result<()> {
    std::fs::rename(tmp, path).with_path(path)?;
    sync_parent_dir(path);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[test]
    fn appears_only_on_commit_and_drop_cleans_up() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("out.bin");
        let mut f = AtomicFile::create(&p).unwrap();
        f.file().write_all(b"abc").unwrap();
        assert!(!p.exists() && f.tmp_path().exists());
        f.commit().unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"abc");
        assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 1);

        let q = d.path().join("dropped.bin");
        let f = AtomicFile::create(&q).unwrap();
        let tmp = f.tmp_path().to_path_buf();
        drop(f);
        assert!(!q.exists() && !tmp.exists());

        write(&q, b"xyz", Durability::Renamed).unwrap();
        assert_eq!(std::fs::read(&q).unwrap(), b"xyz");
    }
}
