//! Ingest chained with normal estimation (ARCHITECTURE.md step 1): the store's passes write
//! the cells into a staged directory, normals are estimated over those cells when the inputs
//! have none, and only then is the store committed (manifest written last, directory
//! renamed), so a store is either complete, with its normals, or absent. Also the first step
//! of a reconstruction: open a store, or ingest the point files into the work directory.

use std::path::Path;

use super::workdir::{StoreSource, WORK_STORE};
use crate::error::{Error, IoContext, Result, Setting};
use crate::exec::Ctx;
use crate::io::InputSpec;
use crate::normals::{self, NormalParams};
use crate::store::manifest::MANIFEST;
use crate::store::{self, NormalsMode, Store, StoreParams};

pub use crate::store::IngestStats;

/// Cell point limit of the store a reconstruction ingests into its work directory: small
/// cells, as leaves read the store cells around them through a small cache.
pub const WORK_STORE_CELL_POINTS: u64 = 1 << 18;

/// Options of [`ingest`].
#[derive(Debug, Clone)]
pub struct IngestParams {
    /// Cells are split until they hold at most this many points.
    pub max_cell_points: u64,
    /// Drop points with non-finite coordinates or non-finite or zero normals instead of failing.
    pub skip_invalid: bool,
    /// zstd level of cell files (see [`StoreParams::zstd_level`]).
    pub zstd_level: i32,
    /// Points per chunk; `None` sizes chunks from the budget.
    pub chunk_points: Option<u64>,
    /// Where normals come from.
    pub normals: NormalsMode,
    /// How they are estimated, when they are.
    pub normal_params: NormalParams,
}

impl Default for IngestParams {
    fn default() -> Self {
        let s = StoreParams::default();
        IngestParams {
            max_cell_points: s.max_cell_points,
            skip_invalid: s.skip_invalid,
            zstd_level: s.zstd_level,
            chunk_points: s.chunk_points,
            normals: s.normals,
            normal_params: NormalParams::default(),
        }
    }
}

impl IngestParams {
    /// The store's share of the options.
    pub fn store_params(&self) -> StoreParams {
        StoreParams {
            max_cell_points: self.max_cell_points,
            skip_invalid: self.skip_invalid,
            zstd_level: self.zstd_level,
            chunk_points: self.chunk_points,
            normals: self.normals,
        }
    }
}

/// Ingest `inputs` into a new store at `out`, estimating normals when they are wanted.
pub fn ingest(
    inputs: &[InputSpec],
    out: &Path,
    params: &IngestParams,
    ctx: &Ctx,
) -> Result<IngestStats> {
    let mut staged = store::stage(inputs, out, &params.store_params(), ctx)?;
    let normals = if staged.wants_normals() {
        Some(normals::estimate_cells(
            &mut staged,
            &params.normal_params,
            ctx,
        )?)
    } else {
        None
    };
    staged.commit(normals)
}

/// Open the store of `source`: the store itself, or the one ingested from the point files into
/// `work_dir` (ingested now, unless `resume` finds it complete from an earlier run).
pub fn open_or_ingest(
    source: &StoreSource,
    work_dir: &Path,
    resume: bool,
    normals: NormalsMode,
    normal_params: NormalParams,
    ctx: &Ctx,
) -> Result<Store> {
    let dir = match source {
        StoreSource::Store(dir) => dir.clone(),
        StoreSource::Points(specs) => {
            let dir = work_dir.join(WORK_STORE);
            let complete = dir.join(MANIFEST).exists();
            if !(resume && complete) {
                if dir.exists() {
                    if !resume {
                        return Err(Error::input(
                            work_dir,
                            format!(
                                "work directory holds another run's files; pass {} to continue that run, or choose another {}",
                                Setting::Resume,
                                Setting::WorkDir
                            ),
                        ));
                    }
                    // A store without its manifest is what a run killed while removing its
                    // work directory leaves: nothing in it can be used.
                    std::fs::remove_dir_all(&dir).with_path(&dir)?;
                }
                std::fs::create_dir_all(work_dir).map_err(|e| {
                    Error::input(work_dir, format!("cannot create the work directory: {e}"))
                })?;
                let params = IngestParams {
                    max_cell_points: WORK_STORE_CELL_POINTS,
                    normals,
                    normal_params,
                    ..Default::default()
                };
                ingest(specs, &dir, &params, ctx)?;
            }
            dir
        }
    };
    Store::open(&dir)
}
