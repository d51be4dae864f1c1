//! The data that flows between stages.
//!
//! World coordinates are `f64` in the input's units. Normals are `f32` unit vectors in the
//! same frame. Colours are 16-bit per channel (8-bit inputs are scaled by 257, so 255 maps
//! to 65535 exactly).
//!
//! By concern: [`geom`] (boxes, the root cube, rigid transforms), [`keys`] (octree cell keys,
//! Morton codes, grid edge keys), [`points`] (point batches, attributes, viewpoints), [`mesh`]
//! (the global marching-cubes grid and a tile's mesh), [`spline`] (a tensor-product B-spline
//! surface) and [`field`] (a tile's fixed-point
//! field, as recon hands it to extract). Everything is re-exported here, so `crate::types::X`
//! names every type.

pub mod field;
pub mod geom;
pub mod keys;
pub mod mesh;
pub mod points;
pub mod spline;

pub use field::{Axis, Blend, Detail, FIELD_LIMIT, Leaf, MAX_SHIFT, VALUE_LIMIT, WEIGHT_BITS};
pub use geom::{Aabb, Cube, Rigid, floor, round_index, wrap};
pub use keys::{CellKey, EdgeKey, KeyHasher, KeyMap, MAX_LEVEL, demorton3, morton3};
pub use mesh::{FLOAT32_SPACING, GridGeom, TileMesh};
pub use points::{Attributes, PointBatch, Viewpoint};
pub use spline::TensorSurface;
