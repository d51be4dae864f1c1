//! The work directory of a run (`reconstruct`, `filter`, `resample`, `spectrum`), and who owns
//! it.
//!
//! A work directory holds the store ingested from point files (`store/`), the leaf and tile
//! checkpoints (`leaves/`, `tiles/`) or the spectral patches (`patches/`, and
//! `resampled.bin` while a resampling writes), the run's identity (`run.json`) and its plan
//! (`solve.json`). scanflow removes only what it created and marked as its own:
//!
//! - A work directory scanflow creates gets a marker file ([`MARKER`]) before anything else.
//! - An existing directory without the marker (a scratch directory, the directory holding the
//!   inputs, the one receiving the output) is never used as the work directory itself: the
//!   run works in a subdirectory it creates inside, named after the output
//!   ([`resolve`]), and never removes the directory the user named.
//! - On success the run removes the entries it knows (marker, run description, store,
//!   checkpoints) and then the directory only if that left it empty; anything else found in
//!   it stays, with a warning.
//!
//! **Resume identity.** `run.json` records the version, every input's canonical path, size,
//! modification time and a content fingerprint, and every option that changes the output's
//! bytes. `--resume` compares it with the run being started and refuses, naming what differs,
//! before anything in the directory is used. The fingerprint is the CRC-32 of the size and of
//! 16 windows of 64 KiB spread evenly over the
//! file, first and last included: a change that keeps the size, the modification time and
//! every sampled byte is not seen, but the check costs the same 1 MiB read for a
//! hundred-gigabyte scan as for a small one, at the start and at every resume.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::reconstruct::RunParams;
use crate::error::{Error, IoContext, Result, Setting};
use crate::fs::atomic::{self, Durability};
use crate::io::InputSpec;
use crate::normals::{NormalParams, NormalsMode};
use crate::recon::Plan;
use crate::store::Store;
use crate::store::manifest::MANIFEST;

/// The file that marks a directory as a scanflow work directory, created first.
pub const MARKER: &str = ".scanflow-work";

/// What the marker says.
const MARKER_TEXT: &[u8] = b"scanflow work directory: scanflow removes it when the run succeeds\n";

/// The run's identity: inputs, options and version.
const RUN_FILE: &str = "run.json";

/// The plan and the store the checkpoints were made with.
const SOLVE_FILE: &str = "solve.json";

/// Leaf checkpoints.
const LEAVES: &str = "leaves";

/// Tile checkpoints.
const TILES: &str = "tiles";

/// The shards' claims on work items.
const CLAIMS: &str = "claims";

/// The tile checkpoints of the work directory `dir`.
pub fn tiles_dir(dir: &Path) -> PathBuf {
    dir.join(TILES)
}

/// Spectral patch checkpoints.
pub const PATCHES: &str = "patches";

/// The file resampled points wait in until their count, which the output's header needs, is
/// known.
pub const RESAMPLED: &str = "resampled.bin";

/// The store a reconstruction ingests its point files into.
pub const WORK_STORE: &str = "store";

/// The split ingest's directory.
pub const INGEST_DIR: &str = "ingest";

/// The description `merge` reads.
pub const MERGE_FILE: &str = "merge.json";

/// Windows read for an input's fingerprint.
const FINGERPRINT_WINDOWS: u64 = 16;

/// Bytes per fingerprint window.
const FINGERPRINT_WINDOW_BYTES: u64 = 64 << 10;

/// How many differences a refused resume lists.
const DIFFS_SHOWN: usize = 4;

/// The work directory a run uses when `requested` is named: `requested` itself when it does
/// not exist yet or is a scanflow work directory; inside an existing directory of someone
/// else's, a subdirectory named after the output (`OUTPUT-NAME.work`). An existing
/// non-directory is refused.
pub fn resolve(requested: &Path, output: &Path) -> Result<PathBuf> {
    match std::fs::symlink_metadata(requested) {
        Err(_) => Ok(requested.to_path_buf()),
        Ok(m) if !m.is_dir() => Err(Error::input(
            requested,
            format!("{} exists and is not a directory", Setting::WorkDir),
        )),
        Ok(_) if requested.join(MARKER).exists() => Ok(requested.to_path_buf()),
        Ok(_) => {
            let name = output
                .file_name()
                .ok_or_else(|| Error::Usage(format!("-o {}: no file name", output.display())))?;
            Ok(requested.join(atomic::with_suffix(Path::new(name), ".work")))
        }
    }
}

