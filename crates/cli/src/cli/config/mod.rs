//! Every option checked once, before any work: the parsed [`Cli`] becomes a [`Config`] of
//! typed values (bytes, library enums and parameters, points, paths), or the error that names
//! the offending option. The commands then only call the library.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

use scanflow::exec::progress::{Mode, Progress};
use scanflow::exec::{Ctx, default_mem_bytes, human_bytes, parse_mem};
use scanflow::io::mesh_write::{MeshFormat, MeshTarget};
use scanflow::normals::{NormalParams, NormalsMode};
use scanflow::pipeline::ReconParams;
use scanflow::pipeline::ingest::IngestParams;
use scanflow::pipeline::shard::Shard;
use scanflow::recon::{DEPTHS, PointWeight, Smoothing};
use scanflow::synth::{BUMPY_RELIEF, Shape};

use super::args::{
    CheckArgs, Cli, Cmd, Common, CompletionsArgs, DemoArgs, HexcheckArgs, HexmeshArgs, InfoArgs,
    IngestArgs, ManArgs, MergeArgs, MeshOutOpts, NormalOpts, ReconstructArgs, SynthArgs,
};
pub use super::fit::FitConfig;
use super::paths;
pub use super::spectral::SpectralConfig;

mod reconstruct;
pub use reconstruct::*;

/// zstd levels `--zstd-level` accepts: zstd's fast levels from -7 up to its level 19 (20 and
/// above need zstd's "ultra" mode and far more memory).
const ZSTD_LEVELS: std::ops::RangeInclusive<i32> = -7..=19;

/// Fewest `--neighbours`: a plane needs three points.
const MIN_NEIGHBOURS: usize = 3;

/// Most `--threads`: more workers than this only cost memory and start-up time (a worker
/// pool of 100,000 threads takes tens of seconds to fail).
const MAX_THREADS: usize = 1024;

/// `--tile` values: powers of two in this range (the plan then keeps a tile at least one
/// leaf's block and at most the whole grid).
const TILES: std::ops::RangeInclusive<u64> = 8..=4096;

/// Widest `--smooth`, in voxels: as wide as the narrowest detail overlap of a leaf (a quarter
/// of the smallest leaf block, 32 voxels).
const MAX_SMOOTH_VOXELS: f64 = 8.0;

/// Largest `--point-weight`: beyond it the screened solve's conjugate gradients need more
/// iterations than the leaf solve's time allows, and the surface is held to every sample's
/// noise.
const MAX_POINT_WEIGHT: f64 = 64.0;

/// One validated command.
pub enum Config {
    /// `scanflow synth`.
    Synth(SynthConfig),
    /// `scanflow ingest`.
    Ingest(IngestConfig),
    /// `scanflow reconstruct`.
    Reconstruct(ReconstructConfig),
    /// `scanflow check`.
    Check(CheckConfig),
    /// `hexmesh`.
    Hexmesh(HexmeshConfig),
    /// `hexcheck`.
    Hexcheck(HexcheckArgs),
    /// `scanflow info`.
    Info(InfoConfig),
    /// `scanflow demo`.
    Demo(DemoConfig),
    /// `scanflow filter`, `resample` and `spectrum`.
    Spectral(SpectralConfig),
    /// `fit`.
    Fit(FitConfig),
    /// `merge`.
    Merge(MergeConfig),
    /// `completions`.
    Completions(CompletionsArgs),
    /// `man`.
    Man(ManArgs),
}

impl Config {
    /// Check every option of `cli`.
    pub fn new(cli: Cli) -> Result<Config> {
        Ok(match cli.cmd {
            Cmd::Synth(a) => Config::Synth(SynthConfig::new(a)?),
            Cmd::Ingest(a) => Config::Ingest(IngestConfig::new(a)?),
            Cmd::Reconstruct(a) => Config::Reconstruct(ReconstructConfig::new(a)?),
            Cmd::Check(a) => Config::Check(CheckConfig::new(a)),
            Cmd::Info(a) => Config::Info(InfoConfig::new(a)?),
            Cmd::Hexmesh(a) => Config::Hexmesh(HexmeshConfig::new(a)?),
            Cmd::Hexcheck(a) => Config::Hexcheck(a),
            Cmd::Demo(a) => Config::Demo(DemoConfig::new(a)?),
            Cmd::Filter(a) => Config::Spectral(SpectralConfig::filter(a)?),
            Cmd::Resample(a) => Config::Spectral(SpectralConfig::resample(a)?),
            Cmd::Spectrum(a) => Config::Spectral(SpectralConfig::spectrum(a)?),
            Cmd::Fit(a) => Config::Fit(FitConfig::new(a)?),
            Cmd::Merge(a) => Config::Merge(MergeConfig::new(a)?),
            Cmd::Completions(a) => Config::Completions(a),
            Cmd::Man(a) => {
                paths::output_dir(&a.output)?;
                Config::Man(a)
            }
        })
    }
}

