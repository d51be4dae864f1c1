//! `scanflow fit`: its options checked (before any work), the fit run, its summary printed.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};

use scanflow::exec::{Ctx, human_bytes, peak_rss_bytes};
use scanflow::pipeline::fit::{FitJob, FitStats, Tolerance, fit_files, write_report};
use scanflow::pipeline::fit_patches::{MIN_PATCH_POINTS, PatchShape};
use scanflow::spline::fit::{Fairness, FitParams, Refine};
use scanflow::spline::param::Method;

use super::args::{FairnessChoice, FitArgs, ParamChoice, RefineChoice};
use super::config::{Points, RunConfig, work_dir};
use super::paths;

/// Finest level `--max-level` allows (knot spacing 2⁻²⁰ of the coarsest).
pub const MAX_LEVEL: usize = 20;

/// A validated `fit`.
pub struct FitConfig {
    /// Threads, memory, progress.
    pub run: RunConfig,
    /// Point files or a store.
    pub inputs: Vec<PathBuf>,
    /// The IGES file.
    pub output: PathBuf,
    /// The fit.
    pub job: FitJob,
    /// `--tiles`.
    pub tiles: bool,
    /// `--patches`: the patches' size and flatness.
    pub patches: Option<PatchShape>,
    /// What `--tiles` and `--patches` read: a store, or point files ingested with these
    /// normal options.
    pub points: Points,
    /// The work directory (`--tiles`).
    pub work_dir: PathBuf,
    /// `--keep-work`.
    pub keep_work: bool,
}

/// `--tolerance`: a positive number, or a positive percentage of the diagonal.
fn tolerance(s: &str) -> Result<Tolerance> {
    let t = s.trim();
    let (num, rel) = match t.strip_suffix('%') {
        Some(n) => (n.trim(), true),
        None => (t, false),
    };
    let x: f64 = num.parse().map_err(|_| {
        anyhow::anyhow!(
            "--tolerance {s}: expected a length in input units (0.01) or a percentage of the bounding-box diagonal (0.1%)"
        )
    })?;
    if !(x.is_finite() && x > 0.0) {
        bail!("--tolerance {s}: expected a positive value");
    }
    if rel && x >= 100.0 {
        bail!("--tolerance {s}: expected a percentage below 100%");
    }
    Ok(if rel {
        Tolerance::Relative(x / 100.0)
    } else {
        Tolerance::Absolute(x)
    })
}

impl FitConfig {
    /// Checks every option and output path.
    pub fn new(a: FitArgs) -> Result<FitConfig> {
        let run = RunConfig::new(&a.common)?;
        if a.inputs.is_empty() {
            bail!("no input: give point files (PLY, LAS/LAZ, XYZ) or a store directory");
        }
        let tol = tolerance(&a.tolerance)?;
        if !(a.omega.is_finite() && a.omega > 0.0 && a.omega <= 1e3) {
            bail!(
                "--omega {}: expected a fairness weight in (0, 1000]",
                a.omega
            );
        }
        if a.max_level > MAX_LEVEL {
            bail!("--max-level {}: expected at most {MAX_LEVEL}", a.max_level);
        }
        paths::output_file_as("-o", &a.output, &["igs", "iges"], "IGES")?;
        let mut outs: Vec<(&str, &Path)> = vec![("-o", &a.output)];
        if let Some(p) = &a.preview {
            paths::output_file_as("--preview", p, &["ply"], "binary PLY")?;
            outs.push(("--preview", p));
        }
        if let Some(p) = &a.report {
            paths::output_file_as("--report", p, &["json"], "JSON")?;
            outs.push(("--report", p));
        }
        for (i, (oa, pa)) in outs.iter().enumerate() {
            for (ob, pb) in &outs[..i] {
                if pa == pb {
                    bail!(
                        "{oa} {}: is also {ob}; give each output its own name",
                        pa.display()
                    );
                }
            }
        }
        let given: Vec<&Path> = a.inputs.iter().map(PathBuf::as_path).collect();
        for (_, p) in &outs {
            paths::not_an_input(p, &given)?;
        }
        if !a.tiles && !a.patches && a.inputs.iter().any(|p| p.is_dir()) {
            bail!(
                "{}: is a directory; a store is fitted tile by tile (--tiles) or patch by patch (--patches)",
                a.inputs
                    .iter()
                    .find(|p| p.is_dir())
                    .map_or(String::new(), |p| p.display().to_string())
            );
        }
        if a.tile_points < 1000 {
            bail!("--tile-points {}: expected at least 1000", a.tile_points);
        }
        if a.patch_points < MIN_PATCH_POINTS {
            bail!(
                "--patch-points {}: expected at least {MIN_PATCH_POINTS}",
                a.patch_points
            );
        }
        if !(a.patch_angle > 0.0 && a.patch_angle < 180.0) {
            bail!(
                "--patch-angle {}: expected a full cone aperture in degrees, in (0, 180)",
                a.patch_angle
            );
        }
        let points = Points::new(a.inputs.clone(), None, &a.normal)?;
        let work_dir = work_dir(a.work_dir, &a.output)?;
        let method = match a.param {
            ParamChoice::Project => Method::Project,
            ParamChoice::Uniform => Method::uniform(),
            ParamChoice::Chord => Method::chord(),
            ParamChoice::Spring => Method::real_spring(),
        };
        let fit = FitParams {
            interpolate: a.interpolate,
            fairness: match a.fairness {
                FairnessChoice::Simple => Fairness::Simple,
                FairnessChoice::Data => Fairness::Data,
            },
            omega: a.omega,
            max_level: a.max_level,
            refine: match a.refine {
                RefineChoice::Local => Refine::Local,
                RefineChoice::Global => Refine::Global,
            },
            ..FitParams::default()
        };
        Ok(FitConfig {
            run,
            inputs: a.inputs,
            output: a.output,
            job: FitJob {
                fit,
                tolerance: tol,
                method,
                preview: a.preview,
                report: a.report,
                tile_points: a.tile_points,
            },
            tiles: a.tiles,
            patches: a.patches.then_some(PatchShape {
                points: a.patch_points,
                angle: a.patch_angle,
            }),
            points,
            work_dir,
            keep_work: a.keep_work,
        })
    }
}