/// Whether `dir` is a work directory scanflow made.
pub fn is_work_dir(dir: &Path) -> bool {
    dir.join(MARKER).is_file()
}

/// What a reconstruction reads its points from.
#[derive(Debug, Clone)]
pub enum StoreSource {
    /// A store made by `ingest`, used as it is.
    Store(PathBuf),
    /// Point files, ingested into the work directory first.
    Points(Vec<InputSpec>),
}

/// What a run is made of: inputs, options and version, as `name → value` pairs.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RunIdentity {
    entries: BTreeMap<String, String>,
}

impl RunIdentity {
    /// The identity of a run of any command: its inputs, the normal options when it ingests
    /// them, and `options`, every option that changes its output.
    pub fn with_options(
        source: &StoreSource,
        normals: NormalsMode,
        normal_params: &NormalParams,
        options: &[(impl AsRef<str>, String)],
    ) -> Result<RunIdentity> {
        let mut e = BTreeMap::new();
        let mut put = |k: &str, v: String| e.insert(k.to_string(), v);
        put("scanflow", env!("CARGO_PKG_VERSION").to_string());
        for (k, v) in options {
            put(k.as_ref(), v.clone());
        }
        match source {
            StoreSource::Store(dir) => {
                let manifest = dir.join(MANIFEST);
                put("store", canonical(dir)?);
                put(
                    "store manifest",
                    file_identity(&manifest, "a store manifest")?,
                );
            }
            StoreSource::Points(specs) => {
                put(Setting::Normals.name(), format!("{normals:?}"));
                put(Setting::Neighbours.name(), normal_params.k.to_string());
                put(
                    Setting::RobustNormals.name(),
                    normal_params.robust.to_string(),
                );
                put(
                    Setting::FixedNeighbours.name(),
                    (!normal_params.adaptive).to_string(),
                );
                for (i, s) in specs.iter().enumerate() {
                    let n = i + 1;
                    put(&format!("input {n}"), canonical(&s.path)?);
                    put(
                        &format!("input {n} content"),
                        file_identity(&s.path, "a point file")?,
                    );
                    put(&format!("input {n} pose"), format!("{:?}", s.transform));
                    put(
                        &format!("input {n} viewpoint"),
                        format!("{:?}", s.viewpoint),
                    );
                }
            }
        }
        Ok(RunIdentity { entries: e })
    }

    /// What differs from `other` (this run's value second), at most [`DIFFS_SHOWN`] items.
    fn differences(&self, now: &RunIdentity) -> Vec<String> {
        let keys: std::collections::BTreeSet<&String> =
            self.entries.keys().chain(now.entries.keys()).collect();
        let none = String::from("(none)");
        keys.into_iter()
            .filter_map(|k| {
                let (a, b) = (
                    self.entries.get(k).unwrap_or(&none),
                    now.entries.get(k).unwrap_or(&none),
                );
                // A setting's key is its name; the message shows it as the front end does.
                let shown = Setting::from_name(k).map_or_else(|| k.to_string(), |s| s.to_string());
                (a != b).then(|| format!("{shown}: {a} then, {b} now"))
            })
            .take(DIFFS_SHOWN)
            .collect()
    }
}

/// `path` made absolute with symbolic links resolved, as text.
fn canonical(path: &Path) -> Result<String> {
    Ok(std::fs::canonicalize(path)
        .with_path(path)?
        .to_string_lossy()
        .into_owned())
}

/// Size, modification time and fingerprint of the file `path` (`what` it should be), as text.
fn file_identity(path: &Path, what: &str) -> Result<String> {
    // Never opens a FIFO or a device (opening a FIFO blocks).
    let meta = crate::io::regular_file(path, what)?;
    let modified = meta
        .modified()
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    let len = meta.len();
    Ok(format!(
        "{len} bytes, modified {modified} ns, fingerprint {:08x}",
        fingerprint(path, len)?
    ))
}

