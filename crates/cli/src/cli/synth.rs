//! `scanflow synth`: oriented samples of a synthetic shape and its exact description.

use std::path::Path;

use anyhow::Result;

use scanflow::exec::Ctx;
use scanflow::synth::{Shape, SynthParams, SynthReport};

use super::config::SynthConfig;
use super::report;

/// Write the samples and print what was written.
pub fn run(c: &SynthConfig, ctx: &Ctx) -> Result<()> {
    let r = synthesise(ctx, c.shape, c.relief, c.points, c.noise, c.seed, &c.output)?;
    report::synth(&r, c.shape, &c.output);
    Ok(())
}

/// Sample `points` points of `shape` (with `relief`, for `bumpy`) with `noise` into `out` (and
/// its `.truth.json`), counting them on a progress stage.
pub fn synthesise(
    ctx: &Ctx,
    shape: Shape,
    relief: Option<[f64; 2]>,
    points: u64,
    noise: f64,
    seed: u64,
    out: &Path,
) -> Result<SynthReport> {
    let params = SynthParams {
        shape,
        relief,
        points,
        noise,
        seed,
        threads: ctx.threads(),
    };
    let stage = ctx.progress.stage("synth", Some(points), "points");
    let mut last = 0;
    let r = scanflow::synth::synth(&params, out, &mut |done| {
        stage.inc(done - last);
        last = done;
    })?;
    stage.finish(None);
    Ok(r)
}
