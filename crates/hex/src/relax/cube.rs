//! Step 1 of the module docs of [`super`]: the ideal cube of a hexahedron, the similarity
//! image of the unit cube closest to its corners (orthogonal Procrustes with scaling,
//! Umeyama 1991), and the misfit of a mesh to its ideal cubes.

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use super::dist2;
use crate::geom::vec::{add, dot, scale, sub};

/// The unit cube's corners in VTK order, centred at the origin.
pub(super) const CUBE: [[f64; 3]; 8] = [
    [-0.5, -0.5, -0.5],
    [0.5, -0.5, -0.5],
    [0.5, 0.5, -0.5],
    [-0.5, 0.5, -0.5],
    [-0.5, -0.5, 0.5],
    [0.5, -0.5, 0.5],
    [0.5, 0.5, 0.5],
    [-0.5, 0.5, 0.5],
];

/// `Σ |P_i|²` over [`CUBE`].
pub(super) const CUBE_NORM2: f64 = 6.0;

/// The corners of the similarity image of the unit cube closest to `x` (module docs, step 1).
pub fn ideal_cube(x: &[[f64; 3]; 8]) -> [[f64; 3]; 8] {
    let mut mean = [0.0; 3];
    for p in x {
        mean = add(mean, *p);
    }
    mean = scale(mean, 1.0 / 8.0);
    let mut h = Matrix3::<f64>::zeros();
    let mut spread = 0.0;
    for (p, c) in x.iter().zip(CUBE.iter()) {
        let a = sub(*p, mean);
        spread += dot(a, a);
        h += Vector3::from(a) * Vector3::from(*c).transpose();
    }
    let svd = h.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return *x;
    };
    let sigma = svd.singular_values;
    let mut d = Matrix3::<f64>::identity();
    let flip = (u * v_t).determinant() < 0.0;
    let smallest = (0..3)
        .min_by(|&a, &b| sigma[a].total_cmp(&sigma[b]))
        .unwrap_or(2);
    if flip {
        d[(smallest, smallest)] = -1.0;
    }
    let r = u * d * v_t;
    let mut s = (0..3).map(|k| sigma[k] * d[(k, k)]).sum::<f64>() / CUBE_NORM2;
    if s.is_nan() || s <= 0.0 {
        s = (spread / CUBE_NORM2).sqrt();
    }
    CUBE.map(|c| {
        let y = r * Vector3::from(c) * s;
        [y[0] + mean[0], y[1] + mean[1], y[2] + mean[2]]
    })
}

pub(super) fn corners(verts: &[[f64; 3]], h: &[u32; 8]) -> [[f64; 3]; 8] {
    h.map(|v| verts[v as usize])
}

/// Root-mean-square distance of the corners to their fitted cubes' (summed in hexahedron
/// order).
pub(super) fn misfit(verts: &[[f64; 3]], hexes: &[[u32; 8]]) -> f64 {
    if hexes.is_empty() {
        return 0.0;
    }
    let per: Vec<f64> = hexes
        .par_iter()
        .map(|h| {
            let x = corners(verts, h);
            let y = ideal_cube(&x);
            (0..8).map(|i| dist2(x[i], y[i])).sum()
        })
        .collect();
    (per.iter().sum::<f64>() / (8 * hexes.len()) as f64).sqrt()
}