/// The CRC-32 of `len` and of evenly spread windows of the file (see the module docs).
fn fingerprint(path: &Path, len: u64) -> Result<u32> {
    let mut f = File::open(path).with_path(path)?;
    let mut h = crc32fast::Hasher::new();
    h.update(&len.to_le_bytes());
    let window = FINGERPRINT_WINDOW_BYTES.min(len);
    let mut buf = vec![0u8; window as usize];
    let span = len - window;
    let mut last = None;
    for i in 0..FINGERPRINT_WINDOWS {
        let at = span * i / (FINGERPRINT_WINDOWS - 1);
        if last == Some(at) {
            continue;
        }
        last = Some(at);
        f.seek(SeekFrom::Start(at)).with_path(path)?;
        f.read_exact(&mut buf).with_path(path)?;
        h.update(&buf);
    }
    Ok(h.finalize())
}

/// A work directory held by this run; see the [module docs](self).
#[derive(Debug)]
pub struct Lease {
    dir: PathBuf,
}

/// Take the work directory `dir` (from [`resolve`]) for the run `identity`: create and mark
/// it, or, when it holds an earlier run, refuse unless `resume` and the identities match.
/// Stale temporary files that killed runs left in it are removed.
pub fn claim(dir: &Path, identity: &RunIdentity, resume: bool) -> Result<Lease> {
    let run_file = dir.join(RUN_FILE);
    if is_work_dir(dir) {
        let old: Option<RunIdentity> = std::fs::read_to_string(&run_file)
            .ok()
            .and_then(|t| serde_json::from_str(&t).ok());
        match old {
            Some(_) if !resume => {
                return Err(Error::input(
                    dir,
                    format!(
                        "work directory holds another run's files; pass {} to continue that run, or choose another {}",
                        Setting::Resume,
                        Setting::WorkDir
                    ),
                ));
            }
            Some(old) if old != *identity => {
                return Err(Error::input(
                    dir,
                    format!(
                        "cannot resume: the work directory was made for another run ({})",
                        old.differences(identity).join("; ")
                    ),
                ));
            }
            _ => {}
        }
        atomic::remove_stale_temps(dir, true);
    } else {
        let parent = dir.parent().filter(|p| !p.as_os_str().is_empty());
        if let Some(p) = parent.filter(|p| !p.is_dir()) {
            return Err(Error::input(
                dir,
                format!(
                    "cannot create the work directory: {} is not a directory",
                    p.display()
                ),
            ));
        }
        std::fs::create_dir(dir)
            .map_err(|e| Error::input(dir, format!("cannot create the work directory: {e}")))?;
        atomic::write(&dir.join(MARKER), MARKER_TEXT, Durability::Synced)?;
    }
    if !run_file.exists() {
        let text = serde_json::to_string_pretty(identity)
            .map_err(|e| Error::Internal(format!("{RUN_FILE}: {e}")))?;
        atomic::write(&run_file, text.as_bytes(), Durability::Synced)?;
    }
    Ok(Lease {
        dir: dir.to_path_buf(),
    })
}

/// Join the work directory `dir` shared by the shards of a split run of `identity`: the
/// first task to arrive makes and marks it, the others find it; every task checks the run
/// description against its own. Nothing in it is removed (another task may be writing
/// there).
///
/// The directory appears by `rename(2)`, already marked, and the description by `link(2)`
/// ([`atomic::write_once`]), which fails when the name exists, so that two tasks arriving
/// together never both write it and a task never reads half of it; both primitives are
/// atomic on NFS.
pub fn join(dir: &Path, identity: &RunIdentity) -> Result<Lease> {
    if !is_work_dir(dir) {
        // Made with its marker under a temporary name and renamed into place: the directory
        // never appears unmarked, so shards arriving together all resolve `--work-dir` to it
        // ([`resolve`]). A rename onto the directory another shard made first fails (it is
        // not empty), and that one is joined.
        let made = atomic::TempDir::create(dir).and_then(|t| {
            atomic::write(&t.path().join(MARKER), MARKER_TEXT, Durability::Synced)?;
            t.commit(dir)
        });
        if let Err(e) = made
            && !is_work_dir(dir)
        {
            return Err(Error::input(
                dir,
                format!("cannot create the work directory: {e}"),
            ));
        }
    }
    let run_file = dir.join(RUN_FILE);
    if !run_file.exists() {
        let text = serde_json::to_string_pretty(identity)
            .map_err(|e| Error::Internal(format!("{RUN_FILE}: {e}")))?;
        // The first shard's description stays; the others compare theirs with it below.
        atomic::write_once(&run_file, text.as_bytes())?;
    }
    let text = std::fs::read_to_string(&run_file).with_path(&run_file)?;
    let old: RunIdentity = serde_json::from_str(&text)
        .map_err(|e| Error::input(&run_file, format!("unreadable run description: {e}")))?;
    if old != *identity {
        return Err(Error::input(
            dir,
            format!(
                "this shard's run differs from the one the work directory was made for ({}): give every shard the same inputs and options, or another {}",
                old.differences(identity).join("; "),
                Setting::WorkDir
            ),
        ));
    }
    Ok(Lease {
        dir: dir.to_path_buf(),
    })
}

