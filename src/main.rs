//! The `scanflow` command line: parse, set up progress and logging, call the library.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};

use scanflow::exec::progress::{Mode, Progress};
use scanflow::exec::{Ctx, default_mem_bytes, human_bytes, parse_mem, peak_rss_bytes};
use scanflow::io::InputSpec;
use scanflow::pipeline::ingest::{IngestParams, StoreSource};
use scanflow::store::Store;

/// Out-of-core streaming surface reconstruction for huge 3D scans.
#[derive(Parser, Debug)]
#[command(name = "scanflow", version, about, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Args, Debug, Clone)]
struct Common {
    /// Worker threads (default: one per core).
    #[arg(long, global = true, default_value_t = 0)]
    threads: usize,
    /// Memory budget: 512M, 4G, 50% of available; default half the available memory.
    #[arg(long, global = true)]
    mem: Option<String>,
    /// Progress display: auto (bars on a terminal, JSON lines otherwise), bars, json, none.
    #[arg(long, global = true, default_value = "auto")]
    progress: String,
}

/// Normal estimation options (ingest and reconstruct).
#[derive(Args, Debug, Clone)]
struct NormalOpts {
    /// Normals: auto (the inputs' when every input has them, else estimated), use (the
    /// inputs'; an error without them), estimate (ignore the inputs' normals).
    #[arg(long, default_value = "auto")]
    normals: String,
    /// Neighbours per plane fit when estimating normals (the point itself included); cells
    /// whose points are noisy use more, up to 6 times as many (see --fixed-neighbours).
    #[arg(long, default_value_t = scanflow::normals::DEFAULT_K)]
    neighbours: usize,
    /// Use exactly --neighbours everywhere, even where noise dominates the fits.
    #[arg(long)]
    fixed_neighbours: bool,
    /// Re-fit each estimated normal once with robust (Cauchy) weights: less pulled by noise
    /// and outliers, a little slower.
    #[arg(long)]
    robust_normals: bool,
    /// Scanner position x,y,z (common frame) that estimated normals face: once for all inputs,
    /// or once per input file in order. `.conf` scans take theirs from their pose.
    #[arg(long, value_name = "X,Y,Z")]
    viewpoint: Vec<String>,
}

impl NormalOpts {
    fn mode(&self) -> Result<scanflow::normals::NormalsMode> {
        Ok(self.normals.parse()?)
    }

