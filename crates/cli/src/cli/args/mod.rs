//! The command line as clap sees it: one struct per command, a [`ValueEnum`] per choice
//! option, mapped onto the library's enums here. Values are checked in `config`, once.

use std::ffi::OsString;
use std::path::PathBuf;

use clap::error::{ContextKind, ContextValue, ErrorKind};
use clap::{Args, Parser, Subcommand, ValueEnum};

use scanflow::exec::progress::{JSON_INTERVAL, Mode};
use scanflow::extract::gpu::GpuMode;
use scanflow::normals::NormalsMode;
use scanflow::pipeline::ingest::IngestParams;
use scanflow::synth::Shape;

mod spectral;
pub use spectral::*;

mod fit;
pub use fit::*;

/// `reconstruct --depth` (and the demo's): 2^9 = 512 cells per edge of the bounding cube.
pub const DEFAULT_DEPTH: u32 = 9;

/// `check --samples` (and the demo's): points sampled per distance direction.
pub const DEFAULT_CHECK_SAMPLES: usize = 200_000;

/// `synth --seed` (and the demo's).
pub const DEFAULT_SEED: u64 = 1;

/// Out-of-core streaming surface reconstruction for huge 3D scans.
#[derive(Parser, Debug)]
#[command(name = "scanflow", version, about, propagate_version = true)]
pub struct Cli {
    /// The command.
    #[command(subcommand)]
    pub cmd: Cmd,
}

/// Options of every command that runs a pipeline.
#[derive(Args, Debug, Clone)]
pub struct Common {
    /// Worker threads (default: one per core).
    #[arg(long, global = true, default_value_t = 0)]
    pub threads: usize,
    /// Memory budget: 512M, 4G, 50% of available; default half the available memory.
    #[arg(long, global = true)]
    pub mem: Option<String>,
    /// Progress display.
    #[arg(long, global = true, value_enum, default_value_t = ProgressChoice::Auto)]
    pub progress: ProgressChoice,
}

/// `--progress`.
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProgressChoice {
    /// Bars on a terminal, JSON lines otherwise.
    Auto,
    /// Bars.
    Bars,
    /// One JSON line on stderr per stage, and every 5 s while it runs.
    Json,
    /// Nothing.
    #[value(name = "none")]
    Quiet,
}

impl From<ProgressChoice> for Mode {
    fn from(c: ProgressChoice) -> Mode {
        match c {
            ProgressChoice::Auto => Mode::detect(),
            ProgressChoice::Bars => Mode::Bars,
            ProgressChoice::Json => Mode::Json {
                every: JSON_INTERVAL,
            },
            ProgressChoice::Quiet => Mode::Quiet,
        }
    }
}

/// Normal estimation options (ingest and reconstruct).
#[derive(Args, Debug, Clone)]
pub struct NormalOpts {
    /// Where normals come from.
    #[arg(long, value_enum, default_value_t = NormalsChoice::Auto)]
    pub normals: NormalsChoice,
    /// Neighbours per plane fit when estimating normals (the point itself included); cells
    /// whose points are noisy use more, up to 8 times as many (see --fixed-neighbours).
    #[arg(long, default_value_t = scanflow::normals::DEFAULT_K)]
    pub neighbours: usize,
    /// Use exactly --neighbours everywhere, even where noise dominates the fits.
    #[arg(long)]
    pub fixed_neighbours: bool,
    /// Re-fit each estimated normal once with robust (Cauchy) weights: less pulled by noise
    /// and outliers, a little slower.
    #[arg(long)]
    pub robust_normals: bool,
    /// Scanner position x,y,z (common frame) that estimated normals face: once for all inputs,
    /// or once per input file in order. `.conf` scans take theirs from their pose.
    #[arg(long, value_name = "X,Y,Z")]
    pub viewpoint: Vec<String>,
}

