//! The one way a file or directory appears under its final name: written under a temporary
//! sibling name, synced, renamed, and the parent directory synced so that the rename itself is
//! durable. A reader therefore sees either nothing or the complete file; a killed run leaves at
//! most a temporary file (`NAME.tmp-<pid>`), which [`AtomicFile`] removes when dropped without
//! [`AtomicFile::commit`].
//!
//! Every output scanflow writes goes through here: meshes and point clouds, synthetic truths,
//! store cells and manifests, checkpoints and tile meshes in the work directory, and the store
//! directory itself ([`TempDir`]).
//!
//! **Interrupts.** Every temporary file and directory is created, renamed and removed through
//! one table of the process's live temporary paths. [`remove_live_temps`] (called by the
//! command line on SIGINT or SIGTERM, just before it exits) removes them all and closes the
//! table, so that no temporary name can appear or be committed afterwards: an interrupted run
//! leaves no temporary file. A run killed outright (SIGKILL, power loss) leaves its
//! temporary names behind; [`remove_stale_temps`] removes those of dead processes when the
//! next run of the same output, or the resume, starts.

use std::collections::BTreeSet;
use std::ffi::OsString;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

use crate::error::{Error, IoContext, Result};

/// The live temporary paths of this process, and whether an interrupt closed the table.
struct Live {
    paths: BTreeSet<PathBuf>,
    closed: bool,
}

static LIVE: Mutex<Live> = Mutex::new(Live {
    paths: BTreeSet::new(),
    closed: false,
});

/// The table, whatever a panicking thread left it as.
fn live() -> MutexGuard<'static, Live> {
    LIVE.lock().unwrap_or_else(|p| p.into_inner())
}

/// The error for any temporary name wanted after an interrupt.
fn interrupted(path: &Path) -> std::io::Error {
    std::io::Error::new(
        std::io::ErrorKind::Interrupted,
        format!("{}: not written: the run was interrupted", path.display()),
    )
}

/// Create (truncating) the temporary file `tmp`, recorded as live.
pub fn create_temp_file(tmp: &Path) -> Result<File> {
    let mut t = live();
    if t.closed {
        return Err(Error::io(tmp, interrupted(tmp)));
    }
    let f = File::options()
        .read(true)
        .write(true)
        .create(true)
        .truncate(true)
        .open(tmp)
        .with_path(tmp)?;
    t.paths.insert(tmp.to_path_buf());
    Ok(f)
}

/// Rename the live temporary `tmp` to `path` (a file or a directory); it is no longer live.
fn rename_live(tmp: &Path, path: &Path) -> Result<()> {
    let mut t = live();
    if t.closed {
        return Err(Error::io(path, interrupted(path)));
    }
    std::fs::rename(tmp, path).with_path(path)?;
    t.paths.remove(tmp);
    Ok(())
}

/// Remove the live temporary file or directory `tmp` (best effort: it may be gone).
pub fn remove_temp(tmp: &Path) {
    let mut t = live();
    if t.paths.remove(tmp) {
        remove_path(tmp);
    }
}

/// Remove a file or a directory tree, ignoring errors.
fn remove_path(p: &Path) {
    match std::fs::symlink_metadata(p) {
        Ok(m) if m.is_dir() => drop(std::fs::remove_dir_all(p)),
        Ok(_) => drop(std::fs::remove_file(p)),
        Err(_) => {}
    }
}

/// Remove every live temporary file and directory of this process and close the table: from
/// now on no temporary name is created and none is committed. For the command line's
/// SIGINT/SIGTERM handler, which exits right after. Returns how many were removed.
pub fn remove_live_temps() -> usize {
    let mut t = live();
    t.closed = true;
    let paths = std::mem::take(&mut t.paths);
    // Keep the table locked until the process exits: a thread in the middle of a rename or a
    // create waits here instead of finishing it.
    std::mem::forget(t);
    for p in &paths {
        remove_path(p);
    }
    paths.len()
}

/// Whether the process `pid` is alive. Without `/proc` (not Linux) nobody can tell, and every
/// process counts as alive, so nothing is removed.
fn alive(pid: u32) -> bool {
    let proc = Path::new("/proc");
    !proc.join("self").exists() || proc.join(pid.to_string()).exists()
}

/// Suffixes of the staging files a writer keeps beside its temporary file (the mesh writer's
/// vertices, faces and normals): `NAME.tmp-<pid>.vertices` belongs to `NAME.tmp-<pid>`.
pub const STAGING_SUFFIXES: [&str; 3] = [".vertices", ".faces", ".normals"];

