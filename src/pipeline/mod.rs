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
//! - [`global_solve`]: the single-solve reference the tests measure the two-level scheme
//!   against.

mod details;
mod global;
pub mod ingest;
mod points;
pub mod reconstruct;
mod tiles;
mod workdir;

pub use global::global_solve;
pub use reconstruct::{ReconParams, ReconStats, reconstruct};