/// How a mesh is written, besides the format its extension names.
#[derive(Args, Debug)]
pub struct MeshOutOpts {
    /// Write PLY as text instead of binary.
    #[arg(long)]
    pub ascii: bool,
    /// Give each vertex a unit normal, the area-weighted mean of its triangles' (PLY nx ny
    /// nz, OBJ vn; PoissonRecon's --normals output). STL always has each triangle's.
    #[arg(long)]
    pub out_normals: bool,
    /// Leave out every connected piece of the mesh whose area is under R of the whole, with
    /// its vertices: the small islands trimming leaves (PoissonRecon's SurfaceTrimmer
    /// --aRatio, whose default is 0.001). 0 <= R < 1.
    #[arg(
        long,
        value_name = "R",
        alias = "aRatio",
        allow_negative_numbers = true
    )]
    pub trim_islands: Option<f64>,
    /// Write a picture of the mesh here (PNG: front, side and isometric views, drawn as the
    /// mesh is written).
    #[arg(long, value_name = "PNG")]
    pub preview: Option<PathBuf>,
    /// Write a report of the run here: .html (one self-contained page: inputs, options,
    /// stage times, memory over time, the leaf map, the mesh's check and its picture) or
    /// .json (the same figures).
    #[arg(long, value_name = "HTML|JSON")]
    pub report: Option<PathBuf>,
}

/// `--normals`.
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum NormalsChoice {
    /// The inputs' normals when every input has them, else estimated.
    Auto,
    /// The inputs' normals; an error for an input without them.
    Use,
    /// Estimated, ignoring the inputs' normals.
    Estimate,
}

impl From<NormalsChoice> for NormalsMode {
    fn from(c: NormalsChoice) -> NormalsMode {
        match c {
            NormalsChoice::Auto => NormalsMode::Auto,
            NormalsChoice::Use => NormalsMode::Use,
            NormalsChoice::Estimate => NormalsMode::Estimate,
        }
    }
}

/// `--gpu`.
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum GpuChoice {
    /// A discrete or integrated GPU when present, else the CPU.
    Auto,
    /// Any Vulkan/Metal/DX12 adapter, software ones included; an error if there is none.
    On,
    /// The CPU only.
    Off,
}

impl From<GpuChoice> for GpuMode {
    fn from(c: GpuChoice) -> GpuMode {
        match c {
            GpuChoice::Auto => GpuMode::Auto,
            GpuChoice::On => GpuMode::On,
            GpuChoice::Off => GpuMode::Off,
        }
    }
}

/// The shapes of `synth`.
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShapeChoice {
    /// Unit sphere.
    Sphere,
    /// Torus around the z axis, R = 1, r = 0.35.
    Torus,
    /// Two concentric spheres, radii 1 and 0.97 (a thin shell).
    #[value(name = "twosheets")]
    TwoSheets,
    /// Unit sphere with a sinusoidal relief.
    Bumpy,
    /// Gaussian bumps over [-1, 1]² (a terrain), uniform in (x, y).
    #[value(name = "heightfield")]
    HeightField,
}

impl From<ShapeChoice> for Shape {
    fn from(c: ShapeChoice) -> Shape {
        match c {
            ShapeChoice::Sphere => Shape::Sphere,
            ShapeChoice::Torus => Shape::Torus,
            ShapeChoice::TwoSheets => Shape::TwoSheets,
            ShapeChoice::Bumpy => Shape::Bumpy,
            ShapeChoice::HeightField => Shape::HeightField,
        }
    }
}

