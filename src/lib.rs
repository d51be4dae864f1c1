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
//! The modules follow the pipeline (the numbers are ARCHITECTURE.md's steps):
//!
//! - [`pipeline`]: the only code that chains the stages below: store-or-ingest, work
//!   directory, run description, resume, leaf and tile waves, writer.
//! - Stages, which never import one another (normals reads and rewrites store cells through
//!   [`store`]'s public API): [`store`] (1: ingest passes and the on-disk octree), [`normals`]
//!   (estimation and orientation), [`recon`] (3: plan, coarse and leaf FFT solves,
//!   checkpoints, partition-of-unity math), [`surface`] (vertex fit, colour, trimming),
//!   [`extract`] (4–5: marching cubes on the CPU and GPU, exact tile-field evaluation, weld).
//! - Shared machinery: [`types`] (what crosses stages), [`error`] (the one error type),
//!   [`exec`] (2: memory budget and its share table, worker pool, the one cache, progress),
//!   [`io`] (readers, writers, the one atomic writer).
//! - Utilities for tests, benches and `scanflow check`: [`synth`] (synthetic oriented scans
//!   with exact ground truth) and [`metrics`] (distances and mesh checks).
#![deny(missing_docs)]
#![deny(unsafe_op_in_unsafe_fn)]
// Fixed-size 3D loops index several arrays at once; iterators would obscure the math.
#![allow(clippy::needless_range_loop)]

pub mod error;
pub mod exec;
pub mod extract;
pub mod geom;
pub mod hex;
pub mod io;
pub mod metrics;
pub mod normals;
pub mod pipeline;
pub mod recon;
pub mod spectral;
pub mod spline;
pub mod store;
pub mod surface;
pub mod synth;
pub mod types;

pub use error::{Error, Location, Result};
pub use types::{Aabb, Attributes, CellKey, Cube, PointBatch, Rigid};
