//! `scanflow demo`: the whole job on a synthetic scan with an exact answer. Synthesise a
//! noisy bumpy sphere (with its normals), reconstruct it as `reconstruct` does by default
//! (ingest into the work directory, depth 9), and check the mesh against the exact surface.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};

use scanflow::exec::Ctx;
use scanflow::pipeline::ReconParams;
use scanflow::pipeline::workdir;
use scanflow::synth::Shape;

use super::args::{DEFAULT_CHECK_SAMPLES, DEFAULT_DEPTH, DEFAULT_SEED};
use super::config::{DemoConfig, Inputs, NormalsConfig, Points};
use super::reconstruct::reconstruct;
use super::report;
use super::synth::synthesise;

/// The demo scan's noise, relative to the bounding-box diagonal.
const NOISE: f64 = 0.001;

/// Run the demo in `c.dir`, replacing the files of an earlier demo there.
pub fn run(c: &DemoConfig, ctx: &Ctx) -> Result<()> {
    let t0 = Instant::now();
    let dir = &c.dir;
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create the demo directory", dir.display()))?;
    let ply = dir.join("demo_points.ply");
    let mesh = dir.join("demo.ply");
    let work = dir.join("demo.work");
    for p in [&ply, &mesh] {
        remove_old(p)?;
    }
    workdir::remove_owned(&work)?;
    let rep = synthesise(ctx, Shape::Bumpy, None, c.points, NOISE, DEFAULT_SEED, &ply)?;
    report::demo_synth(&rep, NOISE);
    let points = Points::Files(Inputs::file(ply.clone()), NormalsConfig::default());
    let params = ReconParams::new(DEFAULT_DEPTH, work);
    let target = scanflow::io::mesh_write::MeshTarget::ply(&mesh);
    let st = reconstruct(ctx, &points, &target, &params, false)?;
    let total = t0.elapsed().as_secs_f64();
    let truth = scanflow::synth::truth_path(&ply);
    let check = scanflow::metrics::run_check(&mesh, Some(&truth), None, DEFAULT_CHECK_SAMPLES)?;
    report::demo_done(&mesh, DEFAULT_DEPTH, &st, &check, total);
    Ok(())
}

/// Remove the earlier demo's file `p`, if it exists (a directory there is left alone, and
/// the new file's commit then reports it).
fn remove_old(p: &Path) -> Result<()> {
    if p.is_file() {
        std::fs::remove_file(p)
            .with_context(|| format!("{}: cannot remove the old demo output", p.display()))?;
    }
    Ok(())
}