/// The commands.
#[derive(Subcommand, Debug)]
pub enum Cmd {
    /// Write oriented samples of a synthetic shape, with its exact description (.truth.json).
    Synth(SynthArgs),
    /// Bucket point files into an on-disk octree store.
    Ingest(IngestArgs),
    /// Reconstruct a surface from points: adaptive two-level FFT Poisson solve, marching
    /// cubes tile by tile; closed unless --trim.
    Reconstruct(ReconstructArgs),
    /// Check a mesh: counts, watertight, manifold, components; distances to a truth or reference.
    Check(CheckArgs),
    /// Describe a point file or a store.
    Info(InfoArgs),
    /// Synthesise a noisy bumpy sphere, reconstruct it at depth 9 and check the mesh against
    /// the exact surface.
    Demo(DemoArgs),
    /// Filter points by the spectra of their patches' height fields (Pauly & Gross 2001):
    /// low-pass, band-stop, enhancement or Wiener restoration; writes the filtered points.
    Filter(FilterArgs),
    /// Resample points within an error bound: each patch at the rate its spectrum needs.
    Resample(ResampleArgs),
    /// Write the patch layout, power spectra of sample patches and a summary (JSON).
    Spectrum(SpectrumArgs),
    /// Fit hierarchical B-spline surfaces to scattered points (Greiner & Hormann 1997) and
    /// write them as IGES (entity 128): one surface for a disc-like patch (a range scan, a
    /// height field), one per tile for terrain (--tiles).
    Fit(FitArgs),
    /// Weld the tiles the shards of a split reconstruction (reconstruct --shard) left in their
    /// work directory into one mesh, the same bytes one process writes.
    Merge(MergeArgs),
    /// Hexahedral mesh of a tetrahedral one by CubeCover (Nieser, Reitebuch, Polthier 2011):
    /// frame field, singular edges, integer-grid parameterisation with greedy rounding, hex
    /// extraction, relaxation; written only when no hexahedron is inverted.
    Hexmesh(HexmeshArgs),
    /// Quality of a hexahedral mesh (Verdict's measures); exit 1 when a hexahedron is inverted.
    Hexcheck(HexcheckArgs),
    /// Print a shell completion script on stdout: `scanflow completions bash >
    /// ~/.local/share/bash-completion/completions/scanflow`.
    Completions(CompletionsArgs),
    /// Write the man pages (scanflow.1 and one per command, scanflow-reconstruct.1, …) into a
    /// directory: `scanflow man -o ~/.local/share/man/man1`.
    Man(ManArgs),
}

/// `scanflow completions`.
#[derive(Args, Debug)]
pub struct CompletionsArgs {
    /// The shell.
    #[arg(value_enum)]
    pub shell: clap_complete::Shell,
}

/// `scanflow man`.
#[derive(Args, Debug)]
pub struct ManArgs {
    /// Directory for the pages (made if missing; its parent must exist).
    #[arg(short, long)]
    pub output: PathBuf,
}

/// `scanflow hexmesh`.
#[derive(Args, Debug)]
pub struct HexmeshArgs {
    /// Tetrahedral mesh (MEDIT .mesh, gmsh .msh 4.1 or 2.2, VTK legacy .vtk), or a closed
    /// triangle surface (PLY, OBJ, STL) whose inside is tetrahedralised first (isosurface
    /// stuffing of its generalised winding number).
    pub input: PathBuf,
    /// Output hexahedral mesh: .vtk, .mesh or .msh.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Frame field: polycube (the rotations of a deformation that turns the boundary onto
    /// axis planes: no interior singularity), smooth (boundary-aligned smooth frames, with
    /// singular curves), constant (the coordinate axes), or meta:FILE (the frames of a coarse
    /// hexahedral meta-mesh in FILE).
    #[arg(long, default_value = "polycube")]
    pub frames: String,
    /// Target hexahedron edge, in input units (default: a twentieth of the bounding box's
    /// diagonal, then up to three edges each 0.85 of the last where its rounding folds
    /// hexahedra or flips tetrahedra; a given edge is tried alone).
    #[arg(long, allow_negative_numbers = true)]
    pub scale: Option<f64>,
    /// Edge of the tetrahedra stuffed into a surface input (PLY, OBJ, STL), in input units
    /// (default: half the hexahedron edge).
    #[arg(long, allow_negative_numbers = true)]
    pub tet_size: Option<f64>,
    /// Add a layer of hexahedra along the boundary before relaxing (the default with
    /// --frames polycube, whose corners would otherwise be flat hexahedra).
    #[arg(long, conflicts_with = "no_pillow")]
    pub pillow: bool,
    /// No boundary layer, even with --frames polycube.
    #[arg(long)]
    pub no_pillow: bool,
    /// Skip the relaxation after extraction.
    #[arg(long)]
    pub no_relax: bool,
    /// Write the mesh even when some hexahedra are inverted (still exit 1).
    #[arg(long)]
    pub keep_inverted: bool,
    /// Write the run's figures (JSON) here.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Threads, memory, progress.
    #[command(flatten)]
    pub common: Common,
}