/// The pid in a temporary name `NAME.tmp-<pid>[@<host>][.vertices|.faces|.normals]` of
/// `name`, if `file` is one made on this host (another host's process cannot be checked: it
/// counts as alive).
fn temp_pid(file: &str, name: &str) -> Option<u32> {
    let rest = file.strip_prefix(name)?.strip_prefix(".tmp-")?;
    let rest = STAGING_SUFFIXES
        .iter()
        .find_map(|s| rest.strip_suffix(s))
        .unwrap_or(rest);
    let digits = match rest.split_once('@') {
        Some((digits, host)) if host == this_host() => digits,
        Some(_) => return None,
        None => rest,
    };
    digits.parse().ok()
}

/// Whether temporary names carry the host (see [`tag_temps_with_host`]).
static HOST_TAGGED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// From now on, temporary names carry this host's name beside the pid
/// (`NAME.tmp-<pid>@<host>`): for the shards of an array job, whose tasks on several hosts
/// share one work directory and may have the same pid.
pub fn tag_temps_with_host() {
    HOST_TAGGED.store(true, std::sync::atomic::Ordering::Relaxed);
}

/// This host's name, letters, digits and `-` only (`_` for anything else); `unknown` where it
/// cannot be read.
pub fn this_host() -> &'static str {
    static HOST: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    HOST.get_or_init(|| {
        let name = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .ok()
            .or_else(|| std::env::var("HOSTNAME").ok())
            .map(|h| h.trim().to_string())
            .filter(|h| !h.is_empty())
            .unwrap_or_else(|| "unknown".into());
        name.chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' {
                    c
                } else {
                    '_'
                }
            })
            .collect()
    })
}

/// Remove the temporary files and directories that killed processes left for `path` (its
/// `path.tmp-<pid>` names, and the store's `.NAME.tmp-<pid>` directories), and, when
/// `recursive` and `path` is a directory of ours, for everything inside it. Returns what was
/// removed. Live processes' temporaries (a concurrent run) are left alone.
pub fn remove_stale_temps(path: &Path, recursive: bool) -> Vec<PathBuf> {
    let mut removed = Vec::new();
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if let Some(name) = path.file_name().and_then(|n| n.to_str()) {
        stale_in(
            &parent,
            &[name.to_string(), format!(".{name}")],
            &mut removed,
        );
    }
    if recursive && path.is_dir() {
        let mut stack = vec![path.to_path_buf()];
        while let Some(dir) = stack.pop() {
            let Ok(rd) = std::fs::read_dir(&dir) else {
                continue;
            };
            let mut names = Vec::new();
            for e in rd.flatten() {
                let p = e.path();
                if e.file_type().map(|t| t.is_dir()).unwrap_or(false) {
                    stack.push(p);
                }
                if let Some(n) = e.file_name().to_str() {
                    names.push(n.to_string());
                }
            }
            let stems: Vec<String> = names
                .iter()
                .filter_map(|n| n.find(".tmp-").map(|i| n[..i].to_string()))
                .collect();
            stale_in(&dir, &stems, &mut removed);
        }
    }
    removed
}

/// Remove the entries of `dir` that are temporary names of dead processes for one of `names`.
fn stale_in(dir: &Path, names: &[String], removed: &mut Vec<PathBuf>) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    for e in rd.flatten() {
        let Some(file) = e.file_name().to_str().map(str::to_string) else {
            continue;
        };
        let dead = names
            .iter()
            .filter_map(|n| temp_pid(&file, n))
            .any(|pid| pid != std::process::id() && !alive(pid));
        if dead {
            let p = e.path();
            remove_path(&p);
            removed.push(p);
        }
    }
}

/// `path` with `suffix` appended to its file name.
pub fn with_suffix(path: &Path, suffix: &str) -> PathBuf {
    let mut s: OsString = path.as_os_str().to_owned();
    s.push(suffix);
    PathBuf::from(s)
}