/// Threads, memory and progress of a command that runs a pipeline.
pub struct RunConfig {
    /// Worker threads; 0 is one per core.
    pub threads: usize,
    /// The memory budget, bytes.
    pub mem_bytes: u64,
    /// How progress is shown.
    pub progress: Mode,
}

impl RunConfig {
    /// Check threads, memory and progress.
    pub(super) fn new(c: &Common) -> Result<RunConfig> {
        if c.threads > MAX_THREADS {
            bail!(
                "--threads {}: expected at most {MAX_THREADS} (0: one per core)",
                c.threads
            );
        }
        let mem_bytes = match &c.mem {
            Some(s) => parse_mem(s)?,
            None => default_mem_bytes(),
        };
        Ok(RunConfig {
            threads: c.threads,
            mem_bytes,
            progress: c.progress.into(),
        })
    }

    /// The worker pool, budget and progress reporter of the command.
    pub fn ctx(&self) -> Result<Ctx> {
        Ok(Ctx::new(
            self.threads,
            self.mem_bytes,
            Progress::new(self.progress),
        )?)
    }
}

/// Where normals come from and how they are estimated.
#[derive(Clone, Copy)]
pub struct NormalsConfig {
    /// `--normals`.
    pub mode: NormalsMode,
    /// `--neighbours` (at least 3), `--fixed-neighbours`, `--robust-normals`.
    pub params: NormalParams,
}

impl NormalsConfig {
    /// Check the normal options.
    pub(super) fn new(n: &NormalOpts) -> Result<NormalsConfig> {
        if n.neighbours < MIN_NEIGHBOURS {
            bail!(
                "--neighbours {}: a plane fit needs at least {MIN_NEIGHBOURS}",
                n.neighbours
            );
        }
        Ok(NormalsConfig {
            mode: n.normals.into(),
            params: NormalParams {
                k: n.neighbours,
                robust: n.robust_normals,
                adaptive: !n.fixed_neighbours,
            },
        })
    }
}

impl Default for NormalsConfig {
    /// `--normals auto` with the default estimation.
    fn default() -> NormalsConfig {
        NormalsConfig {
            mode: NormalsMode::Auto,
            params: NormalParams::default(),
        }
    }
}

/// Point files to read: plain files, a Scanalyze `.conf`, and the scanner positions.
pub struct Inputs {
    /// Point files given on the command line.
    pub files: Vec<PathBuf>,
    /// `--conf`.
    pub conf: Option<PathBuf>,
    /// `--viewpoint`s: none, one for all `files`, or one per file in order.
    pub viewpoints: Vec<[f64; 3]>,
}

impl Inputs {
    /// Check the inputs and their viewpoints.
    pub(super) fn new(
        files: Vec<PathBuf>,
        conf: Option<PathBuf>,
        viewpoints: &[String],
    ) -> Result<Inputs> {
        let viewpoints: Vec<[f64; 3]> = viewpoints
            .iter()
            .map(|v| parse_point(v))
            .collect::<Result<_>>()?;
        let n = viewpoints.len();
        if n > 1 && n != files.len() {
            bail!(
                "--viewpoint given {n} times for {} input files: give it once for all, or once per file",
                files.len()
            );
        }
        Ok(Inputs {
            files,
            conf,
            viewpoints,
        })
    }

    /// The files given: point files and the `.conf`.
    pub fn paths(&self) -> Vec<&Path> {
        self.files
            .iter()
            .chain(self.conf.as_ref())
            .map(PathBuf::as_path)
            .collect()
    }

