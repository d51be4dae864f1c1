//! One error type for the library, with the offending file and an absolute location.
//!
//! Every message a user can cause names the file, what is wrong and where:
//! `scan.ply: element 1203877 (byte 48213004): x is NaN`.
//!
//! A message that points its reader at a setting of the run (raise the memory budget, give
//! the work directory of another run) names it by a [`Setting`], never by a front end's
//! spelling of it. A library caller reads the parameter's name (`` `mem` ``); a front end
//! installs its own names once ([`Setting::name_by`]): the command line shows its flags
//! (`--mem`), from one exhaustive map, so a setting without a flag does not compile.

use std::fmt;
use std::path::{Path, PathBuf};

/// Where in a file something went wrong, counted from the start of the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Location {
    /// Nowhere in particular (the whole file).
    File,
    /// A byte offset.
    Byte(u64),
    /// A 1-based line number.
    Line(u64),
    /// A 0-based element (point) index and the byte it starts at.
    Element {
        /// 0-based index of the element among the points of the file.
        index: u64,
        /// Byte offset where the element starts.
        byte: u64,
    },
    /// A 0-based element index and its 1-based line (text formats).
    ElementLine {
        /// 0-based index of the element among the points of the file.
        index: u64,
        /// 1-based line number.
        line: u64,
    },
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Location::File => write!(f, "file"),
            Location::Byte(b) => write!(f, "byte {b}"),
            Location::Line(l) => write!(f, "line {l}"),
            Location::Element { index, byte } => write!(f, "element {index} (byte {byte})"),
            Location::ElementLine { index, line } => write!(f, "element {index} (line {line})"),
        }
    }
}