    fn params(&self) -> scanflow::normals::NormalParams {
        scanflow::normals::NormalParams {
            k: self.neighbours,
            robust: self.robust_normals,
            adaptive: !self.fixed_neighbours,
        }
    }
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Write oriented samples of a synthetic shape, with its exact description (.truth.json).
    Synth {
        /// sphere, torus, twosheets or bumpy.
        shape: String,
        /// Number of points.
        #[arg(long)]
        points: u64,
        /// Gaussian noise, relative to the bounding-box diagonal.
        #[arg(long, default_value_t = 0.0)]
        noise: f64,
        /// Random seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output PLY.
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        common: Common,
    },
    /// Bucket point files into an on-disk octree store.
    Ingest {
        /// Point files (PLY, LAS/LAZ, XYZ/PTS).
        inputs: Vec<PathBuf>,
        /// Output store directory (must not exist).
        #[arg(short, long)]
        output: PathBuf,
        /// Scanalyze .conf listing scans and their transforms.
        #[arg(long)]
        conf: Option<PathBuf>,
        /// Split cells until they hold at most this many points.
        #[arg(long, default_value_t = 1_000_000)]
        max_cell_points: u64,
        /// Drop points with NaN/infinite coordinates (counted) instead of failing.
        #[arg(long)]
        skip_invalid: bool,
        /// zstd level of cell files (-7 fastest .. 19 smallest).
        #[arg(long, default_value_t = -1, allow_negative_numbers = true)]
        zstd_level: i32,
        #[command(flatten)]
        normal: NormalOpts,
        #[command(flatten)]
        common: Common,
    },
    /// Reconstruct a watertight surface from oriented points (adaptive FFT, two-level).
    Reconstruct {
        /// Point files, or one store directory made by `ingest`.
        inputs: Vec<PathBuf>,
        /// Output mesh (binary PLY).
        #[arg(short, long)]
        output: PathBuf,
        /// Scanalyze .conf listing scans and their transforms.
        #[arg(long)]
        conf: Option<PathBuf>,
        /// Octree depth: 2^depth cells per edge of the bounding cube (as PoissonRecon).
        #[arg(long, default_value_t = 9)]
        depth: u32,
        /// Tile edge in voxels (power of two; default 128).
        #[arg(long)]
        tile: Option<u64>,
        /// Work directory for the store and leaf checkpoints (default: OUTPUT.work).
        #[arg(long)]
        work_dir: Option<PathBuf>,
        /// Continue a killed run from the leaves in its work directory.
        #[arg(long)]
        resume: bool,
        /// Keep the work directory after success.
        #[arg(long)]
        keep_work: bool,
        /// Refine a leaf only where its samples are farther than this (relative to the
        /// bounding-box diagonal) from the coarse solution's surface.
        #[arg(long, default_value_t = scanflow::recon::DEFAULT_ERROR)]
        error: f64,
        /// Refine only leaves holding at least this many points.
        #[arg(long, default_value_t = scanflow::recon::DEFAULT_MIN_POINTS)]
        min_points: u64,
        /// Leave the surface open where no input point supports it.
        #[arg(long)]
        trim: bool,
        /// Width in voxels of the Gaussian that smooths the normal field before the solve
        /// (Kazhdan 2005): larger is smoother and more robust to noise, smaller follows the
        /// points more closely.
        #[arg(long, default_value_t = 1.0)]
        smooth: f64,
        /// Keep the vertices where marching cubes put them, instead of moving each onto the
        /// plane of its nearest input points (by what exceeds the plane's standard error).
        #[arg(long)]
        no_fit: bool,
        /// Tile fields and marching cubes on the GPU: auto (a discrete or integrated GPU when
        /// present), on (any Vulkan/Metal/DX12 adapter, software ones included), off. Same
        /// output either way. Off by default: the GPU path is not yet measured faster end to
        /// end (the earlier version, field on the CPU, took 20.8 s against 15.3 s on an H100).
        #[arg(long, default_value = "off")]
        gpu: String,
        #[command(flatten)]
        normal: NormalOpts,
        #[command(flatten)]
        common: Common,
    },
    /// Check a mesh: counts, watertight, manifold, components; distances to a truth or reference.
    Check {
        /// The mesh (PLY).
        mesh: PathBuf,
        /// Exact surface written by `synth` (.truth.json).
        #[arg(long)]
        truth: Option<PathBuf>,
        /// Reference mesh or point file.
        #[arg(long)]
        reference: Option<PathBuf>,
        /// Sample points for each distance direction.
        #[arg(long, default_value_t = 200_000)]
        samples: usize,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Describe a point file or a store.
    Info {
        /// A point file or a store directory.
        path: PathBuf,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        common: Common,
    },
    /// The main job on an embedded default: synthesise a scan, ingest it, describe the store.
    Demo {
        /// Output directory.
        #[arg(short, long, default_value = "scanflow-demo")]
        output: PathBuf,
        /// Points to synthesise.
        #[arg(long, default_value_t = 1_000_000)]
        points: u64,
        #[command(flatten)]
        common: Common,
    },
}

/// `println!` that ends the process quietly when stdout is a closed pipe (`scanflow ... | head`)
/// instead of panicking.
macro_rules! outln {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        if let Err(e) = writeln!(std::io::stdout(), $($t)*) {
            if e.kind() == std::io::ErrorKind::BrokenPipe {
                std::process::exit(0);
            }
        }
    }};
}

struct Logger;

static LOGGER: Logger = Logger;

impl log::Log for Logger {
    fn enabled(&self, m: &log::Metadata) -> bool {
        m.level() <= log::Level::Info
    }
    fn log(&self, r: &log::Record) {
        if self.enabled(r.metadata()) {
            let level = match r.level() {
                log::Level::Error => "error",
                log::Level::Warn => "warning",
                _ => "info",
            };
            eprintln!("scanflow: {level}: {}", r.args());
        }
    }
    fn flush(&self) {}
}