impl Lease {
    /// The work directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Whether a resume could reuse anything: a complete store or a leaf checkpoint.
    pub fn has_checkpoints(&self) -> bool {
        self.dir.join(WORK_STORE).join(MANIFEST).exists()
            || [LEAVES, PATCHES].iter().any(|d| {
                std::fs::read_dir(self.dir.join(d))
                    .map(|mut d| d.next().is_some())
                    .unwrap_or(false)
            })
    }

    /// Remove what scanflow put in the work directory, then the directory if that emptied
    /// it. Returns the entries left (someone else's), which keep the directory.
    pub fn remove(self) -> Result<Vec<PathBuf>> {
        remove_owned(&self.dir)
    }
}

/// Remove the entries scanflow makes in the work directory `dir` (if it is one) and then
/// `dir` if that emptied it; return the entries it did not make, which stay.
pub fn remove_owned(dir: &Path) -> Result<Vec<PathBuf>> {
    if !is_work_dir(dir) {
        return Ok(Vec::new());
    }
    atomic::remove_stale_temps(dir, true);
    for name in [WORK_STORE, LEAVES, TILES, CLAIMS, PATCHES, INGEST_DIR] {
        let p = dir.join(name);
        if p.is_dir() {
            std::fs::remove_dir_all(&p).with_path(&p)?;
        }
    }
    for name in [RUN_FILE, SOLVE_FILE, MERGE_FILE, RESAMPLED, MARKER] {
        let p = dir.join(name);
        if p.exists() {
            std::fs::remove_file(&p).with_path(&p)?;
        }
    }
    let left: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_path(dir)?
        .flatten()
        .map(|e| e.path())
        .collect();
    if left.is_empty() {
        std::fs::remove_dir(dir).with_path(dir)?;
    }
    Ok(left)
}

/// The plan and store the checkpoints in a work directory were made with; a resumed run must
/// match it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct SolveInfo {
    store_points: u64,
    store_cells_crc: Vec<u32>,
    plan: Plan,
    /// The levels above the finest (the recursive scheme), top last; absent for a
    /// single-level plan, as in earlier versions' work directories.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    levels: Vec<Plan>,
}

/// The checkpoint directories of a prepared work directory.
#[derive(Debug, Clone)]
pub struct WorkDir {
    /// Leaf checkpoints.
    pub leaves: PathBuf,
    /// Tile checkpoints.
    pub tiles: PathBuf,
    /// The claims of a split run's shards on leaves and tiles
    /// ([`Claims`](crate::pipeline::shard::Claims)).
    pub claims: PathBuf,
}

