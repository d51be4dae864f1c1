//! The surface stage: what the input points say about each vertex of the extracted mesh
//! (ARCHITECTURE.md step 4, after marching cubes): its position, colour and intensity, and
//! where the surface is trimmed.
//!
//! **Vertex fit** ([`fit`]). The Poisson surface is smooth at the scale of the Gaussian
//! (one voxel); where the input points are more precise than that, the vertex is moved onto
//! them by a one-step moving-least-squares projection (Alexa et al., "Computing and rendering
//! point set surfaces", 2003, §3): take the [`fit::FIT_NEIGHBOURS`] nearest input points
//! `p_i` of vertex `v`, their mean `c` and covariance `M = Σ (p_i − c)(p_i − c)ᵀ`; the plane
//! through `c` with normal `n`, the eigenvector of `M`'s least eigenvalue `λ₀`, is the local
//! least-squares surface, and `v` moves by its offset `d = (v − c)·n` along `n`.
//!
//! **Why the standard-error rule.** On noisy points the plane's offset is itself uncertain:
//! its standard error is about `√λ₀ / k` for `k` neighbours (the residual spread over the
//! neighbour count). Following an offset that noise could explain would print the noise
//! into the mesh, so the step is shrunk to `d · max(0, 1 − (2·se/d)²)`: an offset within
//! twice the standard error hardly moves the vertex (the smooth Poisson surface is kept), a
//! larger one is followed almost fully (the surface follows precise points as a screened
//! solve would, Kazhdan & Hoppe, "Screened Poisson surface reconstruction", 2013). A vertex
//! moves only where its nearest point is within two voxels, and by at most two voxels, so
//! regions the coarse solution closed (holes) are left as solved.
//!
//! **Colour** ([`colour`]): the inverse-distance blend of the nearest
//! [`colour::COLOUR_NEIGHBOURS`] points. **Neighbours** ([`point_grid`]) are exact k-nearest
//! with ties broken by position, so every answer depends only on the point set, not on how
//! the points were gathered. **Trimming** ([`trim`]) drops triangles whose centroid has no
//! input point within the coarse voxels around it.

pub mod colour;
pub mod fit;
pub mod point_grid;
pub mod trim;

pub use fit::{FIT_NEIGHBOURS, NearPoints, VertexFit};
pub use trim::{Support, trim_mesh};
