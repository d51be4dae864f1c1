//! The arguments of `fit`: the tolerance, the fairness, the parameterisation and refinement,
//! tiles and patches.

use super::*;

/// `fit --fairness`.
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum FairnessChoice {
    /// Thin-plate energy in parameter space.
    Simple,
    /// Thin-plate energy in the metric of the previous iteration's surface.
    Data,
}

/// `fit --param`.
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParamChoice {
    /// Projection onto the best-fit plane (height fields).
    Project,
    /// Spring model, uniform springs (α = 0, r = 0).
    Uniform,
    /// Spring model, chord-length springs (α = 0, r = 1).
    Chord,
    /// Spring model, real springs with rest lengths (α = 0.5, r = 1).
    Spring,
}

/// `fit --refine`.
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum RefineChoice {
    /// Hierarchical: only around the points that miss the tolerance.
    Local,
    /// Halve the knot spacing everywhere (for comparison).
    Global,
}

/// `scanflow fit`.
#[derive(Args, Debug)]
pub struct FitArgs {
    /// Point files (PLY, LAS/LAZ, E57, XYZ/PTS), or one store directory made by `ingest` (--tiles).
    pub inputs: Vec<PathBuf>,
    /// Output IGES file (.igs or .iges).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Largest deviation of a point from its surface: in input units, or a percentage of the
    /// bounding-box diagonal (`0.1%`).
    #[arg(long, allow_negative_numbers = true)]
    pub tolerance: String,
    /// Interpolate every point (Lagrange multipliers) instead of approximating.
    #[arg(long)]
    pub interpolate: bool,
    /// Fairness energy.
    #[arg(long, value_enum, default_value_t = FairnessChoice::Simple)]
    pub fairness: FairnessChoice,
    /// Starting fairness weight ω (dimensionless; ×0.1 per iteration).
    #[arg(long, default_value_t = 0.1)]
    pub omega: f64,
    /// Finest refinement level.
    #[arg(long, default_value_t = 10)]
    pub max_level: usize,
    /// Parameterisation.
    #[arg(long, value_enum, default_value_t = ParamChoice::Chord)]
    pub param: ParamChoice,
    /// Local (hierarchical) or global refinement.
    #[arg(long, value_enum, default_value_t = RefineChoice::Local)]
    pub refine: RefineChoice,
    /// Terrain: fit tile by tile over the store's cells, parameterised by x and y; the tiles
    /// are pieces of one spline, so neighbours meet with C2 continuity.
    #[arg(long)]
    pub tiles: bool,
    /// Points a tile aims at (--tiles): the tile grid follows the point count, never --mem.
    #[arg(long, default_value_t = scanflow::pipeline::fit_tiles::TILE_POINTS)]
    pub tile_points: u64,
    /// Closed objects: one surface per patch of the spectral patch layout (each patch a
    /// height field over its normals' mean direction), with the gap between neighbouring
    /// patches' surfaces reported.
    #[arg(long, conflicts_with = "tiles")]
    pub patches: bool,
    /// Most points in a patch (--patches), before its overlap with its neighbours.
    #[arg(long, default_value_t = scanflow::pipeline::fit_patches::PATCH_POINTS)]
    pub patch_points: usize,
    /// Full aperture of a patch's normal cone, degrees (--patches): larger gives fewer,
    /// steeper patches.
    #[arg(long, default_value_t = scanflow::pipeline::fit_patches::PATCH_ANGLE)]
    pub patch_angle: f64,
    /// Write a tessellated preview mesh (binary PLY).
    #[arg(long)]
    pub preview: Option<PathBuf>,
    /// Write the report (JSON).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Work directory for the ingested store (--tiles, --patches; default: OUTPUT.work).
    #[arg(long)]
    pub work_dir: Option<PathBuf>,
    /// Keep the work directory after success.
    #[arg(long)]
    pub keep_work: bool,
    /// Normal options (--patches: the layout groups points by their normals).
    #[command(flatten)]
    pub normal: NormalOpts,
    /// Threads, memory, progress.
    #[command(flatten)]
    pub common: Common,
}
