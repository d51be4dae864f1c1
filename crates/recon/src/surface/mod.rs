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
//! least-squares surface, and `d = (v − c)·n` is `v`'s offset from it.
//!
//! **Curved surfaces: the jet.** On a surface of curvature radius `R` the plane of a
//! neighbourhood of radius `r` sits about `r²/(4R)` off it, so fine relief is flattened (a
//! sphere of radius 1 sampled by 1M points, fitted at depth 9, came out 2.4·10⁻⁵ off on
//! average, a relief of 1% amplitude and 18 voxels' wavelength 4.2·10⁻⁴). Over the plane's
//! frame (tangents `t₁, t₂` from `M`'s other eigenvectors, `x = (p − c)·t₁`,
//! `y = (p − c)·t₂`, `z = (p − c)·n`) the neighbours are also fitted by the osculating jet
//! of order 2, `z = h(x, y) = q₀ + q₁x + q₂y + q₃x² + q₄xy + q₅y²`, by least squares
//! (Cazals & Pouget, "Estimating differential quantities using polynomial fitting of
//! osculating jets", 2003, §3), and the jet replaces the plane when its three curvature terms
//! are significant: an F ratio `((RSS_plane − RSS_jet)/3)/(RSS_jet/(k − 6))` above
//! `fit::JET_F_RATIO` (20; 5.6, the 99th percentile of F(3, 14), also took jets from noise,
//! and the noisy relief's largest error grew by half). The offset is then
//! `d = z(v) − h(x(v), y(v))`, its standard error the jet's at `q₀`, and the edge fit solves
//! the quadratic in the move along the edge, taking the root nearest the vertex. Measured at
//! depth 9, 1M points: sphere 2.4·10⁻⁵ → 4.7·10⁻⁶, the relief 4.2·10⁻⁴ → 1.2·10⁻⁴ (mean
//! two-sided distance to the exact surface), noisy inputs unchanged.
//!
//! **Two fits, and which one a vertex takes** ([`fit`], [`settle()`]). Marching cubes puts each
//! vertex on a grid edge, and each triangle's three corners on three distinct edges of one
//! cell. The *free fit* moves `v` by the offset along `n`, the plain projection. The *edge
//! fit* moves `v` along its edge (direction `e`, a grid axis) to where the edge meets the
//! plane: by `−d / (n·e)` (the plane's offset changes by `n·e` per unit along the edge), never
//! closer to either end of the edge than [`fit::EDGE_MARGIN`] of its length. Edge fits never
//! collapse a triangle: three points inside three distinct edges of a box are never collinear
//! (were they, the middle one's supporting plane would hold the whole segment, so all three
//! would lie on one face, whose boundary a line meets in at most two points unless it runs
//! along a side, which holds only one edge). The same holds after rounding to float32 as
//! written: rounding to nearest is monotone, so a vertex at least two float32 units in the
//! last place inside its edge stays strictly inside the rounded edge ([`fit::edge_margin`]
//! takes the larger margin). An edge nearly parallel to the plane stops the vertex at its
//! end, closer to the plane than it was; a vertex that slid more than a tenth of a voxel is
//! fitted once more, to the plane (or jet) of the points nearest to where it went (the first
//! one, fitted around the start, misses a curved surface there), keeping the offset the
//! first step kept.
//!
//! A vertex then takes its free fit where that is safe, else its edge fit ([`settle()`]): when
//! its edge lies inside a block of leaf-sized cells (so its four cells, and all its
//! triangles, lie in one block, inside one tile whatever the tile size) and every triangle at
//! it, with it free and each other corner at either of its two fits, keeps a sound shape and
//! the orientation of the all-edge-fit triangle, with a doubled area beyond what rounding
//! the written coordinates could undo (each moves by at most half of
//! [`FLOAT32_SPACING`](crate::types::FLOAT32_SPACING) of the cube's edge; a bound that
//! depends only on the cube's size, so translated inputs choose alike). Every
//! triangle is then sound: with a free corner by that corner's check, without one by the
//! edge fit's guarantee. Both fits and the choice depend only on the vertex, its block's
//! triangles and the points, so a vertex on a tile boundary gets the same position from both
//! tiles, for any thread count and tile size.
//!
//! **Why the standard-error rule.** On noisy points the plane's offset is itself uncertain:
//! its standard error is about `√λ₀ / k` for `k` neighbours (the residual spread over the
//! neighbour count). Following an offset that noise could explain would print the noise
//! into the mesh, so the step is shrunk to `d · max(0, 1 − (2·se/d)²)`: an offset within
//! twice the standard error hardly moves the vertex (the smooth Poisson surface is kept), a
//! larger one is followed almost fully (the surface follows precise points as a screened
//! solve would, Kazhdan & Hoppe, "Screened Poisson surface reconstruction", 2013). Where
//! the model itself misfits (a relief curved more tightly than the neighbourhood's radius,
//! which neither the plane nor the jet can follow), the error at the vertex is of the order
//! of the residuals rather than of their mean, so `se` is at least the residuals' spread
//! beyond the samples' measured noise ([`fit`]'s `MISFIT_SHARE`, `NOISE_SPAN`; the noise is
//! [`crate::noise::NoiseStats::fit_noise_voxels`], read from pairs of close samples
//! where they are not precise): there the screened field, already through the samples, is
//! kept (a precise relief of 8 voxels' wavelength: 5.5·10⁻⁴ with half the spread, 4.9·10⁻⁴
//! with all of it), while residuals that noise explains leave the fit as it was. Noisy
//! samples count half the spread (`NOISY_MISFIT_SHARE`): their noise is one figure for the
//! scan, and where merged scans overlap it is larger than that figure with no relief there
//! (the raw bunny scans' two-sided distance to `bun_zipper`: 1.785·10⁻⁴ against 1.817 with
//! all of it). Samples
//! whose noise reaches a third of a voxel ([`fit`]'s `FIT_NOISE_LIMIT_VOXELS`) move no
//! vertex: the solve's Gaussian has averaged as many of them as the fit's 20, and the fit
//! only adds its own error. A vertex moves only where its nearest point is within two
//! voxels and its plane within two voxels, so regions the coarse solution closed (holes)
//! are left as solved.
//!
//! **Colour** ([`colour`]): the inverse-distance blend of the nearest
//! [`colour::COLOUR_NEIGHBOURS`] points. **Neighbours** ([`point_grid`]) are exact k-nearest
//! with ties broken by position, so every answer depends only on the point set, not on how
//! the points were gathered. **Trimming** ([`trim`]) drops triangles whose centroid has no
//! input point within the coarse voxels around it.

pub mod colour;
pub mod fit;
pub mod point_grid;
pub mod settle;
pub mod trim;

pub use fit::{FIT_NEIGHBOURS, NearPoints, VertexFit};
pub use settle::settle;
pub use trim::{Support, trim_by_density, trim_mesh};
