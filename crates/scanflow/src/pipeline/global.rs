//! The global-solve reference: one FFT solve over the whole cube ([`crate::recon::global`]),
//! extracted as a single tile.

use crate::error::Result;
use crate::extract::cpu::marching_cubes;
use crate::recon::global_field;
use crate::types::{Cube, GridGeom, TileMesh};

/// One global FFT solve over the whole cube at `depth`, extracted as a single tile: the
/// reference the two-level adaptive solve is measured against at depths where `(2^depth)³`
/// nodes fit in memory, screened with weight `point_weight` as `reconstruct` screens. The periodic grid is padded by an eighth of the cube on each side
/// (the coarse solve of `reconstruct` pads at least 4 coarse voxels).
///
/// Errors: those of [`marching_cubes`] (a grid too large for 32-bit edge counts).
pub fn global_solve(
    pos: &[[f64; 3]],
    nrm: &[[f32; 3]],
    cube: &Cube,
    depth: u32,
    sigma_vox: f64,
    point_weight: f64,
) -> Result<TileMesh> {
    let g = global_field(pos, nrm, cube, depth, sigma_vox, point_weight);
    let geom = GridGeom {
        origin: cube.origin,
        h: g.spacing,
        n: 1u64 << depth,
    };
    let mut mesh = TileMesh::default();
    marching_cubes(
        &g.values,
        [g.nodes; 3],
        [0; 3],
        g.iso as f32,
        &geom,
        &mut mesh,
    )?;
    Ok(mesh)
}
