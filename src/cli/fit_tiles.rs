//! `scanflow fit --tiles`: the store (given, or ingested into the work directory) fitted tile
//! by tile, then the outputs written.

use anyhow::Result;

use scanflow::exec::Ctx;
use scanflow::pipeline::fit::{FitStats, input_stamp, write_outputs};
use scanflow::pipeline::fit_tiles::fit_tiles;
use scanflow::pipeline::workdir::RunIdentity;

use super::args::NormalOpts;
use super::config::Points;
use super::fit::FitConfig;
use super::reconstruct::WorkRun;

/// Runs the tiled fit in a work directory and writes the IGES file and preview.
pub fn run(c: &FitConfig, ctx: &Ctx) -> Result<FitStats> {
    let normals = NormalOpts::default_for_tiles();
    let points = Points::new(c.inputs.clone(), None, &normals)?;
    let job = WorkRun {
        points: &points,
        output: &c.output,
        work_dir: &c.work_dir,
        resume: false,
        keep_work: c.keep_work,
    };
    let opts = vec![("command", "fit --tiles".to_string())];
    let st = job.run(
        ctx,
        |src: &_, mode, np: &_| RunIdentity::with_options(src, mode, np, &opts),
        |store, work| {
            let st = fit_tiles(store, work, &c.job, ctx)?;
            write_outputs(&c.output, &c.job, &st.surfaces, input_stamp(&c.inputs))?;
            Ok(st)
        },
    )?;
    Ok(st)
}