    /// One point file, no `.conf`, no viewpoint.
    pub fn file(path: PathBuf) -> Inputs {
        Inputs {
            files: vec![path],
            conf: None,
            viewpoints: Vec::new(),
        }
    }
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

/// `scanflow synth`.
pub struct SynthConfig {
    /// Threads, memory, progress.
    pub run: RunConfig,
    /// The surface.
    pub shape: Shape,
    /// Number of points (the library rejects 0).
    pub points: u64,
    /// Noise relative to the bounding-box diagonal (the library rejects negative or NaN).
    pub noise: f64,
    /// Random seed.
    pub seed: u64,
    /// `bumpy`'s relief (amplitude, frequency), when not the standard one.
    pub relief: Option<[f64; 2]>,
    /// Output PLY.
    pub output: PathBuf,
}

impl SynthConfig {
    fn new(a: SynthArgs) -> Result<SynthConfig> {
        paths::output_file(&a.output, paths::PLY)?;
        let shape: Shape = a.shape.into();
        // Checked against the shape and ranges by the library, before any file is touched.
        let relief = (a.amplitude.is_some() || a.frequency.is_some()).then(|| {
            [
                a.amplitude.unwrap_or(BUMPY_RELIEF[0]),
                a.frequency.unwrap_or(BUMPY_RELIEF[1]),
            ]
        });
        Ok(SynthConfig {
            run: RunConfig::new(&a.common)?,
            shape,
            points: a.points,
            noise: a.noise,
            seed: a.seed,
            relief,
            output: a.output,
        })
    }
}

/// `scanflow ingest`.
pub struct IngestConfig {
    /// Threads, memory, progress.
    pub run: RunConfig,
    /// What to read.
    pub inputs: Inputs,
    /// The store directory to create.
    pub output: PathBuf,
    /// Cell size, invalid points, compression, normals.
    pub params: IngestParams,
    /// `--shard`, with the work directory the tasks share.
    pub split: Option<(Shard, PathBuf)>,
}

impl IngestConfig {
    fn new(a: IngestArgs) -> Result<IngestConfig> {
        if !ZSTD_LEVELS.contains(&a.zstd_level) {
            bail!(
                "--zstd-level {}: expected {} ..= {}",
                a.zstd_level,
                ZSTD_LEVELS.start(),
                ZSTD_LEVELS.end()
            );
        }
        let run = RunConfig::new(&a.common)?;
        let inputs = Inputs::new(a.inputs, a.conf, &a.normal.viewpoint)?;
        let split = match &a.shard {
            Some(text) => {
                let shard = Shard::parse(text, |k| std::env::var(k).ok())?;
                // Another task may have written the store already: the ingest checks it.
                paths::writable_parent(&a.output)?;
                Some((shard, work_dir(a.work_dir, &a.output)?))
            }
            None => {
                if let Some(w) = &a.work_dir {
                    bail!(
                        "--work-dir {}: only a split ingest (--shard) has a work directory; one process builds the store beside -o",
                        w.display()
                    );
                }
                paths::new_dir(&a.output)?;
                None
            }
        };
        paths::not_an_input(&a.output, &inputs.paths())?;
        let normals = NormalsConfig::new(&a.normal)?;
        Ok(IngestConfig {
            run,
            inputs,
            split,
            output: a.output,
            params: IngestParams {
                max_cell_points: a.max_cell_points,
                skip_invalid: a.skip_invalid,
                zstd_level: a.zstd_level,
                normals: normals.mode,
                normal_params: normals.params,
                ..Default::default()
            },
        })
    }
}

/// The points `reconstruct` reads.
pub enum Points {
    /// One store directory made by `ingest`, read as it is.
    Store {
        /// The store.
        dir: PathBuf,
        /// `--normals` or `--viewpoint` was given: they apply to `ingest`, not to a store.
        ignores_normal_options: bool,
    },
    /// Point files, ingested into the work directory first.
    Files(Inputs, NormalsConfig),
}

impl Points {
    /// One directory argument is a store; anything else is ingested into the work directory.
    pub(super) fn new(
        inputs: Vec<PathBuf>,
        conf: Option<PathBuf>,
        n: &NormalOpts,
    ) -> Result<Points> {
        let normals = NormalsConfig::new(n)?;
        Ok(
            if conf.is_none() && inputs.len() == 1 && inputs[0].is_dir() {
                Points::Store {
                    ignores_normal_options: normals.mode != NormalsMode::Auto
                        || !n.viewpoint.is_empty(),
                    dir: inputs[0].clone(),
                }
            } else {
                Points::Files(Inputs::new(inputs, conf, &n.viewpoint)?, normals)
            },
        )
    }
}

/// `scanflow merge`.
pub struct MergeConfig {
    /// Threads, memory, progress.
    pub run: RunConfig,
    /// The shards' work directory.
    pub work_dir: PathBuf,
    /// The mesh to write.
    pub output: PathBuf,
    /// Its format and normals.
    pub mesh: MeshTarget,
    /// The picture and report.
    pub outputs: RunOutputs,
    /// Keep the work directory after success.
    pub keep_work: bool,
}

impl MergeConfig {
    fn new(a: MergeArgs) -> Result<MergeConfig> {
        let run = RunConfig::new(&a.common)?;
        let (mesh, outputs) = mesh_target(&a.output, &a.mesh, false)?;
        if !a.work_dir.is_dir() {
            bail!("{}: no such work directory", a.work_dir.display());
        }
        if paths::inside(&a.output, &a.work_dir) {
            bail!(
                "-o {}: lies inside the work directory {}, which merge removes after success",
                a.output.display(),
                a.work_dir.display()
            );
        }
        Ok(MergeConfig {
            run,
            work_dir: a.work_dir,
            output: a.output,
            mesh,
            outputs,
            keep_work: a.keep_work,
        })
    }
}

/// The mesh output `-o path`: its format by extension (with `--ascii`), what it can carry
/// (`--out-normals`, `--density`), the path's checks ([`paths::output_file_as`]), and the
/// picture and report files.
fn mesh_target(path: &Path, o: &MeshOutOpts, density: bool) -> Result<(MeshTarget, RunOutputs)> {
    let format = MeshFormat::for_path(path, o.ascii)?;
    format.carries(path, o.out_normals, density)?;
    paths::output_file_as(
        "-o",
        path,
        &MeshFormat::EXTENSIONS,
        "a mesh (PLY, OBJ or STL)",
    )?;
    if let Some(p) = &o.preview {
        paths::output_file_as("--preview", p, &["png"], "a PNG picture")?;
    }
    if let Some(p) = &o.report {
        paths::output_file_as("--report", p, &["html", "json"], "an HTML or JSON report")?;
    }
    for (opt, p) in [("--preview", &o.preview), ("--report", &o.report)] {
        if p.as_deref() == Some(path) {
            bail!("{opt} {}: the same file as -o", path.display());
        }
    }
    if o.preview.is_some() && o.preview == o.report {
        bail!("--report: the same file as --preview");
    }
    let html = o.report.as_ref().is_some_and(|r| {
        r.extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("html"))
    });
    if let Some(r) = o.trim_islands
        && !(0.0..1.0).contains(&r)
    {
        bail!(
            "--trim-islands {r}: expected a fraction of the mesh's area, at least 0 and under 1 (PoissonRecon's --aRatio default is 0.001)"
        );
    }
    let mesh = MeshTarget {
        path: path.to_path_buf(),
        format,
        normals: o.out_normals,
        islands: o.trim_islands,
        preview: (o.preview.is_some() || html).then_some(PREVIEW_SIDE),
    };
    let outputs = RunOutputs {
        preview: o.preview.clone(),
        report: o.report.clone(),
    };
    Ok((mesh, outputs))
}

