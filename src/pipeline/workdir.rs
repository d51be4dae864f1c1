//! The work directory of a reconstruction: its run description (`run.json`), leaf checkpoints
//! (`leaves/`) and tile checkpoints (`tiles/`). A run refuses another run's files unless it
//! resumes the same run (same version, inputs and options).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::reconstruct::ReconParams;
use crate::error::{Error, IoContext, Result};
use crate::io::atomic::{self, Durability};
use crate::recon::Plan;
use crate::store::Store;

/// What a work directory was made for; a resumed run must match it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct RunInfo {
    scanflow: String,
    trim: bool,
    #[serde(default)]
    fit: bool,
    error: f64,
    min_points: u64,
    store_points: u64,
    store_cells_crc: Vec<u32>,
    plan: Plan,
}

/// The checkpoint directories of a prepared work directory.
#[derive(Debug, Clone)]
pub struct WorkDir {
    /// Leaf checkpoints.
    pub leaves: PathBuf,
    /// Tile checkpoints.
    pub tiles: PathBuf,
}

/// Make `params.work_dir` ready for a run of `plan` on `store`: write its run description, or
/// check that it describes this run when resuming; refuse another run's files.
pub fn prepare(store: &Store, plan: &Plan, params: &ReconParams) -> Result<WorkDir> {
    let m = &store.manifest;
    let leaves = params.work_dir.join("leaves");
    let info = RunInfo {
        scanflow: env!("CARGO_PKG_VERSION").into(),
        trim: params.trim,
        fit: params.fit,
        error: params.error,
        min_points: params.min_points,
        store_points: m.point_count,
        store_cells_crc: m.cells.iter().map(|c| c.crc32).collect(),
        plan: *plan,
    };
    let info_path = params.work_dir.join("run.json");
    if info_path.exists() {
        check_resumable(&info_path, &info, params)?;
    } else {
        std::fs::create_dir_all(&leaves).with_path(&leaves)?;
        let text = serde_json::to_string_pretty(&info)
            .map_err(|e| Error::Internal(format!("run.json: {e}")))?;
        atomic::write(&info_path, text.as_bytes(), Durability::Synced)?;
    }
    std::fs::create_dir_all(&leaves).with_path(&leaves)?;
    let tiles = params.work_dir.join("tiles");
    std::fs::create_dir_all(&tiles).with_path(&tiles)?;
    Ok(WorkDir { leaves, tiles })
}

/// Refuse the existing run description at `info_path` unless resuming the run `info`.
fn check_resumable(info_path: &Path, info: &RunInfo, params: &ReconParams) -> Result<()> {
    let old: Option<RunInfo> = std::fs::read_to_string(info_path)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok());
    if !params.resume {
        return Err(Error::input(
            &params.work_dir,
            "work directory holds another run's files; pass --resume to continue that run, or choose another --work-dir",
        ));
    }
    if old.as_ref() != Some(info) {
        return Err(Error::input(
            &params.work_dir,
            "cannot resume: the work directory was made for other inputs or options",
        ));
    }
    Ok(())
}
