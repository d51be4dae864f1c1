//! `scanflow reconstruct`: a store, or point files ingested into the work directory, to a
//! mesh.

use std::path::Path;

use anyhow::{Context, Result};

use scanflow::exec::Ctx;
use scanflow::pipeline::ingest::{StoreSource, open_or_ingest};
use scanflow::pipeline::{ReconParams, ReconStats};

use super::config::{Points, ReconstructConfig};
use super::ingest::input_specs;
use super::report;

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
    let (source, normals) = match points {
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
            (StoreSource::Store(dir.clone()), None)
        }
        Points::Files(inputs, normals) => {
            (StoreSource::Points(input_specs(inputs)?), Some(normals))
        }
    };
    let (mode, normal_params) = normals.map(|n| (n.mode, n.params)).unwrap_or_default();
    let store = open_or_ingest(&source, work, params.resume, mode, normal_params, ctx)?;
    let st = scanflow::pipeline::reconstruct(&store, output, params, ctx)?;
    if !keep_work {
        std::fs::remove_dir_all(work)
            .with_context(|| format!("{}: cannot remove the work directory", work.display()))?;
    }
    Ok(st)
}