/// The temporary name this process writes `path` under: `path` + `.tmp-<pid>`, and
/// `@<host>` after [`tag_temps_with_host`].
pub fn temp_name(path: &Path) -> PathBuf {
    let pid = std::process::id();
    if HOST_TAGGED.load(std::sync::atomic::Ordering::Relaxed) {
        with_suffix(path, &format!(".tmp-{pid}@{}", this_host()))
    } else {
        with_suffix(path, &format!(".tmp-{pid}"))
    }
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
        let file = create_temp_file(&tmp_path)?;
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
        rename_live(&self.tmp_path, &self.final_path)?;
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
            remove_temp(&self.tmp_path);
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

/// Write `bytes` to `path` unless `path` exists, as one step that never replaces it: written
/// under the temporary name, synced, then hard-linked to `path` (`link(2)` fails when the
/// name exists, atomically on local file systems and on NFS), and the temporary name
/// removed. Returns whether this call wrote it; `false`: someone else's file is there, left
/// as it is. For a description several processes publish, the first one winning.
pub fn write_once(path: &Path, bytes: &[u8]) -> Result<bool> {
    use std::io::Write;
    let tmp = temp_name(path);
    let written = create_temp_file(&tmp).and_then(|mut f| {
        f.write_all(bytes).with_path(&tmp)?;
        f.sync_all().with_path(&tmp)
    });
    let linked = written.and_then(|()| match std::fs::hard_link(&tmp, path) {
        Ok(()) => Ok(true),
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Ok(false),
        Err(e) => Err(Error::io(path, e)),
    });
    remove_temp(&tmp);
    if let Ok(true) = linked {
        sync_parent_dir(path);
    }
    linked
}

/// A directory built under the temporary sibling name `.NAME.tmp-<pid>` and renamed to its
/// final name when complete (a store); removed when dropped without [`TempDir::commit`].
#[derive(Debug)]
pub struct TempDir {
    tmp: Option<PathBuf>,
}

impl TempDir {
    /// Create the temporary directory for `path`, replacing a stale one of this process.
    pub fn create(path: &Path) -> Result<TempDir> {
        let name = path
            .file_name()
            .ok_or_else(|| Error::input(path, "output path has no file name"))?
            .to_string_lossy()
            .to_string();
        let tmp = temp_name(&path.with_file_name(format!(".{name}")));
        let mut t = live();
        if t.closed {
            return Err(Error::io(&tmp, interrupted(&tmp)));
        }
        remove_path(&tmp);
        std::fs::create_dir(&tmp).with_path(&tmp)?;
        t.paths.insert(tmp.clone());
        Ok(TempDir { tmp: Some(tmp) })
    }

    /// The temporary directory.
    pub fn path(&self) -> &Path {
        self.tmp.as_deref().unwrap_or(Path::new(""))
    }

    /// Rename the finished directory to `path` and sync the parent, so that it appears under
    /// its name only when complete.
    pub fn commit(mut self, path: &Path) -> Result<()> {
        if let Some(tmp) = self.tmp.take() {
            if let Err(e) = rename_live(&tmp, path) {
                self.tmp = Some(tmp);
                return Err(e);
            }
            sync_parent_dir(path);
        }
        Ok(())
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        if let Some(p) = self.tmp.take() {
            remove_temp(&p);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[test]
    fn write_once_keeps_the_first_file() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("run.json");
        assert!(write_once(&p, b"first").unwrap());
        assert!(!write_once(&p, b"second").unwrap());
        assert_eq!(std::fs::read(&p).unwrap(), b"first");
        let names: Vec<_> = std::fs::read_dir(d.path()).unwrap().flatten().collect();
        assert_eq!(names.len(), 1, "a temporary file was left");
        assert!(write_once(&d.path().join("none").join("x"), b"x").is_err());
    }

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

    #[test]
    fn stale_temps_of_dead_processes_go_and_others_stay() {
        assert_eq!(temp_pid("m.ply.tmp-42", "m.ply"), Some(42));
        assert_eq!(temp_pid("m.ply.tmp-42.faces", "m.ply"), Some(42));
        assert_eq!(temp_pid("m.ply.tmp-42.vertices", "m.ply"), Some(42));
        assert_eq!(temp_pid("m.ply.tmp-42.normals", "m.ply"), Some(42));
        assert_eq!(temp_pid("m.ply.tmp-x", "m.ply"), None);
        assert_eq!(temp_pid("n.ply.tmp-42", "m.ply"), None);
        // Another host's process cannot be checked from here: never stale.
        let here = format!("m.ply.tmp-42@{}.faces", this_host());
        assert_eq!(temp_pid(&here, "m.ply"), Some(42));
        assert_eq!(temp_pid("m.ply.tmp-42@not-this-host-x", "m.ply"), None);
        let d = tempfile::tempdir().unwrap();
        let out = d.path().join("m.ply");
        // A pid above Linux's largest (2^22) belongs to no live process.
        let dead = [
            d.path().join("m.ply.tmp-99999999"),
            d.path().join("m.ply.tmp-99999999.faces"),
        ];
        let live = d.path().join(format!("m.ply.tmp-{}", std::process::id()));
        let other = d.path().join("n.ply.tmp-99999999");
        for p in dead.iter().chain([&live, &other]) {
            std::fs::write(p, b"x").unwrap();
        }
        let dir = d.path().join(".m.ply.tmp-99999999");
        std::fs::create_dir(&dir).unwrap();
        let mut removed = remove_stale_temps(&out, false);
        removed.sort();
        let mut want = vec![dead[0].clone(), dead[1].clone(), dir.clone()];
        want.sort();
        if Path::new("/proc/self").exists() {
            assert_eq!(removed, want);
        }
        assert!(live.exists() && other.exists());
    }
}
