//! Hierarchical B-spline surfaces fitted to scattered points: Greiner & Hormann,
//! "Interpolating and approximating scattered 3D-data with hierarchical tensor product
//! B-splines" (1997). Pure kernels on slices; the pipeline (`pipeline::fit`,
//! `pipeline::fit_tiles`) reads the points and writes the surfaces.
//!
//! ```text
//! points ─▶ graph ─▶ param (§4) ─▶ fit: solve (§7) ─▶ correct parameters ─▶ refine (§5) ─┐
//!                                        ▲  fairness (§6)                                │
//!                                        └───────────────────────────────────────────────┘
//!                                   ─▶ hier::to_tensor: one clamped tensor-product surface ─▶ IGES
//! ```
//!
//! * [`graph`]: the springs (a triangulation's edges, or k nearest neighbours) and the
//!   boundary points (§4).
//! * [`param`]: the spring model `Σ k_ij (|u_i − u_j| − L_ij)²` with `k = 1/|P_i − P_j|^r`,
//!   `L = α|P_i − P_j|`, the boundary held at its projection onto the best-fit plane; uniform,
//!   chord and real springs; the parameter rectangle as the smallest enclosing one (§4).
//! * [`basis`]: the uniform cubic B-spline, its refinement mask and knot insertion (Oslo).
//! * [`hier`]: the hierarchical space, Kraft's selection of B-splines over nested
//!   rectangular regions, local and global refinement, exact export (§5).
//! * [`fit`]: the fitting loop: penalty (`(BᵀB + ω A₀) c = BᵀP`, ω × 0.1 per iteration) or
//!   Lagrange interpolation, simple or data-dependent thin-plate fairness (§6, §7), Hoschek's
//!   parameter correction, refinement where the tolerance is missed.
//! * [`block`]: one block of block Gauss–Seidel, for terrain tiles (§7's block iteration).
//! * [`iges`]: tensor-product B-spline surfaces as IGES 5.3 entity 128
//!   ([`iges::write_iges`]; whole files, small next to the points they were fitted to).
//!
//! Sparse assembly and faer's sparse Cholesky and LU are [`sparse`], in `scanflow-core`
//! (shared with the hex parameterisations).
//! * [`tensor`]: evaluation of a bicubic tensor-product surface with second derivatives, and
//!   the orthogonal projection of a point onto it (the deviation reported).
//!
//! Units: parameters are in input length units (the rectangle of the plane the points are
//! mapped to); coefficients and deviations are in input units. Everything is deterministic:
//! the same slices give the same bits for any thread count (parallel loops write per index or
//! collect in order; sparse entries are summed in a fixed order; faer runs sequentially).
#![deny(missing_docs)]
#![deny(unsafe_op_in_unsafe_fn)]
// Fixed-size 3D loops index several arrays at once; iterators would obscure the math.
#![allow(clippy::needless_range_loop)]

use scanflow_core::{error, exec, fs, geom, sparse, types};

pub mod basis;
pub mod block;
pub mod fit;
mod frame;
pub mod graph;
pub mod hier;
pub mod iges;
pub mod param;
pub mod tensor;