macro_rules! settings {
    ($($(#[$doc:meta])* $variant:ident => $name:literal,)*) => {
        /// A setting of a run that a message may point its reader at.
        ///
        /// Its [`Display`](fmt::Display) is the parameter's name in backquotes
        /// (`` `work_dir` ``), what a library caller reads, or the front end's name for it
        /// once one is installed with [`Setting::name_by`] (the command line's flag).
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum Setting {
            $($(#[$doc])* $variant,)*
        }

        impl Setting {
            /// Every setting, in declaration order.
            pub const ALL: &'static [Setting] = &[$(Setting::$variant),*];

            /// The parameter's name, without the backquotes: the same for every front end
            /// (run identities are keyed by it).
            pub fn name(self) -> &'static str {
                match self {
                    $(Setting::$variant => $name,)*
                }
            }

            /// The setting whose [`name`](Setting::name) is `name`.
            pub fn from_name(name: &str) -> Option<Setting> {
                match name {
                    $($name => Some(Setting::$variant),)*
                    _ => None,
                }
            }
        }
    };
}

settings! {
    /// The output file.
    Output => "output",
    /// The memory budget.
    Mem => "mem",
    /// The work directory of a run.
    WorkDir => "work_dir",
    /// Continuing a run from its work directory.
    Resume => "resume",
    /// Which part of a split run this process does.
    Shard => "shard",
    /// Dropping points with non-finite coordinates instead of failing.
    SkipInvalid => "skip_invalid",
    /// Where normals come from (the inputs', estimated, or either).
    Normals => "normals",
    /// Neighbours of a normal's plane fit.
    Neighbours => "neighbours",
    /// Normals fitted robustly to outliers.
    RobustNormals => "robust_normals",
    /// A fixed neighbour count instead of the adaptive one.
    FixedNeighbours => "fixed_neighbours",
    /// The scanner position normals are oriented toward.
    Viewpoint => "viewpoint",
    /// The most points a store cell holds.
    MaxCellPoints => "max_cell_points",
    /// The store's zstd compression level.
    ZstdLevel => "zstd_level",
    /// The octree depth of a reconstruction.
    Depth => "depth",
    /// The smoothing width of the splatted samples.
    Smooth => "smooth",
    /// The screening weight of the samples.
    PointWeight => "point_weight",
    /// The error below which leaves are not refined.
    Error => "error",
    /// The fewest samples a leaf is refined for.
    MinPoints => "min_points",
    /// Dropping the surface away from the samples.
    Trim => "trim",
    /// Leaving out the vertex fit to the samples.
    NoFit => "no_fit",
    /// Extracting the mesh on a GPU.
    Gpu => "gpu",
    /// Solving the leaves on a GPU.
    GpuSolve => "gpu_solve",
    /// Each vertex's sampling density in the output.
    Density => "density",
    /// Weighing samples by their confidence.
    Confidence => "confidence",
    /// The samples a node averages (PoissonRecon's).
    SamplesPerNode => "samples_per_node",
    /// Dropping triangles under a sampling density.
    TrimDensity => "trim_density",
    /// Dropping small connected pieces of the mesh.
    TrimIslands => "trim_islands",
    /// The extraction tile's size.
    Tile => "tile",
    /// ASCII instead of binary output.
    Ascii => "ascii",
    /// Vertex normals in the output.
    OutNormals => "out_normals",
    /// Amplifying a band of the spectrum.
    Enhance => "enhance",
    /// Attenuating a band of the spectrum.
    Bandstop => "bandstop",
    /// The fit's tolerance.
    Tolerance => "tolerance",
    /// The finest level of a hierarchical fit.
    MaxLevel => "max_level",
    /// Fitting the points in patches.
    Patches => "patches",
    /// The most points a patch holds.
    PatchPoints => "patch_points",
    /// Fitting the points in tiles.
    Tiles => "tiles",
    /// A point count.
    Points => "points",
    /// The synthetic shape's noise.
    Noise => "noise",
    /// The synthetic relief's amplitude.
    Amplitude => "amplitude",
    /// The synthetic relief's frequency.
    Frequency => "frequency",
    /// The tetrahedra's edge length.
    TetSize => "tet_size",
    /// Where a hex mesh's frames come from.
    Frames => "frames",
    /// The hexahedra's size.
    Scale => "scale",
    /// Writing inverted hexahedra anyway.
    KeepInverted => "keep_inverted",
}

/// The front end's names for the settings, once installed.
static FRONT_END_NAMES: std::sync::OnceLock<fn(Setting) -> &'static str> =
    std::sync::OnceLock::new();

impl Setting {
    /// Name every setting by `names` in every message from now on: a front end's spelling
    /// (the command line installs its flags before it parses). Only the first call counts, as
    /// with a logger.
    pub fn name_by(names: fn(Setting) -> &'static str) {
        let _ = FRONT_END_NAMES.set(names);
    }
}

impl fmt::Display for Setting {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match FRONT_END_NAMES.get() {
            Some(names) => f.write_str(names(*self)),
            None => write!(f, "`{}`", self.name()),
        }
    }
}

/// Errors of the scanflow library.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// An operating-system error on a file.
    #[error("{}: {err}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error (in the message, so not chained again).
        err: std::io::Error,
    },
    /// Malformed content at a known place in a file.
    #[error("{}: {location}: {msg}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// Where.
        location: Location,
        /// What was expected and what was found.
        msg: String,
    },
    /// A whole-file problem (unsupported format, nothing to read, inconsistent options).
    #[error("{}: {msg}", path.display())]
    Input {
        /// The file or directory.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// A bad option value.
    #[error("{0}")]
    Usage(String),
    /// A worker thread died; a bug, reported instead of a panic.
    #[error("internal error: {0}")]
    Internal(String),
}

/// Result alias for the library.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An I/O error on `path`.
    pub fn io(path: impl AsRef<Path>, source: std::io::Error) -> Error {
        Error::Io {
            path: path.as_ref().to_path_buf(),
            err: source,
        }
    }

    /// A format error at `location` in `path`.
    pub fn format(path: impl AsRef<Path>, location: Location, msg: impl Into<String>) -> Error {
        Error::Format {
            path: path.as_ref().to_path_buf(),
            location,
            msg: msg.into(),
        }
    }

    /// A whole-file error on `path`.
    pub fn input(path: impl AsRef<Path>, msg: impl Into<String>) -> Error {
        Error::Input {
            path: path.as_ref().to_path_buf(),
            msg: msg.into(),
        }
    }
}

/// Attach a path to `std::io::Result`s.
pub trait IoContext<T> {
    /// Map the error to [`Error::Io`] naming `path`.
    fn with_path(self, path: impl AsRef<Path>) -> Result<T>;
}

impl<T> IoContext<T> for std::io::Result<T> {
    fn with_path(self, path: impl AsRef<Path>) -> Result<T> {
        self.map_err(|e| Error::io(path, e))
    }
}
