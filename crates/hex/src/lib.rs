//! Hexahedral meshing by CubeCover: Nieser, Reitebuch, Polthier, "CubeCover — parameterization
//! of 3D volumes" (SGP 2011). Pure kernels on slices; the pipeline reads the meshes and writes
//! the hexahedra.
//!
//! ```text
//! tet mesh (read, or isosurface stuffing) ─▶ frame field (§3.2) ─▶ matchings, singular edges (§2.2)
//!   ─▶ parameterisation with greedy rounding (§3.1) ─▶ hex extraction ─▶ relaxation ─▶ quality
//! ```
//!
//! Where a polycube or constant field's aligned map cannot be made injective (it flips
//! tetrahedra before any rounding), the pipeline meshes the grid of the axes unaligned
//! instead (`pipeline::hexmesh`, "Grid"): the same extraction, pillowing and relaxation.
//!
//! * [`mesh`]: the tetrahedral and hexahedral meshes and their orientation conventions.
//! * [`rotation`]: the 24 cube rotations, matchings between frames, edge holonomy (§2.1–2.2).
//! * [`topology`]: the checks of an input tetrahedral mesh (named elements) and edge stars.
//! * [`frames`]: constant and meta-mesh frames, matchings, singular edges and invalid
//!   configurations (§2.2, §3.2).
//! * [`smooth_frames`]: boundary-aligned smooth frames (L4 spherical harmonics).
//! * [`polycube`]: frames without interior singularities from a polycube deformation.
//! * [`param`]: the integer-grid parameterisation with greedy rounding (§3.1).
//! * [`quality`]: Verdict's element measures.
//! * [`stuffing`], [`winding`]: tetrahedra of a closed surface's inside (isosurface stuffing
//!   with the generalised winding number).
//! * [`extract`]: hexahedra from an integer-grid map by walks from cube centres to corners.
//! * [`pillow`]: a layer of hexahedra along the boundary (for polycube corners, and for the
//!   staircase of a grid, made pillowable first).
//! * [`relax`]: relaxation of the extracted mesh towards ideal cubes, boundary on the surface.
//! * [`untangle`]: inverted tetrahedra of a rounded map turned back (foldover-free maps).
#![deny(missing_docs)]
#![deny(unsafe_op_in_unsafe_fn)]
// Fixed-size 3D loops index several arrays at once; iterators would obscure the math.
#![allow(clippy::needless_range_loop)]

use scanflow_core::{error, fs, geom, sparse, types};
use scanflow_formats as io;

pub mod extract;
pub mod frames;
pub mod mesh;
pub mod param;
pub mod pillow;
pub mod polycube;
pub mod quality;
pub mod relax;
pub mod rotation;
pub mod smooth_frames;
pub mod stuffing;
pub mod topology;
pub mod untangle;
pub mod volume;
pub mod winding;

pub use mesh::{Frame, HexMesh, TetMesh};
