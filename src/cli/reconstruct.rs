//! `scanflow reconstruct`: a store, or point files ingested into the work directory, to a
//! mesh.

use std::path::Path;

use anyhow::{Context, Result, bail};

use scanflow::exec::Ctx;
use scanflow::recon::{ReconParams, ReconStats};
use scanflow::store::{IngestParams, Store};

use super::config::{Points, ReconstructConfig};
use super::ingest::input_specs;
use super::report;

/// Cell size of the store ingested into the work directory: small cells, because leaves
/// read the store cells around them through a small cache.
const WORK_STORE_CELL_POINTS: u64 = 1 << 18;

/// Reconstruct and print the summary.
pub fn run(c: &ReconstructConfig, ctx: &Ctx) -> Result<()> {
    let st = reconstruct(ctx, &c.points, &c.output, &c.params, c.keep_work)?;
    report::reconstruct(&st, &c.output);
    Ok(())
}

/// Open the store, or ingest the point files into `params.work_dir` (unless a resumed run
/// already did), reconstruct into `output`, and remove the work directory unless
/// `keep_work`.
pub fn reconstruct(
    ctx: &Ctx,
    points: &Points,
    output: &Path,
    params: &ReconParams,
    keep_work: bool,
) -> Result<ReconStats> {
    let work = &params.work_dir;
    let store_dir = match points {
        Points::Store {
            dir,
            ignores_normal_options,
        } => {
            if *ignores_normal_options {
                log::warn!(
                    "{}: a store keeps the normals it was ingested with; --normals and --viewpoint apply to `ingest`",
                    dir.display()
                );
            }
            dir.clone()
        }
        Points::Files(inputs, normals) => {
            let specs = input_specs(inputs)?;
            let dir = work.join("store");
            if !(params.resume && dir.join("manifest.json").exists()) {
                if dir.exists() && !params.resume {
                    bail!(
                        "{}: work directory holds another run's files; pass --resume to continue that run, or choose another --work-dir",
                        work.display()
                    );
                }
                std::fs::create_dir_all(work).with_context(|| {
                    format!("{}: cannot create the work directory", work.display())
                })?;
                let ingest = IngestParams {
                    max_cell_points: WORK_STORE_CELL_POINTS,
                    normals: normals.mode,
                    normal_params: normals.params,
                    ..Default::default()
                };
                scanflow::store::ingest(&specs, &dir, &ingest, ctx)?;
            }
            dir
        }
    };
    let store = Store::open(&store_dir)?;
    let st = scanflow::recon::reconstruct(&store, output, params, ctx)?;
    if !keep_work {
        std::fs::remove_dir_all(work)
            .with_context(|| format!("{}: cannot remove the work directory", work.display()))?;
    }
    Ok(st)
}
