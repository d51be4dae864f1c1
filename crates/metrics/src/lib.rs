//! Distances and checks shared by tests, benches and `scanflow check`, on meshes and on point
//! clouds.
//!
//! # Mesh topology ([`check_mesh`])
//!
//! Counts are over the triangles of a [`Mesh`]; an *edge* is an unordered pair of distinct
//! vertex indices, and a triangle `(a, b, c)` *uses* its edges in the directions
//! `a→b`, `b→c`, `c→a`. With `n` the number of triangles using an edge:
//!
//! * `n = 1`: a boundary edge; `n > 2`: a non-manifold edge;
//! * `n = 2` with both uses in the same direction: an inconsistent edge (the two triangles
//!   have opposite orientations). Worked example: `(0, 1, 2)` uses `2→0` and `(0, 2, 3)` uses
//!   `0→2`, so {0, 2} is consistent; `(0, 1, 2)` with `(0, 3, 2)`, which also uses `2→0`,
//!   makes {0, 2} inconsistent.
//!
//! Triangles that repeat an index are *degenerate* and take no part in edge counting (their
//! "edges" would cancel in pairs and hide holes); nor do triangles with an index out of range
//! (counted apart, never produced by [`crate::io::mesh_read::read_mesh`]). A triangle is also
//! degenerate when its area is zero up to rounding: `|(b - a) × (c - a)| ≤ 1e-12 ℓ²`, `ℓ` its
//! longest edge; such triangles still count in edges. *Components* are the connected
//! components of the graph whose nodes are triangles, two triangles being connected when they
//! share a **vertex** (union-find over the vertices of each triangle), so two cones touching
//! at their apex are one component. A vertex is *non-manifold* when its proper triangles form
//! more than one fan: around vertex `v` each triangle `(v, a, b)` is an edge `a–b` of `v`'s
//! link, and the fans are the link's connected components (two cones touching at their apex:
//! two fans; a closed or open umbrella: one). A mesh is *watertight* when it has no boundary
//! and no non-manifold edge, *edge-manifold* when no edge is used more than twice,
//! *vertex-manifold* when no vertex is non-manifold, and *oriented* when no edge is
//! inconsistent.
//!
//! Edges are counted by sorting one packed `u64` key per directed use (3 per triangle:
//! 24 bytes a triangle, in parallel with rayon), not by hashing; fans from the triangles at
//! each vertex, listed by a counting sort (12 bytes a triangle, 16 a vertex).
//!
//! # Distances ([`mesh_to_truth`], [`mesh_to_reference`])
//!
//! Both directions are measured by sampling: points uniform by area on the mesh (seeded,
//! deterministic whatever the number of threads) and their distance to the other surface, and
//! points on the other surface and their distance to the mesh. Distances to a mesh are exact
//! point-to-triangle distances ([`point_triangle_distance`]), the nearest triangle being found
//! by a [`TriangleIndex`] (kd-tree over centroids, with a bound that makes the search exact).
//!
//! # Files
//!
//! * `mesh_check.rs`: [`check_mesh`], the topology of a mesh;
//! * `nearest.rs`: exact point-to-triangle distances and the nearest-triangle and
//!   nearest-point indexes ([`TriangleIndex`], [`PointIndex`]);
//! * `distance.rs`: sampled two-sided distances ([`mesh_to_truth`], [`mesh_to_reference`]);
//!   the exact surfaces are sampled by [`crate::synth`]'s sampler, with the same seeded
//!   generators and vector helpers;
//! * `points.rs`: `scanflow check` on a point cloud ([`run_check_points`]): every point's
//!   distance to a truth or reference, and the relief kept of the bumpy sphere
//!   ([`relief_scale`]);
//! * `report.rs`: `scanflow check` on a mesh ([`run_check`]) and its printed report.
#![deny(missing_docs)]
#![deny(unsafe_op_in_unsafe_fn)]
// Fixed-size 3D loops index several arrays at once; iterators would obscure the math.
#![allow(clippy::needless_range_loop)]

use scanflow_core::{error, fs, geom, types};
use scanflow_formats as io;

mod distance;
#[cfg(test)]
pub(crate) mod fixtures;
mod mesh_check;
mod nearest;
mod points;
mod report;
pub mod synth;

pub use distance::{
    Distances, Reference, ReferenceParams, TwoSided, mesh_to_reference, mesh_to_truth, quantile,
    sample_truth,
};
pub use mesh_check::{MeshCheck, check_mesh};
pub use nearest::{PointIndex, TriangleIndex, point_triangle_distance};
pub use points::{
    PointDistances, PointTarget, PointsAgainst, PointsReport, is_point_file, point_distances,
    relief_scale, run_check_points,
};
pub use report::{Against, CheckParams, CheckReport, Comparison, run_check, run_check_with};

use crate::io::mesh_read::Mesh;

/// The corners of triangle `t`, or `None` when an index is out of range.
#[inline]
pub(crate) fn corners(m: &Mesh, t: [u32; 3]) -> Option<[[f64; 3]; 3]> {
    Some([
        *m.vertices.get(t[0] as usize)?,
        *m.vertices.get(t[1] as usize)?,
        *m.vertices.get(t[2] as usize)?,
    ])
}

pub(crate) use crate::geom::vec::double_area;