/// `scanflow hexcheck`.
#[derive(Args, Debug)]
pub struct HexcheckArgs {
    /// Hexahedral mesh: .vtk, .mesh or .msh.
    pub input: PathBuf,
    /// Print JSON instead of the table.
    #[arg(long)]
    pub json: bool,
}

/// `scanflow synth`.
#[derive(Args, Debug)]
pub struct SynthArgs {
    /// The shape (ASCII case ignored).
    #[arg(value_enum, ignore_case = true)]
    pub shape: ShapeChoice,
    /// Number of points.
    #[arg(long)]
    pub points: u64,
    /// Gaussian noise, relative to the bounding-box diagonal.
    #[arg(long, default_value_t = 0.0)]
    pub noise: f64,
    /// Random seed.
    #[arg(long, default_value_t = DEFAULT_SEED)]
    pub seed: u64,
    /// Relief amplitude of `bumpy`, relative to the radius: r(u) = 1 + A sin(K u_x)
    /// sin(K u_y) sin(K u_z) (default 0.05).
    #[arg(long)]
    pub amplitude: Option<f64>,
    /// Relief frequency K of `bumpy`, per unit of the unit sphere's coordinates: a wavelength
    /// of 2π/K (default 8).
    #[arg(long)]
    pub frequency: Option<f64>,
    /// Output PLY.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Threads, memory, progress.
    #[command(flatten)]
    pub common: Common,
}

/// `scanflow ingest`.
#[derive(Args, Debug)]
pub struct IngestArgs {
    /// Point files (PLY, LAS/LAZ, E57, XYZ/PTS).
    pub inputs: Vec<PathBuf>,
    /// Output store directory (must not exist).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Scanalyze .conf listing scans and their transforms.
    #[arg(long)]
    pub conf: Option<PathBuf>,
    /// Split cells until they hold at most this many points.
    #[arg(long, default_value_t = IngestParams::default().max_cell_points)]
    pub max_cell_points: u64,
    /// Drop points with NaN/infinite coordinates or NaN/infinite/zero normals (counted) instead
    /// of failing.
    #[arg(long)]
    pub skip_invalid: bool,
    /// zstd level of cell files (-7 fastest .. 19 smallest).
    #[arg(long, default_value_t = IngestParams::default().zstd_level, allow_negative_numbers = true)]
    pub zstd_level: i32,
    /// Do one slice of the ingest, as one task of a cluster array job sharing --work-dir with
    /// the others: I/N (shard I of N, from 0), auto (SLURM's SLURM_ARRAY_TASK_ID and _COUNT)
    /// or auto/N (the index from SLURM, JOB_COMPLETION_INDEX under Kubernetes or
    /// AWS_BATCH_JOB_ARRAY_INDEX). Whichever task finds the last slice done writes the store.
    /// Give every task the same inputs and options, --mem included.
    #[arg(long, value_name = "I/N|auto|auto/N")]
    pub shard: Option<String>,
    /// Work directory the tasks of a split ingest (--shard) share, on a file system they all
    /// see (default: OUTPUT.work); removed once the store is written.
    #[arg(long)]
    pub work_dir: Option<PathBuf>,
    /// Normal options.
    #[command(flatten)]
    pub normal: NormalOpts,
    /// Threads, memory, progress.
    #[command(flatten)]
    pub common: Common,
}

