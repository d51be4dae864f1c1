//! Hexahedral meshing by CubeCover: Nieser, Reitebuch, Polthier, "CubeCover — parameterization
//! of 3D volumes" (SGP 2011). Pure kernels on slices; the pipeline reads the meshes and writes
//! the hexahedra.
//!
//! ```text
//! tet mesh (read, or isosurface stuffing) ─▶ frame field (§3.2) ─▶ matchings, singular edges (§2.2)
//!   ─▶ parameterisation with greedy rounding (§3.1) ─▶ hex extraction ─▶ relaxation ─▶ quality
//! ```
//!
//! * [`mesh`]: the tetrahedral and hexahedral meshes and their orientation conventions.

pub mod mesh;
pub mod quality;
pub mod smooth_frames;
pub mod stuffing;
pub mod topology;
pub mod winding;

pub use mesh::{Frame, HexMesh, TetMesh};