/// Make `params.work_dir` ready for the solve of `levels` (finest first,
/// [`crate::recon::plan::levels`]) on `store`: record them; when the checkpoints there were
/// made with other levels or another store (a resume with another `--mem` or `--tile`), drop
/// them, as no leaf of theirs fits this plan.
pub fn prepare(store: &Store, levels: &[Plan], params: &RunParams) -> Result<WorkDir> {
    let m = &store.manifest;
    let info = SolveInfo {
        store_points: m.point_count,
        store_cells_crc: m.cells.iter().map(|c| c.crc32).collect(),
        plan: levels[0],
        levels: levels[1..].to_vec(),
    };
    let dir = &params.work_dir;
    if !dir.is_dir() {
        std::fs::create_dir_all(dir).with_path(dir)?;
    }
    let info_path = dir.join(SOLVE_FILE);
    let old: Option<SolveInfo> = std::fs::read_to_string(&info_path)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok());
    if old.as_ref() != Some(&info) {
        if old.is_some() && params.shard.is_split() {
            // Another shard's checkpoints: never removed.
            return Err(Error::input(
                &info_path,
                format!(
                    "another shard of this work directory planned other grids or read another store: give every shard the same store, options and {} (the grids follow the memory budget)",
                    Setting::Mem
                ),
            ));
        }
        if old.is_some() {
            log::info!(
                "{}: the checkpoints there were made with another plan ({} and {} change it): solving the leaves again",
                dir.display(),
                Setting::Mem,
                Setting::Tile
            );
            for name in [LEAVES, TILES, CLAIMS] {
                let p = dir.join(name);
                if p.is_dir() {
                    std::fs::remove_dir_all(&p).with_path(&p)?;
                }
            }
        }
        let text = serde_json::to_string_pretty(&info)
            .map_err(|e| Error::Internal(format!("{SOLVE_FILE}: {e}")))?;
        atomic::write(&info_path, text.as_bytes(), Durability::Synced)?;
    }
    let leaves = dir.join(LEAVES);
    std::fs::create_dir_all(&leaves).with_path(&leaves)?;
    let tiles = dir.join(TILES);
    std::fs::create_dir_all(&tiles).with_path(&tiles)?;
    let claims = dir.join(CLAIMS);
    if params.shard.is_split() {
        std::fs::create_dir_all(&claims).with_path(&claims)?;
    }
    Ok(WorkDir {
        leaves,
        tiles,
        claims,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fingerprint_sees_a_changed_byte_in_a_window_and_the_size() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a.bin");
        let mut bytes: Vec<u8> = (0..300_000u32).map(|i| (i % 251) as u8).collect();
        std::fs::write(&p, &bytes).unwrap();
        let a = fingerprint(&p, bytes.len() as u64).unwrap();
        let last = bytes.len() - 1;
        bytes[last] ^= 1;
        std::fs::write(&p, &bytes).unwrap();
        let b = fingerprint(&p, bytes.len() as u64).unwrap();
        assert_ne!(a, b);
        std::fs::write(&p, b"xyz").unwrap();
        assert_ne!(fingerprint(&p, 3).unwrap(), b);
        std::fs::write(&p, b"").unwrap();
        fingerprint(&p, 0).unwrap();
    }

    #[test]
    fn a_foreign_directory_is_never_the_work_directory() {
        let d = tempfile::tempdir().unwrap();
        let out = d.path().join("m.ply");
        let fresh = d.path().join("w");
        assert_eq!(resolve(&fresh, &out).unwrap(), fresh);
        std::fs::create_dir(&fresh).unwrap();
        assert_eq!(resolve(&fresh, &out).unwrap(), fresh.join("m.ply.work"));
        std::fs::write(fresh.join(MARKER), b"").unwrap();
        assert_eq!(resolve(&fresh, &out).unwrap(), fresh);
        let file = d.path().join("f");
        std::fs::write(&file, b"").unwrap();
        assert!(resolve(&file, &out).is_err());
    }

    #[test]
    fn removal_keeps_what_scanflow_did_not_make() {
        let d = tempfile::tempdir().unwrap();
        let w = d.path().join("w");
        let id = RunIdentity {
            entries: BTreeMap::new(),
        };
        let lease = claim(&w, &id, false).unwrap();
        std::fs::create_dir_all(w.join(LEAVES)).unwrap();
        std::fs::write(w.join(LEAVES).join("x"), b"1").unwrap();
        std::fs::write(w.join("mine.txt"), b"user").unwrap();
        let left = lease.remove().unwrap();
        assert_eq!(left, vec![w.join("mine.txt")]);
        assert_eq!(std::fs::read(w.join("mine.txt")).unwrap(), b"user");
        assert!(!w.join(LEAVES).exists() && !w.join(MARKER).exists());
    }
}