/// Pixels a side of each of the preview's three views.
const PREVIEW_SIDE: usize = 400;

/// The picture and report a run writes besides its mesh.
#[derive(Debug, Clone, Default)]
pub struct RunOutputs {
    /// `--preview`.
    pub preview: Option<PathBuf>,
    /// `--report`.
    pub report: Option<PathBuf>,
}

/// `--work-dir` when given (its parent must exist), else `OUTPUT.work`.
pub(super) fn work_dir(given: Option<PathBuf>, output: &Path) -> Result<PathBuf> {
    match given {
        Some(w) if !paths::parent(&w).is_dir() => bail!(
            "--work-dir {}: directory {} does not exist",
            w.display(),
            paths::parent(&w).display()
        ),
        Some(w) => Ok(w),
        None => Ok(default_work_dir(output)),
    }
}

/// `OUTPUT.work`, beside the output.
pub fn default_work_dir(output: &Path) -> PathBuf {
    let mut s = output.as_os_str().to_owned();
    s.push(".work");
    PathBuf::from(s)
}

/// `scanflow check`.
pub struct CheckConfig {
    /// The mesh or point file.
    pub input: PathBuf,
    /// `--truth`.
    pub truth: Option<PathBuf>,
    /// `--reference` (the library refuses it together with a truth).
    pub reference: Option<PathBuf>,
    /// Sample points per distance direction.
    pub samples: usize,
    /// Print JSON.
    pub json: bool,
}

