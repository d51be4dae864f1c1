//! The global marching-cubes grid and a tile's mesh: what recon hands to extract and extract
//! to the writer. The conventions (inside, winding, seams, vertex order) are stated once, in
//! the `extract` module's docs.

use super::EdgeKey;
use crate::error::{Error, Result};

/// The largest float32 spacing, relative to the cube's edge, at which output vertices are
/// written as float32 (else float64): float32 then keeps the input's resolution, and every
/// written coordinate is within half of this of the value computed. The writer
/// (`io::mesh_write`) picks the format by it; the vertex fit (`surface`) keeps triangles
/// large enough that rounding this fine cannot collapse or flip them.
pub const FLOAT32_SPACING: f64 = 1.0 / (1u64 << 20) as f64;

/// Geometry of the global grid: node `(i, j, k)` sits at `origin + h·(i, j, k)`; `n` cells per
/// axis, so node indices run over `0..=n`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridGeom {
    /// World position of node `(0, 0, 0)`, in input units.
    pub origin: [f64; 3],
    /// Edge length of a cell, in input units.
    pub h: f64,
    /// Cells per axis (at most [`GridGeom::MAX_N`]).
    pub n: u64,
}

impl GridGeom {
    /// The largest `n`: `3·(n + 1)³` edge keys must fit a `u64`.
    pub const MAX_N: u64 = 1 << 20;

    /// A validated grid: `h` finite and positive, `origin` finite, `1 ≤ n ≤ MAX_N`.
    pub fn new(origin: [f64; 3], h: f64, n: u64) -> Result<GridGeom> {
        if !(h.is_finite() && h > 0.0) {
            return Err(Error::Usage(format!(
                "grid cell size is {h}, expected a finite positive number"
            )));
        }
        if origin.iter().any(|v| !v.is_finite()) {
            return Err(Error::Usage(format!(
                "grid origin is {origin:?}, expected finite coordinates"
            )));
        }
        if n == 0 || n > Self::MAX_N {
            return Err(Error::Usage(format!(
                "grid of {n} cells per axis, expected 1 to {}",
                Self::MAX_N
            )));
        }
        Ok(GridGeom { origin, h, n })
    }

    /// World position of node `node`.
    #[inline]
    pub fn node_position(&self, node: [u64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|d| self.origin[d] + self.h * node[d] as f64)
    }

    /// The key of the edge from node `node` along `axis` (see [`EdgeKey`]). `node` must be a
    /// node of the grid (coordinates `≤ n`) and `axis < 3`.
    #[inline]
    pub fn edge_key(&self, node: [u64; 3], axis: u8) -> EdgeKey {
        debug_assert!(node.iter().all(|&c| c <= self.n) && axis < 3);
        let m = self.n + 1;
        EdgeKey(((node[0] * m + node[1]) * m + node[2]) * 3 + axis as u64)
    }

    /// The lower node and axis of key `k`; the inverse of [`GridGeom::edge_key`].
    #[inline]
    pub fn decode_edge(&self, k: EdgeKey) -> ([u64; 3], u8) {
        let m = self.n + 1;
        let axis = (k.0 % 3) as u8;
        let r = k.0 / 3;
        let z = r % m;
        let r = r / m;
        ([r / m, r % m, z], axis)
    }
}

/// One tile's mesh: vertex `i` lies on grid edge `keys[i]` at `positions[i]` (in the frame of
/// its [`GridGeom`], input units: the pipeline's grid starts at zero, the cube's corner, which
/// the writer adds back); triangles index into them, wound as in the conventions of the
/// `extract` module.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TileMesh {
    /// The grid edge of each vertex; no key appears twice.
    pub keys: Vec<EdgeKey>,
    /// Position of each vertex, in the grid's frame.
    pub positions: Vec<[f64; 3]>,
    /// Triangles, as indices into `keys` and `positions`.
    pub triangles: Vec<[u32; 3]>,
    /// Colour of each vertex (empty when the input points have none).
    pub colors: Vec<[u8; 3]>,
    /// Intensity of each vertex (empty when the input points have none).
    pub intensity: Vec<f32>,
    /// Sampling density at each vertex, input points per square unit (empty unless asked
    /// for: `--density`, `--trim-density`).
    pub density: Vec<f32>,
}

impl TileMesh {
    /// Empty the mesh, keeping its buffers.
    pub fn clear(&mut self) {
        self.keys.clear();
        self.positions.clear();
        self.triangles.clear();
        self.colors.clear();
        self.intensity.clear();
        self.density.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn edge_keys_round_trip() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        for n in [1u64, 2, 17, 1000, GridGeom::MAX_N] {
            let g = GridGeom::new([0.0; 3], 1.0, n).unwrap();
            for _ in 0..200 {
                let node = [0; 3].map(|_: u64| rng.random_range(0..=n));
                let axis = rng.random_range(0..3u8);
                assert_eq!(g.decode_edge(g.edge_key(node, axis)), (node, axis));
            }
            let top = g.edge_key([n; 3], 2);
            assert_eq!(top.0, 3 * (n + 1).pow(3) - 1);
        }
        assert!(GridGeom::new([0.0; 3], 0.0, 4).is_err());
        assert!(GridGeom::new([0.0; 3], 1.0, GridGeom::MAX_N + 1).is_err());
        assert!(GridGeom::new([f64::NAN, 0.0, 0.0], 1.0, 4).is_err());
    }
}