/// Run the fit and print its summary. A tolerance missed is reported and exits non-zero.
pub fn run(c: &FitConfig, ctx: &Ctx) -> Result<()> {
    let st = if c.tiles || c.patches.is_some() {
        super::fit_tiles::run(c, ctx)?
    } else {
        fit_files(&c.inputs, &c.output, &c.job, ctx)?
    };
    if let Some(p) = &c.job.report {
        write_report(p, &st, &c.job)?;
    }
    summary(&st, c);
    let missed: usize = st
        .surfaces
        .iter()
        .map(|s| s.fit.report.missed.iter().map(|m| m.points).sum::<usize>())
        .sum();
    if st.surfaces.iter().any(|s| !s.fit.report.met) {
        let mut regions: Vec<String> = Vec::new();
        for (k, s) in st.surfaces.iter().enumerate() {
            for m in s.fit.report.missed.iter().take(5) {
                regions.push(format!(
                    "surface {k}: {} points in [{:.6}, {:.6}, {:.6}]..[{:.6}, {:.6}, {:.6}] up to {:.3e}",
                    m.points,
                    m.bounds[0][0],
                    m.bounds[0][1],
                    m.bounds[0][2],
                    m.bounds[1][0],
                    m.bounds[1][1],
                    m.bounds[1][2],
                    m.max_deviation
                ));
            }
        }
        bail!(
            "the tolerance {:.3e} was not met within --max-level {} at {missed} points (the surfaces were written; the report lists every region): {}",
            st.tolerance,
            c.job.fit.max_level,
            regions.join("; ")
        );
    }
    Ok(())
}

fn summary(st: &FitStats, c: &FitConfig) {
    let t = st.totals();
    outln!(
        "fitted {} points with {} surface(s) into {} in {:.2} s ({:.0} points/s); peak memory {}",
        st.input_points,
        st.surfaces.len(),
        c.output.display(),
        st.secs,
        st.input_points as f64 / st.secs.max(1e-9),
        human_bytes(peak_rss_bytes())
    );
    outln!(
        "control points: {} hierarchical, {} in the exported tensor-product surface(s)",
        t.control_points,
        t.tensor_control_points
    );
    outln!(
        "deviation: max {:.4e}, RMS {:.4e} (tolerance {:.4e}; diagonal {:.4e})",
        t.max_deviation,
        t.rms_deviation,
        st.tolerance,
        st.diagonal
    );
    match st.seam_gap {
        Some(g) if c.tiles => {
            outln!("largest gap between neighbouring tiles along their seams: {g:.3e}")
        }
        Some(g) => outln!(
            "largest gap between neighbouring patches' surfaces along their shared boundaries: {g:.3e} ({} pairs of neighbours)",
            st.gaps.len()
        ),
        None => {}
    }
}
