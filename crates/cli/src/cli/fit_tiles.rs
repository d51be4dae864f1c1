//! `scanflow fit --tiles` and `--patches`: the store (given, or ingested into the work
//! directory) fitted tile by tile or patch by patch, then the outputs written.

use anyhow::Result;

use scanflow::exec::Ctx;
use scanflow::pipeline::fit::{FitStats, input_stamp, write_outputs};
use scanflow::pipeline::fit_patches::fit_patches;
use scanflow::pipeline::fit_tiles::fit_tiles;
use scanflow::pipeline::workdir::RunIdentity;

use super::fit::FitConfig;
use super::reconstruct::WorkRun;

/// Runs the tiled or patch-wise fit in a work directory and writes the IGES file and preview.
pub fn run(c: &FitConfig, ctx: &Ctx) -> Result<FitStats> {
    let job = WorkRun {
        points: &c.points,
        output: &c.output,
        work_dir: &c.work_dir,
        resume: false,
        keep_work: c.keep_work,
        shared: false,
    };
    let command = match c.patches {
        Some(p) => format!(
            "fit --patches --patch-points {} --patch-angle {}",
            p.points, p.angle
        ),
        None => "fit --tiles".to_string(),
    };
    let opts = vec![("command", command)];
    let st = job.run(
        ctx,
        |src: &_, mode, np: &_| RunIdentity::with_options(src, mode, np, &opts),
        |store, work| {
            let st = match c.patches {
                Some(shape) => fit_patches(store, &c.job, shape, ctx)?,
                None => fit_tiles(store, work, &c.job, ctx)?,
            };
            write_outputs(&c.output, &c.job, &st.surfaces, input_stamp(&c.inputs))?;
            Ok(st)
        },
    )?;
    Ok(st)
}
