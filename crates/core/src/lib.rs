//! scanflow-core: what every stage of scanflow shares, and nothing that chains them.
//!
//! - [`types`]: the values that cross stages (boxes, keys, point batches, leaf grids, meshes,
//!   tensor surfaces).
//! - [`error`]: the one error type, each variant naming the file and the place in it.
//! - [`exec`]: the memory budget and its share table, the worker pool, the one cache,
//!   progress, the allocator.
//! - [`geom`]: pure geometry kernels (vector helpers, tangent frames, the least eigenvector,
//!   the minimum-area rectangle).
//! - [`fs`]: the one atomic writer, memory maps, little-endian records.
//! - [`sparse`]: the one sparse Cholesky and LU wrapper (faer), used by the spline fit and
//!   the hex parameterisations.
#![deny(missing_docs)]
#![deny(unsafe_op_in_unsafe_fn)]
// Fixed-size 3D loops index several arrays at once; iterators would obscure the math.
#![allow(clippy::needless_range_loop)]

pub mod error;
pub mod exec;
pub mod fs;
pub mod geom;
pub mod sparse;
pub mod types;

pub use error::{Error, Location, Result, Setting};
pub use types::{Aabb, Attributes, CellKey, Cube, PointBatch, Rigid};
