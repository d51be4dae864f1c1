//! Which vertices of a tile take their free fit (moved along the plane's normal) rather than
//! their edge fit (moved along their grid edge), so that no triangle collapses or flips
//! ([module docs](super)).

use super::fit::VertexFit;
use crate::types::{EdgeKey, FLOAT32_SPACING, GridGeom};

/// Least `2·area / ℓ²` (`ℓ` the longest edge) a triangle with a free vertex must keep: far
/// above `scanflow check`'s `1e-12`.
pub const MIN_SHAPE: f64 = 1e-6;

/// How many times the most that rounding the written coordinates can change a triangle's
/// doubled area a triangle with a free vertex must keep. Moving each corner by at most `δ`
/// per coordinate changes `(b − a) × (c − a)` by at most `4√3·δ·ℓ + 12δ²` (`ℓ` the longest
/// edge); twice that is kept, so neither a zero area nor a flip can appear in the file.
const ROUNDING_GUARD: f64 = 2.0;

/// The final position of each vertex of a tile mesh (`triangles` over `keys` and `fits`):
/// the free fit where the vertex may take it, else the edge fit. A vertex may when its edge
/// lies inside a block of `block` grid cells (no off-axis node coordinate a multiple of
/// `block`: its four cells, hence all its triangles, lie in one block, inside one tile
/// whatever the tile size), and every triangle at it, with it free and each other corner at
/// either of its possible positions, keeps [`MIN_SHAPE`] and the orientation it has with all
/// corners at their edge fits. So every triangle is sound: with a free corner by that corner's
/// check, without one by the edge fit's guarantee.
pub fn settle(
    triangles: &[[u32; 3]],
    keys: &[EdgeKey],
    fits: &[VertexFit],
    geom: &GridGeom,
    block: u64,
) -> Vec<[f64; 3]> {
    let n = fits.len();
    let block = block.max(1);
    // The most a written coordinate differs from the computed one: half float32's spacing
    // where the writer uses float32 (a fixed fraction of the cube's edge, so the choice below
    // is the same for translated inputs).
    let delta = 0.5 * FLOAT32_SPACING * geom.h * geom.n as f64;
    let may_free: Vec<bool> = keys
        .iter()
        .zip(fits)
        .map(|(k, f)| {
            let (node, axis) = geom.decode_edge(*k);
            f.free_pos != f.pos && (0..3).all(|d| d == axis as usize || node[d] % block != 0)
        })
        .collect();
    // The triangles at each vertex (counting sort).
    let mut start = vec![0usize; n + 1];
    let proper = |t: &[u32; 3]| t.iter().all(|&v| (v as usize) < n);
    for t in triangles.iter().filter(|t| proper(t)) {
        for &v in t {
            start[v as usize + 1] += 1;
        }
    }
    for v in 0..n {
        start[v + 1] += start[v];
    }
    let mut at = vec![0u32; start[n]];
    let mut fill = start.clone();
    for (ti, t) in triangles.iter().enumerate().filter(|(_, t)| proper(t)) {
        for &v in t {
            at[fill[v as usize]] = ti as u32;
            fill[v as usize] += 1;
        }
    }
    let options = |v: u32| -> [[f64; 3]; 2] {
        let f = &fits[v as usize];
        if may_free[v as usize] {
            [f.pos, f.free_pos]
        } else {
            [f.pos, f.pos]
        }
    };
    (0..n)
        .map(|v| {
            let f = &fits[v];
            let free_ok = may_free[v]
                && at[start[v]..start[v + 1]].iter().all(|&ti| {
                    let t = triangles[ti as usize];
                    let k = t.iter().position(|&x| x as usize == v).unwrap_or(0);
                    let (b, c) = (t[(k + 1) % 3], t[(k + 2) % 3]);
                    let reference = normal([f.pos, fits[b as usize].pos, fits[c as usize].pos]);
                    options(b).iter().all(|pb| {
                        options(c)
                            .iter()
                            .all(|pc| sound([f.free_pos, *pb, *pc], reference, delta))
                    })
                });
            if free_ok { f.free_pos } else { f.pos }
        })
        .collect()
}

/// `(b − a) × (c − a)` for the triangle `t = [a, b, c]`.
fn normal(t: [[f64; 3]; 3]) -> [f64; 3] {
    let u = [0, 1, 2].map(|d| t[1][d] - t[0][d]);
    let w = [0, 1, 2].map(|d| t[2][d] - t[0][d]);
    [
        u[1] * w[2] - u[2] * w[1],
        u[2] * w[0] - u[0] * w[2],
        u[0] * w[1] - u[1] * w[0],
    ]
}

/// Whether triangle `t` keeps [`MIN_SHAPE`] and turns the way `reference` does, with a
/// doubled area beyond what rounding each coordinate by up to `delta` could undo
/// ([`ROUNDING_GUARD`]).
fn sound(t: [[f64; 3]; 3], reference: [f64; 3], delta: f64) -> bool {
    let nrm = normal(t);
    let len2 = |a: usize, b: usize| (0..3).map(|d| (t[a][d] - t[b][d]).powi(2)).sum::<f64>();
    let longest = len2(0, 1).max(len2(1, 2)).max(len2(2, 0));
    let area2 = (0..3).map(|d| nrm[d] * nrm[d]).sum::<f64>().sqrt();
    let turn: f64 = (0..3).map(|d| nrm[d] * reference[d]).sum();
    let rounding = 4.0 * 3f64.sqrt() * delta * longest.sqrt() + 12.0 * delta * delta;
    area2 > MIN_SHAPE * longest && area2 > ROUNDING_GUARD * rounding && turn > 0.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fit(pos: [f64; 3], free_pos: [f64; 3]) -> VertexFit {
        VertexFit {
            pos,
            free_pos,
            color: [0; 3],
            intensity: 0.0,
            reach: 0.0,
            density: 0.0,
        }
    }

    #[test]
    fn free_fit_is_refused_where_it_would_collapse_a_triangle() {
        let geom = GridGeom::new([0.0; 3], 1.0, 64).unwrap();
        // Three vertices on the x, y and z edges at node (5, 5, 5) (inside a block of 4).
        let keys = [0u8, 1, 2].map(|a| geom.edge_key([5, 5, 5], a));
        let safe = [[5.5, 5.0, 5.0], [5.0, 5.5, 5.0], [5.0, 5.0, 5.5]];
        // Vertex 0's free fit lands on the line through the other two: collapse.
        let fits = [
            fit(safe[0], [5.0, 5.25, 5.25]),
            fit(safe[1], safe[1]),
            fit(safe[2], safe[2]),
        ];
        let out = settle(&[[0, 1, 2]], &keys, &fits, &geom, 4);
        assert_eq!(out, safe.to_vec());
        // A harmless free fit is taken.
        let fits = [
            fit(safe[0], [5.6, 5.0, 5.1]),
            fit(safe[1], safe[1]),
            fit(safe[2], safe[2]),
        ];
        let out = settle(&[[0, 1, 2]], &keys, &fits, &geom, 4);
        assert_eq!(out[0], [5.6, 5.0, 5.1]);
        // On a block face (y = 4): the edge fit, whatever the triangles.
        let keys4 = [0u8, 1, 2].map(|a| geom.edge_key([5, 4, 5], a));
        let out = settle(&[[0, 1, 2]], &keys4, &fits, &geom, 4);
        assert_eq!(out[0], safe[0]);
    }
}
