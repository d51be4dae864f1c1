//! The arguments of the spectral commands (`filter`, `resample`, `spectrum`).

use super::*;

/// Inputs and options every spectral command shares.
#[derive(Args, Debug)]
pub struct SpectralInputs {
    /// Point files, or one store directory made by `ingest`.
    pub inputs: Vec<PathBuf>,
    /// Scanalyze .conf listing scans and their transforms.
    #[arg(long)]
    pub conf: Option<PathBuf>,
    /// Most points in a patch (the layout merges clusters up to this size).
    #[arg(long, default_value_t = scanflow::spectral::layout::LayoutParams::default().patch_max)]
    pub patch_size: usize,
    /// Work directory for the ingested store and the patch checkpoints (default: OUTPUT.work).
    #[arg(long)]
    pub work_dir: Option<PathBuf>,
    /// Continue a killed run from the patches checkpointed in its work directory.
    #[arg(long)]
    pub resume: bool,
    /// Keep the work directory after success.
    #[arg(long)]
    pub keep_work: bool,
    /// Normal options.
    #[command(flatten)]
    pub normal: NormalOpts,
    /// Threads, memory, progress.
    #[command(flatten)]
    pub common: Common,
}

/// `scanflow filter`. Frequencies are relative to each patch's Nyquist frequency (its grid
/// follows the local point spacing): 1 is the finest detail the points can carry, 0.5 detail
/// twice as wide.
#[derive(Args, Debug)]
pub struct FilterArgs {
    /// Inputs and shared options.
    #[command(flatten)]
    pub input: SpectralInputs,
    /// Output point file (binary PLY).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Low-pass: gauss:F (Gaussian, F its standard deviation) or ideal:F (cut at F).
    #[arg(long, value_name = "KIND:F")]
    pub lowpass: Option<String>,
    /// Scale the band from A to B by G in [0, 1) (0 removes it).
    #[arg(long, value_name = "A,B,G")]
    pub bandstop: Option<String>,
    /// Scale the band from A to B by G > 1 (sharpen detail).
    #[arg(long, value_name = "A,B,G")]
    pub enhance: Option<String>,
    /// Wiener restoration; the noise is estimated from each spectrum's flat tail unless a
    /// signal-to-noise power ratio is given.
    #[arg(long, value_name = "SNR", num_args = 0..=1, default_missing_value = "auto", allow_negative_numbers = true)]
    pub wiener: Option<String>,
    /// Write each point's Parseval error (the RMS change of its patch) as `parseval_error`.
    #[arg(long)]
    pub write_parseval: bool,
}

/// `scanflow resample`.
#[derive(Args, Debug)]
pub struct ResampleArgs {
    /// Inputs and shared options.
    #[command(flatten)]
    pub input: SpectralInputs,
    /// Output point file (binary PLY).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Largest change of the surface, relative to the bounding-box diagonal.
    #[arg(long, default_value_t = DEFAULT_MAX_ERROR)]
    pub max_error: f64,
    /// About this many points: the rates the error bound gives, scaled to reach it.
    #[arg(long)]
    pub points: Option<u64>,
}

/// `resample --max-error`.
pub const DEFAULT_MAX_ERROR: f64 = 1e-4;

/// `scanflow spectrum`.
#[derive(Args, Debug)]
pub struct SpectrumArgs {
    /// Inputs and shared options.
    #[command(flatten)]
    pub input: SpectralInputs,
    /// Output directory (must not exist): layout.ply, spectrum-*.png, summary.json.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Power-spectrum images: the first patch of this many cells spread over the store.
    #[arg(long, default_value_t = 4)]
    pub images: usize,
}
