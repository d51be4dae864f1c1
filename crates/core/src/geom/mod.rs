//! Geometry shared by stages: pure kernels on slices, no files, threads or budget.
//!
//! [`vec`](mod@vec): small helpers on `[f64; 3]` (dot, cross, norm, ...), the one set every crate uses.
//! [`eigen`]: the least eigenvector of a symmetric 3×3 matrix in closed form.
//! [`frame`]: the tangent plane's basis of a normal, the frame of local height fields (a
//! spectral patch, a jet fit, a boundary frame). [`rect`]: the smallest-area rectangle enclosing a set of 2D points, the parameter domain of
//! a spectral patch's height field (Pauly & Gross 2001, §3) and of a fitted spline surface
//! (Greiner & Hormann 1997, §4).

pub mod eigen;
pub mod frame;
pub mod rect;
pub mod vec;

pub use eigen::least_eigenvector;
pub use frame::plane_basis;
pub use rect::{Rect, RectWorkspace, min_area_rect, min_area_rect_with};
pub use vec::{cross, dot};
