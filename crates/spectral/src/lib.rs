//! Spectral processing of point-sampled geometry (Pauly & Gross, "Spectral processing of
//! point-sampled geometry", SIGGRAPH 2001), out of core: filters, restoration, resampling and
//! analysis of scans by the Fourier spectra of local height fields.
//!
//! The paper's pipeline, and where each step lives:
//!
//! 1. **Patch layout (§3)**, [`layout`]: the points are split into clusters of at most 100 by
//!    a binary space partition, which are then merged, best pair first, by a priority that
//!    favours small, flat and compact results, under the *normal-cone condition*: the smallest
//!    spherical cap holding a patch's normals ([`cone`]) has an aperture of at most π/2, so
//!    that the patch is a height field over the plane normal to the cap's axis. Out of core,
//!    the layout runs on one store cell's points at a time; a patch belongs to the cell its
//!    members are in, and every point is a member of exactly one patch.
//! 2. **Height fields (§3)**, [`patch`]: each patch's base plane is normal to its cone's axis;
//!    its parameter box is the smallest enclosing rectangle of its members' projections
//!    ([`crate::geom::rect`]), grown by 10% for the overlap, where points of neighbouring patches (and of
//!    neighbouring cells: the *halo*) join when their normals lie within the cone widened by
//!    π/8.
//! 3. **Scattered-data approximation (§3)**, [`sda`]: the heights are approximated on a
//!    regular grid of `N × M` nodes with `N = s₁K`, `M = s₂K`, `K = √(κn/(s₁s₂))` for `n`
//!    points over a box of `s₁ × s₂` (κ = 1: about one node per point) by push-pull on linear
//!    B-spline bases: splat, pull (coarsen), push (fill the gaps from coarser levels). The RMS
//!    error at the points is reported.
//! 4. **Spectra (§4)**, [`fft`]: the 2D discrete Fourier transform of each grid (real to
//!    complex), with plans cached per size per worker. By Parseval's theorem the RMS change a
//!    filter makes to the heights equals `√(Σ|ΔX|²)/(NM)` over the spectrum's change: every
//!    filtered patch reports it.
//! 5. **Filters (§5)**, [`filter`]: ideal and Gaussian low-pass, band-stop, enhancement
//!    (spectral scaling) and Wiener restoration (Eq. 6), whose noise power comes from the
//!    spectrum's flat tail. Frequencies are relative to each patch grid's Nyquist frequency:
//!    at κ = 1 the grid follows the local point spacing, so `0.5` means detail twice as wide
//!    as the finest the points can carry, wherever the scan is dense or sparse.
//! 6. **Resampling (§6)**, [`cell::resample_cell`]: a patch keeps the band `b` (relative to
//!    its Nyquist frequency) below which no height changes by more than the error bound (the
//!    triangle inequality on the inverse transform: the sum of the dropped coefficients'
//!    magnitudes over `NM`); the sampling theorem then asks for a sample spacing of `step/b`.
//!    Rates are blended across patches as positions are (§7), and new points are drawn from a
//!    progressive Poisson-disk pattern ([`pattern`]).
//! 7. **Reconstruction (§7)**, [`cell`]: each patch's blending function is its members'
//!    coverage of the grid convolved with a Gaussian and taken to zero at the box's edge; a
//!    point's filtered position is the weighted mean of its projections (same `(u, v)`) onto
//!    every patch admitting it; normals likewise, from the height fields' divided
//!    differences, except where the patches disagree (the weighted mean's length below
//!    [`cell::NORMAL_AGREEMENT`]), where the least-squares plane of the heaviest patch's
//!    nodes gives it; the count is reported.
//!
//! Everything here is a pure function of slices; `pipeline::spectral` reads the store's cells
//! with their halos, runs the waves under the budget, checkpoints the patches
//! ([`checkpoint`]) and writes the points. Every result depends on the store's cells and the
//! options only, never on the thread count.
#![deny(missing_docs)]
#![deny(unsafe_op_in_unsafe_fn)]
// Fixed-size 3D loops index several arrays at once; iterators would obscure the math.
#![allow(clippy::needless_range_loop)]

use scanflow_core::{error, geom};

pub mod buckets;
pub mod cell;
pub mod checkpoint;
pub mod cone;
pub mod fft;
pub mod filter;
pub mod layout;
pub mod patch;
pub mod pattern;
pub mod sda;