/// `scanflow reconstruct`.
#[derive(Args, Debug)]
pub struct ReconstructArgs {
    /// Point files, or one store directory made by `ingest`.
    pub inputs: Vec<PathBuf>,
    /// Output mesh, in the format of its extension: .ply (binary; --ascii for text), .obj or
    /// .stl (binary).
    #[arg(short, long)]
    pub output: PathBuf,
    /// How the mesh is written.
    #[command(flatten)]
    pub mesh: MeshOutOpts,
    /// Give each vertex its sampling density (input points per square unit near it), written
    /// as the PLY's `quality` property (MeshLab's vertex quality; a scalar field in
    /// CloudCompare), to trim by after the fact as with PoissonRecon's --density.
    #[arg(long)]
    pub density: bool,
    /// Weigh each sample's normal by its confidence, as PoissonRecon's --confidence: the PLY's
    /// `confidence` property clamped to [0, 1], or, where there is none, the length of the
    /// normals the inputs carry. Less trusted samples pull the surface less where better ones
    /// overlap them. Without it every normal counts as unit length.
    #[arg(long)]
    pub confidence: bool,
    /// Drop the triangles whose corners' mean sampling density (input points per square
    /// unit, as --density writes it) is below D: trimming by a threshold.
    #[arg(long, value_name = "D", allow_negative_numbers = true)]
    pub trim_density: Option<f64>,
    /// Scanalyze .conf listing scans and their transforms.
    #[arg(long)]
    pub conf: Option<PathBuf>,
    /// Octree depth: 2^depth cells per edge of the bounding cube (as PoissonRecon), 5 to 13.
    #[arg(long, default_value_t = DEFAULT_DEPTH)]
    pub depth: u32,
    /// Tile edge in voxels: a power of two from 8 to 4096 (default 64; raised to one leaf's
    /// block and lowered to the whole grid where needed). Same output for any tile size.
    #[arg(long)]
    pub tile: Option<u64>,
    /// The deepest the dense global coarse solve may be, 4 to depth − 2 (default: as deep
    /// as --mem allows, at most 8, i.e. 256 cells per edge). Levels of leaves fill the
    /// octaves between it and --depth, two at a time: a shallower coarse solve adds levels,
    /// less memory and a different surface (within the method's accuracy).
    #[arg(long, value_name = "D")]
    pub coarse_depth: Option<u32>,
    /// Work directory for the ingested store, the leaf and tile checkpoints and the run
    /// description (default: OUTPUT.work).
    #[arg(long)]
    pub work_dir: Option<PathBuf>,
    /// Continue a killed run from the leaves and tiles checkpointed in its work directory.
    #[arg(long)]
    pub resume: bool,
    /// Keep the work directory after success.
    #[arg(long)]
    pub keep_work: bool,
    /// Refine a leaf only where its samples are farther than this (relative to the
    /// bounding-box diagonal) from the coarse solution's surface.
    #[arg(long, default_value_t = scanflow::recon::DEFAULT_ERROR)]
    pub error: f64,
    /// Refine only leaves holding at least this many points.
    #[arg(long, default_value_t = scanflow::recon::DEFAULT_MIN_POINTS)]
    pub min_points: u64,
    /// Refine a leaf only where its points average at least S per fine voxel of the surface
    /// crossing it (S·E² points in a leaf of E voxels a side), as PoissonRecon's
    /// --samplesPerNode (also accepted; it suggests 1 to 5 for clean data, 15 to 20 for noisy):
    /// sparse parts keep the coarse solve's smoother surface.
    #[arg(
        long,
        alias = "samplesPerNode",
        value_name = "S",
        allow_negative_numbers = true
    )]
    pub samples_per_node: Option<f64>,
    /// Leave the surface open where no input point supports it.
    #[arg(long)]
    pub trim: bool,
    /// Width in voxels of the Gaussian that smooths the normal field before the solve
    /// (Kazhdan 2005), in (0, 8]: larger is smoother and more robust to noise, smaller
    /// follows the points more closely. `measured` (the default) takes it from the samples'
    /// spread measured within fine voxels: 0.35 for precise samples (fine relief), growing
    /// with the spread to 1 for noise of a fifth of a voxel and more; and on every grid at
    /// least 0.4 of the samples' spacing in its voxels (up to 4), where a depth finer than
    /// the sampling would leave them apart.
    #[arg(long, default_value = "measured")]
    pub smooth: String,
    /// Screening weight α of the screened Poisson solve (Kazhdan & Hoppe 2013): how
    /// strongly the surface is pulled through the samples against the smoothed normals, in
    /// [0, 64]; 0 solves the unscreened equation; a number is used as given, as
    /// PoissonRecon's `--pointWeight` (also accepted), with its scaling by depth. `standard`
    /// (the default) takes 4, lowered as 1/σ² where the samples' measured noise across the
    /// surface exceeds 0.85 voxel (there 4 grows blobs out of the noise), lowered further to
    /// the relief's share where noise from 0.35 to 0.75 voxel outweighs the relief (a plain
    /// noisy surface is solved unscreened), and 8 for samples that read precise (a spread
    /// within voxels under 0.05 voxel); `auto` raises it, up to 32, for precise samples
    /// (fine relief, metrology).
    #[arg(long, alias = "pointWeight", default_value = "standard")]
    pub point_weight: String,
    /// Keep the vertices where marching cubes put them, instead of moving each onto the
    /// plane (or, where they are curved, the quadratic jet) of its nearest input points (by
    /// what exceeds the fit's standard error).
    #[arg(long)]
    pub no_fit: bool,
    /// Tile fields and marching cubes on the GPU. Same output either way. Off by default:
    /// the GPU path is not yet measured faster end to end.
    #[arg(long, value_enum, default_value_t = GpuChoice::Off)]
    pub gpu: GpuChoice,
    /// The leaves' fine solves (FFTs and conjugate gradients) on the GPU, batched. The
    /// device computes in float32 where the CPU sums in float64, so the mesh differs from
    /// the CPU's by rounding (a small fraction of a voxel); off (the default) keeps the
    /// CPU's bytes.
    #[arg(long, value_enum, default_value_t = GpuChoice::Off)]
    pub gpu_solve: GpuChoice,
    /// Do one slice of the work, as one task of a cluster array job sharing --work-dir with
    /// the others: I/N (shard I of N, from 0), auto (SLURM's SLURM_ARRAY_TASK_ID and
    /// _COUNT) or auto/N (the index from SLURM, JOB_COMPLETION_INDEX under Kubernetes or
    /// AWS_BATCH_JOB_ARRAY_INDEX). Reads a store made by `ingest`; writes no mesh: `merge`
    /// does, once every shard has finished. Give every shard the same options and --mem.
    #[arg(long, value_name = "I/N|auto|auto/N", conflicts_with = "hex")]
    pub shard: Option<String>,
    /// Then mesh the inside of the reconstructed surface with hexahedra (as `hexmesh OUTPUT
    /// -o HEX` with polycube frames) and write them here: .vtk, .mesh or .msh. Needs a
    /// closed surface (no --trim).
    #[arg(long, conflicts_with = "trim")]
    pub hex: Option<PathBuf>,
    /// Hexahedron edge for --hex, in input units (default: a twentieth of the surface's
    /// bounding-box diagonal, then finer edges where it folds, as hexmesh's --scale).
    #[arg(long, requires = "hex", allow_negative_numbers = true)]
    pub hex_scale: Option<f64>,
    /// Normal options.
    #[command(flatten)]
    pub normal: NormalOpts,
    /// Threads, memory, progress.
    #[command(flatten)]
    pub common: Common,
}

