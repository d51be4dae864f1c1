//! The pipeline: the only code that chains stages (ARCHITECTURE.md steps 1 to 5). A stage
//! (`store`, `normals`, `recon`, `surface`, `extract`) never imports a sibling; the pipeline
//! reads the store, hands each stage the slices it works on, and owns the work directory,
//! resume, the waves and the writer.
//!
//! - [`ingest`]: point files to a committed store: the store's passes, then normals
//!   ([`normals`](crate::normals)), then the commit; or an existing store opened.
//! - [`reconstruct()`]: a store to a mesh: plan, coarse pass, leaf pass ([`recon`](crate::recon)),
//!   then the tiles (`tiles`: blend and extract, fit and colour ([`surface`](crate::surface)),
//!   weld and write).
//! - [`shard`]: one task's slice of a run split over a cluster array job, and
//!   [`merge()`]: the split run's tiles welded into the mesh one process writes.
//! - [`global_solve`]: the single-solve reference the tests measure the two-level scheme
//!   against.

mod details;
pub mod fit;
pub mod fit_patches;
pub mod fit_tiles;
mod global;
pub mod hexmesh;
pub mod ingest;
pub mod ingest_split;
pub mod merge;
mod points;
pub mod reconstruct;
pub mod shard;
pub mod spectral;
pub mod spectrum;
mod tiles;
pub mod workdir;

pub use global::global_solve;
pub use merge::{MergeStats, merge};
pub use reconstruct::{ReconParams, ReconStats, reconstruct};
