//! scanflow: out-of-core streaming surface reconstruction for huge 3D scans.
//!
//! ```text
//!  input files ──mmap──▶ 1 ingest ──▶ octree store ──▶ normals ──▶ 3 solve ──────▶ 4 tiles ──▶ 5 writer ──▶ OUT.ply
//!  (PLY, LAS/LAZ,         bounds,      cells of zstd      PCA fits,    coarse global   blend by     weld by      streamed,
//!   XYZ, .conf)           count,       records,           MST          solve + leaf    partition    grid edge,   header patched,
//!                         scatter,     manifest           orientation  FFT details,    of unity,    frontier     atomic rename
//!                         split        (written last)     (halo)       checkpointed    marching
//!                                                                                      cubes
//!                          └──────────── 2 execution: budget, worker pool, caches, progress ────────────┘
//! ```
//!
//! This crate is [`pipeline`], the only code that chains the stages: store-or-ingest, work
//! directory, run description, resume, leaf and tile waves, writer. The stages live in
//! crates of their own, which never depend on one another (ARCHITECTURE.md has the graph,
//! checked by a test); this crate re-exports each under its module name, so that a user of
//! the library, the command line and the tests reach every part through one crate:
//!
//! - [`types`], [`error`], [`exec`], [`geom`], [`fs`], [`sparse`]: `scanflow-core`.
//! - [`io`]: `scanflow-formats` (point and surface-mesh readers and writers).
//! - [`store`] (1: ingest passes and the on-disk octree) and [`normals`]: `scanflow-store`.
//! - [`recon`] (3: plan, coarse and leaf FFT solves, checkpoints, partition-of-unity math),
//!   [`surface`] (vertex fit, colour, trimming) and [`extract`] (4–5: marching cubes on the
//!   CPU and GPU, exact tile-field evaluation, weld): `scanflow-recon`.
//! - [`spectral`], [`spline`] (with IGES), [`hex`] (with the volume-mesh formats): one crate
//!   each.
//! - [`synth`] and [`metrics`]: `scanflow-metrics` (synthetic scans with exact ground truth,
//!   distances and mesh checks, for `scanflow check`, the demo, tests and benches).
#![deny(missing_docs)]
#![deny(unsafe_op_in_unsafe_fn)]
// Fixed-size 3D loops index several arrays at once; iterators would obscure the math.
#![allow(clippy::needless_range_loop)]

pub mod pipeline;

pub use scanflow_core::{
    Aabb, Attributes, CellKey, Cube, Error, Location, PointBatch, Result, Rigid, Setting,
};
pub use scanflow_core::{error, exec, fs, geom, sparse, types};
pub use scanflow_formats as io;
pub use scanflow_hex as hex;
pub use scanflow_metrics as metrics;
pub use scanflow_metrics::synth;
pub use scanflow_recon as recon;
pub use scanflow_recon::{extract, surface};
pub use scanflow_spectral as spectral;
pub use scanflow_spline as spline;
pub use scanflow_store as store;
pub use scanflow_store::normals;
