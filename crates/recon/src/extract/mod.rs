//! Iso-surface extraction (ARCHITECTURE.md steps 4 and 5): marching cubes per tile, on the
//! CPU ([`cpu`]) or the GPU ([`gpu`]), the tile's field evaluated from its fixed-point blend
//! ([`field`]), and welding the tiles' vertices into one indexed mesh ([`weld`]). The kernels
//! here are pure: a block of values (or a blend) in, a
//! [`TileMesh`](crate::types::TileMesh) out. The tile loop (which tiles, in what order, with
//! which workspace per worker) lives in the pipeline.
//!
//! # Marching cubes
//!
//! The field is sampled at the nodes of one global grid: node `(i, j, k)` sits at
//! `origin + h·(i, j, k)` ([`GridGeom`](crate::types::GridGeom)). Each cell (cube of 8 nodes)
//! is classified by which of its corners are *inside*, with value `< iso`; the field is lower
//! inside the surface, and a value exactly equal to `iso` counts as outside (so is NaN). The
//! 8 bits give the case index, bit `c` for corner `c` ([`tables::CORNER_OFFSETS`]). The
//! surface crosses every grid edge whose two nodes differ in class, at the point found by
//! linear interpolation from the edge's lower node `a` to its upper node `b`:
//! `p = a + t·(b − a)` with `t = (iso − v_a) / (v_b − v_a)`, in `f64` from the global node
//! coordinates (Lorensen & Cline, "Marching cubes: a high resolution 3D surface construction
//! algorithm", SIGGRAPH 1987, §3).
//!
//! Lorensen and Cline's 15 cases are ambiguous on faces with two diagonally opposite inside
//! corners, and their table lets neighbouring cells disagree there, leaving holes. This
//! crate's table ([`tables`]) is generated from a face rule instead: on an ambiguous face the
//! two inside corners are always cut off separately. The rule looks at the 4 corners of a
//! face only, so the two cells sharing the face draw the same segments on it, and the mesh is
//! closed and edge-manifold away from the grid's border; a case still has at most
//! [`tables::MAX_CASE_TRIANGLES`] = 5 triangles.
//!
//! # Conventions (written once, here)
//!
//! - **Corners and edges:** corner `c` has offsets `(c & 1, (c >> 1) & 1, (c >> 2) & 1)`;
//!   edge `e` runs along axis `e / 4` ([`tables::EDGE_CORNERS`] has the table and a worked
//!   example).
//! - **Winding:** triangles are counter-clockwise seen from outside the surface, the side where
//!   values exceed `iso`: the normal `(b − a) × (c − a)` points toward increasing values. For a
//!   signed distance (negative inside) that is the outward normal.
//! - **Vertices are stored once per grid edge.** A vertex is named by the global grid edge it
//!   lies on, an [`EdgeKey`](crate::types::EdgeKey); no cell duplicates a vertex (the idea
//!   Timokhin & Mikhaylyuk, "GPU-based marching cubes with tessellation-generated threads",
//!   2020, build their GPU pass on, together with giving work to active cells only: cells
//!   whose case is neither 0 nor 255).
//! - **Seams:** a tile is a block of nodes; it processes the cells whose 8 corners it holds.
//!   Neighbouring tiles share one face of nodes, so each cell belongs to exactly one tile,
//!   while the edges on the shared face belong to both: both tiles compute the vertex of such
//!   an edge, bit for bit the same (the position depends on the global node and the two values
//!   only), and [`weld::Welder`] gives both the same global index. The surface of the whole
//!   grid is therefore exactly the surface one block over the whole grid would give.
//! - **Order:** within a tile, vertices come in order of first use, scanning cells with x
//!   fastest, then y, then z, and the edges of a cell in the order of
//!   [`tables::case_edges`]; triangles come in cell order. Tiles are welded in a fixed tile
//!   order, so output bytes do not depend on thread timing.

pub mod cpu;
pub mod field;
pub mod gpu;
pub mod tables;
pub mod weld;

pub use cpu::{McStats, McWorkspace, marching_cubes};
pub use field::BlendEval;
pub use gpu::{GpuExtractor, GpuMode, GpuStats};
pub use tables::{CORNER_OFFSETS, EDGE_CORNERS, case_triangles, flat_table};
pub use weld::Welder;