fn main() -> ExitCode {
    let _ = log::set_logger(&LOGGER).map(|()| log::set_max_level(log::LevelFilter::Info));
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("scanflow: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn ctx(c: &Common) -> Result<Ctx> {
    let mem = match &c.mem {
        Some(s) => parse_mem(s)?,
        None => default_mem_bytes(),
    };
    let mode = match c.progress.as_str() {
        "auto" => Mode::detect(),
        "bars" => Mode::Bars,
        "json" => Mode::Json {
            every: std::time::Duration::from_secs(5),
        },
        "none" => Mode::Quiet,
        other => anyhow::bail!("--progress \"{other}\": expected auto, bars, json or none"),
    };
    Ok(Ctx::new(c.threads, mem, Progress::new(mode))?)
}

fn run(cli: Cli) -> Result<()> {
    match cli.cmd {
        Cmd::Synth {
            shape,
            points,
            noise,
            seed,
            output,
            common,
        } => {
            let ctx = ctx(&common)?;
            let report = synth(&ctx, &shape, points, noise, seed, &output)?;
            outln!(
                "wrote {} points of {} to {} in {:.2} s",
                report.points,
                shape,
                output.display(),
                report.secs
            );
        }
        Cmd::Ingest {
            inputs,
            output,
            conf,
            max_cell_points,
            skip_invalid,
            zstd_level,
            normal,
            common,
        } => {
            if !(-7..=19).contains(&zstd_level) {
                anyhow::bail!("--zstd-level {zstd_level}: expected -7 ..= 19");
            }
            let ctx = ctx(&common)?;
            let specs = input_specs(&inputs, conf.as_deref(), &normal.viewpoint)?;
            let params = IngestParams {
                max_cell_points,
                skip_invalid,
                zstd_level,
                normals: normal.mode()?,
                normal_params: normal.params(),
                ..Default::default()
            };
            let st = scanflow::pipeline::ingest::ingest(&specs, &output, &params, &ctx)?;
            if let Some((n, secs)) = &st.normals {
                outln!(
                    "estimated normals for {} points in {:.2} s ({:.2} M points/s; k = {}..{}, {} by viewpoint, {} by propagation, {} degenerate, {} components)",
                    st.points,
                    secs,
                    st.points as f64 / secs / 1e6,
                    n.k,
                    n.k_max,
                    n.by_viewpoint,
                    n.by_propagation,
                    n.degenerate,
                    n.components
                );
            }
            outln!(
                "ingested {} points ({} skipped as invalid) into {} cells of {} in {:.2} s: {:.2} M points/s, store {}, peak memory {}",
                st.points,
                st.skipped_invalid,
                st.cells,
                output.display(),
                st.secs,
                st.points as f64 / st.secs / 1e6,
                human_bytes(st.store_bytes),
                human_bytes(peak_rss_bytes())
            );
        }
        Cmd::Reconstruct {
            inputs,
            output,
            conf,
            depth,
            tile,
            work_dir,
            resume,
            keep_work,
            error,
            min_points,
            trim,
            smooth,
            no_fit,
            gpu,
            normal,
            common,
        } => {
            if !(smooth > 0.0 && smooth <= 8.0) {
                anyhow::bail!("--smooth {smooth}: expected a width in voxels in (0, 8]");
            }
            let ctx = ctx(&common)?;
            if !(error >= 0.0 && error.is_finite()) {
                anyhow::bail!(
                    "--error {error}: expected a non-negative number (relative to the bounding-box diagonal)"
                );
            }
            let work = work_dir.unwrap_or_else(|| {
                let mut s = output.as_os_str().to_owned();
                s.push(".work");
                PathBuf::from(s)
            });
            let mut params = scanflow::pipeline::ReconParams::new(depth, work);
            params.tile_voxels = tile;
            params.resume = resume;
            params.error = error;
            params.min_points = min_points;
            params.trim = trim;
            params.sigma_vox = smooth;
            params.fit = !no_fit;
            params.gpu = gpu.parse()?;
            let st = reconstruct(
                &ctx,
                &inputs,
                conf.as_deref(),
                &output,
                params,
                keep_work,
                &normal,
            )?;
            outln!(
                "reconstructed {} vertices, {} triangles into {} in {:.2} s ({} leaves, {} refined, iso {:.4}), peak memory {}",
                st.vertices,
                st.faces,
                output.display(),
                st.secs,
                st.leaves,
                st.leaves_refined,
                st.iso,
                human_bytes(peak_rss_bytes())
            );
        }
        Cmd::Check {
            mesh,
            truth,
            reference,
            samples,
            json,
        } => {
            let rep = scanflow::metrics::run_check(
                &mesh,
                truth.as_deref(),
                reference.as_deref(),
                samples,
            )?;
            if json {
                outln!("{}", serde_json::to_string(&rep)?);
            } else {
                outln!("{rep}");
            }
        }
        Cmd::Info { path, json, common } => {
            let ctx = ctx(&common)?;
            info(&ctx, &path, json)?;
        }
        Cmd::Demo {
            output,
            points,
            common,
        } => {
            let ctx = ctx(&common)?;
            let t0 = Instant::now();
            std::fs::create_dir_all(&output).with_context(|| {
                format!("{}: cannot create the demo directory", output.display())
            })?;
            let ply = output.join("demo_points.ply");
            let mesh = output.join("demo.ply");
            let work = output.join("demo.work");
            for p in [&ply, &mesh, &work] {
                if p.is_dir() {
                    std::fs::remove_dir_all(p).with_context(|| {
                        format!("{}: cannot remove the old demo output", p.display())
                    })?;
                } else if p.exists() {
                    std::fs::remove_file(p).with_context(|| {
                        format!("{}: cannot remove the old demo output", p.display())
                    })?;
                }
            }
            let rep = synth(&ctx, "bumpy", points, 0.001, 1, &ply)?;
            outln!(
                "synthesised {} points of a bumpy sphere (noise 0.001) in {:.2} s",
                rep.points,
                rep.secs
            );
            let params = scanflow::pipeline::ReconParams::new(9, work);
            let normal = NormalOpts {
                normals: "auto".into(),
                neighbours: scanflow::normals::DEFAULT_K,
                fixed_neighbours: false,
                robust_normals: false,
                viewpoint: Vec::new(),
            };
            let st = reconstruct(
                &ctx,
                std::slice::from_ref(&ply),
                None,
                &mesh,
                params,
                false,
                &normal,
            )?;
            let total = t0.elapsed().as_secs_f64();
            let check = scanflow::metrics::run_check(
                &mesh,
                Some(&scanflow::synth::truth_path(&ply)),
                None,
                200_000,
            )?;
            outln!(
                "reconstructed {} at depth 9 in {:.2} s: {} vertices, {} triangles",
                mesh.display(),
                st.secs,
                st.vertices,
                st.faces
            );
            outln!("{check}");
            outln!(
                "demo done in {:.2} s, peak memory {}",
                total,
                human_bytes(peak_rss_bytes())
            );
        }
    }
    Ok(())
}

fn synth(
    ctx: &Ctx,
    shape: &str,
    points: u64,
    noise: f64,
    seed: u64,
    out: &Path,
) -> Result<scanflow::synth::SynthReport> {
    let params = scanflow::synth::SynthParams {
        shape: shape.parse()?,
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

fn reconstruct(
    ctx: &Ctx,
    inputs: &[PathBuf],
    conf: Option<&Path>,
    output: &Path,
    params: scanflow::pipeline::ReconParams,
    keep_work: bool,
    normal: &NormalOpts,
) -> Result<scanflow::pipeline::ReconStats> {
    let work = params.work_dir.clone();
    let resume = params.resume;
    // One directory argument is a store; anything else is ingested into the work dir.
    let mode = normal.mode()?;
    let source = if conf.is_none() && inputs.len() == 1 && inputs[0].is_dir() {
        if mode != scanflow::normals::NormalsMode::Auto || !normal.viewpoint.is_empty() {
            log::warn!(
                "{}: a store keeps the normals it was ingested with; --normals and --viewpoint apply to `ingest`",
                inputs[0].display()
            );
        }
        StoreSource::Store(inputs[0].clone())
    } else {
        StoreSource::Points(input_specs(inputs, conf, &normal.viewpoint)?)
    };
    let store = scanflow::pipeline::ingest::open_or_ingest(
        &source,
        &work,
        resume,
        mode,
        normal.params(),
        ctx,
    )?;
    let st = scanflow::pipeline::reconstruct(&store, output, &params, ctx)?;
    if !keep_work {
        std::fs::remove_dir_all(&work)
            .with_context(|| format!("{}: cannot remove the work directory", work.display()))?;
    }
    Ok(st)
}

fn input_specs(
    inputs: &[PathBuf],
    conf: Option<&Path>,
    viewpoints: &[String],
) -> Result<Vec<InputSpec>> {
    let mut specs = Vec::new();
    if let Some(c) = conf {
        specs.extend(scanflow::io::conf::read_conf(c)?);
    }
    let from_conf = specs.len();
    specs.extend(inputs.iter().map(InputSpec::plain));
    if specs.is_empty() {
        anyhow::bail!("no input: give point files, a store, or --conf FILE");
    }
    let parsed: Vec<[f64; 3]> = viewpoints
        .iter()
        .map(|v| parse_point(v))
        .collect::<Result<_>>()?;
    let files = &mut specs[from_conf..];
    match parsed.len() {
        0 => {}
        1 => files
            .iter_mut()
            .for_each(|s| s.viewpoint = Some(scanflow::types::Viewpoint::Point(parsed[0]))),
        n if n == files.len() => {
            for (s, p) in files.iter_mut().zip(parsed) {
                s.viewpoint = Some(scanflow::types::Viewpoint::Point(p));
            }
        }
        n => anyhow::bail!(
            "--viewpoint given {n} times for {} input files: give it once for all, or once per file",
            files.len()
        ),
    }
    Ok(specs)
}

/// `x,y,z` as three finite numbers.
fn parse_point(s: &str) -> Result<[f64; 3]> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .ok()
        .filter(|v: &Vec<f64>| v.len() == 3 && v.iter().all(|x| x.is_finite()))
        .with_context(|| format!("--viewpoint \"{s}\": expected three numbers x,y,z"))?;
    Ok([v[0], v[1], v[2]])
}

fn info(ctx: &Ctx, path: &Path, json: bool) -> Result<()> {
    if path.is_dir() {
        let store = Store::open(path)?;
        let m = &store.manifest;
        // Histogram of cell sizes in powers of two.
        let mut hist: std::collections::BTreeMap<u32, usize> = Default::default();
        for c in &m.cells {
            *hist.entry(64 - c.count.leading_zeros()).or_default() += 1;
        }
        let mut levels: std::collections::BTreeMap<u32, usize> = Default::default();
        for c in &m.cells {
            *levels.entry(c.level).or_default() += 1;
        }
        let bytes: u64 = m.cells.iter().map(|c| c.bytes).sum();
        if json {
            let v = serde_json::json!({
                "kind": "store",
                "path": path.display().to_string(),
                "points": m.point_count,
                "skipped_invalid": m.skipped_invalid,
                "attributes": m.attributes.names(),
                "bounds": m.bounds,
                "cells": m.cells.len(),
                "store_bytes": bytes,
                "cells_by_level": levels,
                "cell_size_histogram": hist.iter().map(|(b, n)| serde_json::json!({"min_points": if *b == 0 {0} else {1u64 << (b - 1)}, "max_points": (1u64 << b) - 1, "cells": n})).collect::<Vec<_>>(),
                "inputs": m.inputs,
            });
            outln!("{v}");
            return Ok(());
        }
        outln!("store       {}", path.display());
        outln!("points      {}", m.point_count);
        if m.skipped_invalid > 0 {
            outln!("skipped     {} invalid points", m.skipped_invalid);
        }
        outln!("attributes  {}", m.attributes.names().join(" "));
        outln!(
            "bounds      [{:.6}, {:.6}, {:.6}] .. [{:.6}, {:.6}, {:.6}]",
            m.bounds.min[0],
            m.bounds.min[1],
            m.bounds.min[2],
            m.bounds.max[0],
            m.bounds.max[1],
            m.bounds.max[2]
        );
        outln!("inputs      {}", m.inputs.len());
        outln!(
            "cells       {} ({}, {:.2} bytes/point)",
            m.cells.len(),
            human_bytes(bytes),
            bytes as f64 / m.point_count.max(1) as f64
        );
        outln!(
            "levels      {}",
            levels
                .iter()
                .map(|(l, n)| format!("L{l}:{n}"))
                .collect::<Vec<_>>()
                .join(" ")
        );
        outln!("cell sizes (points per cell):");
        let most = hist.values().copied().max().unwrap_or(1);
        for (b, n) in &hist {
            let lo = if *b == 0 { 0 } else { 1u64 << (b - 1) };
            let hi = (1u64 << b) - 1;
            outln!(
                "  {:>10} .. {:<10} {:>6} {}",
                lo,
                hi,
                n,
                "#".repeat((n * 40).div_ceil(most))
            );
        }
        return Ok(());
    }
    let fi = scanflow::store::file_info(path, ctx)?;
    if json {
        outln!("{}", serde_json::to_string(&fi)?);
        return Ok(());
    }
    outln!("file        {}", fi.path);
    outln!("format      {}", fi.format.name());
    outln!("points      {}", fi.points);
    outln!("attributes  {}", fi.attributes.join(" "));
    outln!(
        "bounds      [{:.6}, {:.6}, {:.6}] .. [{:.6}, {:.6}, {:.6}]",
        fi.bounds.min[0],
        fi.bounds.min[1],
        fi.bounds.min[2],
        fi.bounds.max[0],
        fi.bounds.max[1],
        fi.bounds.max[2]
    );
    if fi.invalid_points > 0 {
        outln!(
            "invalid     {} points with NaN/infinite coordinates",
            fi.invalid_points
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cli_is_consistent() {
        use clap::CommandFactory;
        Cli::command().debug_assert();
    }
}
