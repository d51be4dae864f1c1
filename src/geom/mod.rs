//! Plane geometry shared by stages: pure kernels on slices, no files, threads or budget.
//!
//! [`frame`]: the tangent plane's basis of a normal, the frame of local height fields (a
//! spectral patch, a jet fit, a boundary frame). [`rect`]: the smallest-area rectangle enclosing a set of 2D points, the parameter domain of
//! a spectral patch's height field (Pauly & Gross 2001, §3) and of a fitted spline surface
//! (Greiner & Hormann 1997, §4).

pub mod frame;
pub mod rect;

pub use frame::{cross, dot, plane_basis};
pub use rect::{Rect, RectWorkspace, min_area_rect, min_area_rect_with};
