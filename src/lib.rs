//! scanflow: out-of-core streaming surface reconstruction for huge 3D scans.
//!
//! ```text
//!  input files ──mmap──▶ ingest ──▶ on-disk octree store ──▶ per-cell work ──▶ tiles ──▶ writer ──▶ output file
//!  (PLY, LAS, XYZ)       (passes:    (cells bucketed,        (bounded worker   (seams     (streamed,
//!                         bounds,    zstd chunks,            pool, memory      blended    header patched,
//!                         count,     manifest)               budget)           by PU)     atomic rename)
//!                         scatter)
//! ```
//!
//! The modules follow the pipeline: [`io`] (formats), [`store`] (ingest and the on-disk
//! octree, DESIGN.md step 1), [`exec`] (memory budget, worker pool, progress, step 2),
//! [`synth`] (synthetic oriented scans with exact ground truth) and [`metrics`] (distances
//! used by tests, benches and `scanflow check`). Shared data types live in [`types`], the one
//! error type in [`error`].
#![deny(missing_docs)]
#![deny(unsafe_op_in_unsafe_fn)]
// Fixed-size 3D loops index several arrays at once; iterators would obscure the math.
#![allow(clippy::needless_range_loop)]

pub mod error;
pub mod exec;
pub mod extract;
pub mod io;
pub mod metrics;
pub mod normals;
pub mod pipeline;
pub mod recon;
pub mod store;
pub mod surface;
pub mod synth;
pub mod types;

pub use error::{Error, Location, Result};
pub use types::{Aabb, Attributes, CellKey, Cube, PointBatch, Rigid};
