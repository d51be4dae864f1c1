//! One global FFT solve over the whole cube: the reference the two-level scheme is measured
//! against at depths where `(2^depth)³` nodes fit in memory.

use super::fft_solve::{self, LocalGrid};
use crate::types::Cube;

/// The fine padding of a global solve on each side, in voxels: an eighth of the cube (at least
/// 2), so that the periodic solve never wraps the surface.
fn global_pad(n: usize) -> usize {
    (n / 8).max(2)
}

/// A global solve's field on the cube's `(N+1)³` fine nodes (x fastest) and its iso-value,
/// the mean of the field at the samples.
#[derive(Debug, Clone)]
pub struct GlobalField {
    /// Field values at the cube's fine nodes.
    pub values: Vec<f32>,
    /// Nodes per axis, `N + 1`.
    pub nodes: usize,
    /// Fine spacing.
    pub spacing: f64,
    /// Iso-value.
    pub iso: f64,
}

/// Solve the points `pos` with normals `nrm` on one periodic grid of `2^depth` voxels across
/// `cube`, padded by an eighth of the cube (at least 2 voxels) on each side, screened with
/// weight `point_weight` (0: unscreened).
pub fn global_field(
    pos: &[[f64; 3]],
    nrm: &[[f32; 3]],
    cube: &Cube,
    depth: u32,
    sigma_vox: f64,
    point_weight: f64,
) -> GlobalField {
    let n = 1usize << depth;
    let pad = global_pad(n);
    let h = cube.size / n as f64;
    let grid = LocalGrid {
        n: n + 2 * pad,
        h,
        origin: cube.origin.map(|o| o - pad as f64 * h),
        unit: cube.size,
    };
    let (f, _) =
        fft_solve::Solver::new(&grid, sigma_vox).solve_points(&grid, pos, nrm, point_weight);
    let iso = pos.iter().map(|p| grid.eval(&f, *p)).sum::<f64>() / pos.len().max(1) as f64;
    let m = n + 1;
    let mut values = Vec::with_capacity(m * m * m);
    for z in 0..m {
        for y in 0..m {
            for x in 0..m {
                values.push(f[((z + pad) * grid.n + y + pad) * grid.n + x + pad]);
            }
        }
    }
    GlobalField {
        values,
        nodes: m,
        spacing: h,
        iso,
    }
}