/// `scanflow merge`.
#[derive(Args, Debug)]
pub struct MergeArgs {
    /// The work directory the shards shared (their --work-dir).
    pub work_dir: PathBuf,
    /// Output mesh, in the format of its extension: .ply (binary; --ascii for text), .obj or
    /// .stl (binary).
    #[arg(short, long)]
    pub output: PathBuf,
    /// How the mesh is written.
    #[command(flatten)]
    pub mesh: MeshOutOpts,
    /// Keep the work directory after success (default: removed, as a run in one process
    /// removes its own).
    #[arg(long)]
    pub keep_work: bool,
    /// Threads, memory, progress.
    #[command(flatten)]
    pub common: Common,
}

/// `scanflow check`.
#[derive(Args, Debug)]
pub struct CheckArgs {
    /// The mesh (a PLY with faces, OBJ or STL), or a point file (a PLY without faces,
    /// LAS/LAZ, XYZ/PTS): then every point's distance to the truth or reference is measured.
    pub input: PathBuf,
    /// Exact surface written by `synth` (.truth.json).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Reference mesh or point file.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// Sample points for each distance direction (a mesh; a point file is measured whole).
    #[arg(long, default_value_t = DEFAULT_CHECK_SAMPLES)]
    pub samples: usize,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// `scanflow info`.
#[derive(Args, Debug)]
pub struct InfoArgs {
    /// A point file or a store directory.
    pub path: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Store: read every cell, checking its record count and CRC-32 (without it, only that
    /// each cell file is there with its size). A point file is always read whole.
    #[arg(long)]
    pub verify: bool,
    /// Threads, memory, progress.
    #[command(flatten)]
    pub common: Common,
}

/// `scanflow demo`.
#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Output directory (its earlier demo files are replaced).
    #[arg(short, long, default_value = "scanflow-demo")]
    pub output: PathBuf,
    /// Points to synthesise.
    #[arg(long, default_value_t = 1_000_000)]
    pub points: u64,
    /// Threads, memory, progress.
    #[command(flatten)]
    pub common: Common,
}

/// How parsing ended without a [`Cli`].
pub enum ParseError {
    /// A bad choice value (`--gpu`, `--normals`, `--progress`, the synth shape): reported as
    /// `scanflow: error: ...` in the library's words, with the usage exit status 2.
    Choice(String),
    /// Any other clap outcome (usage error: status 2; `--help`, `--version`: status 0).
    Clap(clap::Error),
}

impl Cli {
    /// Parse `args` (the program name first). From here on the library's messages name
    /// settings by their flags ([`flags::install`](crate::cli::flags::install)).
    pub fn parse_from_args(
        args: impl IntoIterator<Item = impl Into<OsString> + Clone>,
    ) -> Result<Cli, ParseError> {
        crate::cli::flags::install();
        Cli::try_parse_from(args).map_err(|e| match choice_message(&e) {
            Some(msg) => ParseError::Choice(msg),
            None => ParseError::Clap(e),
        })
    }
}

/// The message of a rejected choice value, worded by the library's own parser of that choice
/// (the `--progress` one is the command line's); `None` for any other clap error.
fn choice_message(e: &clap::Error) -> Option<String> {
    if e.kind() != ErrorKind::InvalidValue {
        return None;
    }
    let (Some(ContextValue::String(arg)), Some(ContextValue::String(value))) = (
        e.get(ContextKind::InvalidArg),
        e.get(ContextKind::InvalidValue),
    ) else {
        return None;
    };
    let err = |r: Result<(), scanflow::Error>| r.err().map(|e| e.to_string());
    match arg.split_whitespace().next()? {
        "--gpu" => err(value.parse::<GpuMode>().map(drop)),
        "--gpu-solve" => Some(format!(
            "--gpu-solve \"{value}\": expected one of auto, on, off"
        )),
        "--normals" => err(value.parse::<NormalsMode>().map(drop)),
        "<SHAPE>" => err(value.parse::<Shape>().map(drop)),
        "--progress" => Some(format!(
            "--progress \"{value}\": expected auto, bars, json or none"
        )),
        _ => None,
    }
}

#[cfg(test)]
mod tests;