impl CheckConfig {
    fn new(a: CheckArgs) -> CheckConfig {
        CheckConfig {
            input: a.input,
            truth: a.truth,
            reference: a.reference,
            samples: a.samples,
            json: a.json,
        }
    }
}

/// `scanflow info`.
pub struct InfoConfig {
    /// Threads, memory, progress.
    pub run: RunConfig,
    /// A point file or a store directory.
    pub path: PathBuf,
    /// Print JSON.
    pub json: bool,
    /// Read and check every cell of a store.
    pub verify: bool,
}

impl InfoConfig {
    fn new(a: InfoArgs) -> Result<InfoConfig> {
        Ok(InfoConfig {
            run: RunConfig::new(&a.common)?,
            path: a.path,
            json: a.json,
            verify: a.verify,
        })
    }
}

/// `scanflow demo`.
pub struct DemoConfig {
    /// Threads, memory, progress.
    pub run: RunConfig,
    /// The demo directory.
    pub dir: PathBuf,
    /// Points to synthesise.
    pub points: u64,
}

impl DemoConfig {
    fn new(a: DemoArgs) -> Result<DemoConfig> {
        paths::output_dir(&a.output)?;
        Ok(DemoConfig {
            run: RunConfig::new(&a.common)?,
            dir: a.output,
            points: a.points,
        })
    }
}

/// `scanflow hexmesh`.
pub struct HexmeshConfig {
    /// Threads, memory, progress.
    pub run: RunConfig,
    /// The run (`--report` in it).
    pub job: scanflow::pipeline::hexmesh::HexJob,
}

/// A hexahedron edge given as `option` must be positive and finite.
fn hex_scale(scale: Option<f64>, option: &str) -> Result<()> {
    if let Some(x) = scale
        && !(x.is_finite() && x > 0.0)
    {
        bail!("{option} {x}: the hexahedron edge must be a positive number of input units");
    }
    Ok(())
}

/// The extensions of the volume meshes scanflow writes.
const VOLUME_EXTS: &[&str] = &["vtk", "mesh", "msh"];

impl HexmeshConfig {
    fn new(a: HexmeshArgs) -> Result<HexmeshConfig> {
        use scanflow::pipeline::hexmesh::{FrameChoice, HexJob};
        let frames = match a.frames.as_str() {
            "constant" => FrameChoice::Constant,
            "smooth" => FrameChoice::Smooth,
            "polycube" => FrameChoice::Polycube,
            s => match s.strip_prefix("meta:") {
                Some(f) if !f.is_empty() => {
                    let f = PathBuf::from(f);
                    if !f.is_file() {
                        bail!("--frames {s}: {} is not a file", f.display());
                    }
                    FrameChoice::Meta(f)
                }
                _ => bail!(
                    "--frames {s}: expected polycube, smooth, constant or meta:FILE (a hexahedral meta-mesh)"
                ),
            },
        };
        hex_scale(a.scale, "--scale")?;
        if let Some(x) = a.tet_size
            && !(x.is_finite() && x > 0.0)
        {
            bail!("--tet-size {x}: the tetrahedron edge must be a positive number of input units");
        }
        if !a.input.is_file() {
            bail!("{}: no such file", a.input.display());
        }
        paths::output_file_as("-o", &a.output, VOLUME_EXTS, "a hexahedral mesh")?;
        paths::not_an_input(&a.output, &[a.input.as_path()])?;
        if let Some(r) = &a.report {
            paths::output_file_as("--report", r, &["json"], "JSON")?;
            paths::not_an_input(r, &[a.input.as_path()])?;
        }
        Ok(HexmeshConfig {
            run: RunConfig::new(&a.common)?,
            job: HexJob {
                input: a.input,
                output: a.output,
                frames,
                scale: a.scale,
                tet_size: a.tet_size,
                pillow: match (a.pillow, a.no_pillow) {
                    (true, _) => Some(true),
                    (_, true) => Some(false),
                    _ => None,
                },
                relax: !a.no_relax,
                keep_inverted: a.keep_inverted,
                report: a.report,
            },
        })
    }
}

#[cfg(test)]
mod tests;
