//! Exact distances to a mesh's triangles and to a point set: [`point_triangle_distance`],
//! [`TriangleIndex`] (kd-tree over centroids, with a bound that makes the search exact) and
//! [`PointIndex`].

use std::num::NonZero;

use kiddo::SquaredEuclidean;
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use rayon::prelude::*;

use super::corners;
use crate::geom::vec::{add, cross, dot, norm, scale, sub};
use crate::io::mesh_read::Mesh;

/// A nearest-neighbour index over a point set (kd-tree).
pub struct PointIndex {
    tree: ImmutableKdTree<f64, u64, 3, 32>,
}

impl PointIndex {
    /// Index `points`.
    pub fn new(points: &[[f64; 3]]) -> PointIndex {
        PointIndex {
            tree: ImmutableKdTree::new_from_slice(points),
        }
    }

    /// Distance from `p` to the nearest indexed point (infinite for an empty index).
    pub fn nearest_distance(&self, p: [f64; 3]) -> f64 {
        self.tree
            .nearest_one::<SquaredEuclidean>(&p)
            .distance
            .sqrt()
    }
}

// Point-to-triangle distance.

/// Distance from `p` to segment `ab` (a point when `a == b`).
#[inline]
fn point_segment_distance(p: [f64; 3], a: [f64; 3], b: [f64; 3]) -> f64 {
    let ab = sub(b, a);
    let l2 = dot(ab, ab);
    let t = if l2 > 0.0 {
        (dot(sub(p, a), ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    norm(sub(p, add(a, scale(ab, t))))
}

/// Exact Euclidean distance from `p` to the triangle `abc` (a closed, filled triangle).
///
/// Voronoi-region classification of Ericson, *Real-Time Collision Detection* (2005),
/// §5.1.5 "Closest point on triangle to point". A triangle whose area vanishes relative to
/// its edges (`|ab × ac|² ≤ 1e-24 |ab|² |ac|²`, collinear or repeated corners) is treated as
/// the union of its three edges, where the classification would divide by zero.
pub fn point_triangle_distance(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let ab = sub(b, a);
    let ac = sub(c, a);
    let n = cross(ab, ac);
    if dot(n, n) <= 1e-24 * dot(ab, ab) * dot(ac, ac) || dot(n, n) == 0.0 {
        return point_segment_distance(p, a, b)
            .min(point_segment_distance(p, b, c))
            .min(point_segment_distance(p, c, a));
    }
    let ap = sub(p, a);
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return norm(ap);
    }
    let bp = sub(p, b);
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if d3 >= 0.0 && d4 <= d3 {
        return norm(bp);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return norm(sub(p, add(a, scale(ab, v))));
    }
    let cp = sub(p, c);
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if d6 >= 0.0 && d5 <= d6 {
        return norm(cp);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return norm(sub(p, add(a, scale(ac, w))));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return norm(sub(p, add(b, scale(sub(c, b), w))));
    }
    // Inside the face region: the distance to the plane.
    (dot(ap, n) / dot(n, n).sqrt()).abs()
}

/// Centroids visited before the search radius is checked.
const NEAREST_CENTROIDS: usize = 16;
/// Most triangles kept out of the kd-tree because they are much larger than the rest.
const MAX_LARGE_TRIANGLES: usize = 256;

/// Exact nearest-triangle distance queries over a mesh.
///
/// A kd-tree holds the centroids of the triangles. Every point of a triangle lies within its
/// *reach* `ρ = max |v_i - centroid|` of its centroid, so a triangle whose centroid is at
/// distance `d_c` from the query is at least `d_c - ρ_max` away. A query takes the
/// 16 nearest centroids and their exact distances, best `d`; if the
/// farthest of them is within `d + ρ_max`, every centroid within `d + ρ_max` is visited too.
/// The answer is therefore exact. So that one huge triangle does not inflate `ρ_max` for all,
/// triangles with a reach above 4 × the 99th percentile (at most 256 of
/// the largest) are kept apart and measured on every query.
pub struct TriangleIndex<'a> {
    mesh: &'a Mesh,
    /// Centroids of the triangles in `ids`.
    tree: Option<ImmutableKdTree<f64, u64, 3, 32>>,
    /// Triangle of each tree item.
    ids: Vec<u32>,
    /// Largest reach among the triangles in the tree (slightly enlarged against rounding).
    reach: f64,
    /// Triangles measured on every query.
    large: Vec<u32>,
}

impl<'a> TriangleIndex<'a> {
    /// Index the triangles of `mesh` (those with an index out of range are left out).
    pub fn new(mesh: &'a Mesh) -> TriangleIndex<'a> {
        let centroid_reach = |t: [u32; 3]| {
            let c = corners(mesh, t)?;
            let g = scale(add(add(c[0], c[1]), c[2]), 1.0 / 3.0);
            let r = c.iter().map(|&v| norm(sub(v, g))).fold(0.0, f64::max);
            Some((g, r))
        };
        // Reach of each triangle; NaN for those left out.
        let reaches: Vec<f64> = mesh
            .triangles
            .par_iter()
            .map(|&t| centroid_reach(t).map_or(f64::NAN, |(_, r)| r))
            .collect();
        let mut cut = f64::INFINITY;
        let mut radii: Vec<f64> = reaches.iter().copied().filter(|r| !r.is_nan()).collect();
        if radii.len() > MAX_LARGE_TRIANGLES {
            let k = ((radii.len() - 1) as f64 * 0.99) as usize;
            let (_, q99, _) = radii.select_nth_unstable_by(k, f64::total_cmp);
            cut = 4.0 * *q99;
            // Keep at most MAX_LARGE_TRIANGLES apart: raise the cut to the next reach down.
            let above = radii.iter().filter(|&&r| r > cut).count();
            if above > MAX_LARGE_TRIANGLES {
                let j = radii.len() - MAX_LARGE_TRIANGLES - 1;
                let (_, r, _) = radii.select_nth_unstable_by(j, f64::total_cmp);
                cut = *r;
            }
        }
        drop(radii);
        let large: Vec<u32> = (0..reaches.len() as u32)
            .filter(|&t| reaches[t as usize] > cut)
            .collect();
        let ids: Vec<u32> = (0..reaches.len() as u32)
            .filter(|&t| reaches[t as usize] <= cut)
            .collect();
        let reach = ids.iter().map(|&t| reaches[t as usize]).fold(0.0, f64::max);
        drop(reaches);
        let centroids: Vec<[f64; 3]> = ids
            .par_iter()
            .map(|&t| centroid_reach(mesh.triangles[t as usize]).map_or([0.0; 3], |(g, _)| g))
            .collect();
        let tree = (!centroids.is_empty()).then(|| ImmutableKdTree::new_from_slice(&centroids));
        TriangleIndex {
            mesh,
            tree,
            ids,
            reach: reach * (1.0 + 1e-9) + f64::MIN_POSITIVE,
            large,
        }
    }

    #[inline]
    fn triangle_distance(&self, p: [f64; 3], t: u32) -> f64 {
        match corners(self.mesh, self.mesh.triangles[t as usize]) {
            Some([a, b, c]) => point_triangle_distance(p, a, b, c),
            None => f64::INFINITY,
        }
    }

    /// Distance from `p` to the nearest triangle (infinite for a mesh without triangles).
    pub fn distance(&self, p: [f64; 3]) -> f64 {
        let mut best = f64::INFINITY;
        for &t in &self.large {
            best = best.min(self.triangle_distance(p, t));
        }
        let Some(tree) = &self.tree else {
            return best;
        };
        let k = NonZero::new(NEAREST_CENTROIDS).unwrap_or(NonZero::<usize>::MIN);
        let near = tree.nearest_n::<SquaredEuclidean>(&p, k);
        for nb in &near {
            best = best.min(self.triangle_distance(p, self.ids[nb.item as usize]));
        }
        let farthest = near.last().map_or(0.0, |nb| nb.distance.sqrt());
        if near.len() == NEAREST_CENTROIDS && farthest - self.reach < best {
            let r = best + self.reach;
            for nb in tree.within_unsorted::<SquaredEuclidean>(&p, r * r) {
                best = best.min(self.triangle_distance(p, self.ids[nb.item as usize]));
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quantile;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    #[test]
    fn nearest_matches_brute_force() {
        let pts: Vec<[f64; 3]> = (0..500)
            .map(|i| {
                let t = i as f64 * 0.37;
                [t.sin(), (1.3 * t).cos(), (0.7 * t).sin() * 2.0]
            })
            .collect();
        let idx = PointIndex::new(&pts);
        for q in [[0.1, 0.2, 0.3], [2.0, -1.0, 0.5], [0.0, 0.0, 0.0]] {
            let brute = pts
                .iter()
                .map(|p| {
                    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
                })
                .fold(f64::INFINITY, f64::min);
            assert!((idx.nearest_distance(q) - brute).abs() < 1e-12);
        }
        let mut v = vec![3.0, 1.0, 2.0];
        assert_eq!(quantile(&mut v, 0.5), 2.0);
    }

    /// Distance from `p` to the triangle by dense barycentric sampling: never below the exact
    /// distance, and above it by at most the grid spacing.
    fn brute_triangle(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3], n: usize) -> f64 {
        let mut best = f64::INFINITY;
        for i in 0..=n {
            for j in 0..=n - i {
                let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
                let q = add(a, add(scale(sub(b, a), u), scale(sub(c, a), v)));
                best = best.min(norm(sub(p, q)));
            }
        }
        best
    }

    #[test]
    fn point_triangle_matches_dense_sampling() {
        let mut rng = Pcg64::seed_from_u64(7);
        let mut r = |s: f64| [0; 3].map(|_| (rng.random::<f64>() - 0.5) * s);
        let n = 300;
        for case in 0..200 {
            let a = r(2.0);
            let mut b = r(2.0);
            let mut c = r(2.0);
            match case % 10 {
                // Collinear, a repeated corner, and a point triangle.
                7 => c = add(a, scale(sub(b, a), 1.7)),
                8 => b = a,
                9 => {
                    b = a;
                    c = a;
                }
                _ => {}
            }
            let p = r(4.0);
            let exact = point_triangle_distance(p, a, b, c);
            let brute = brute_triangle(p, a, b, c, n);
            let h = [sub(b, a), sub(c, a)]
                .map(norm)
                .into_iter()
                .fold(0.0, f64::max)
                / n as f64;
            assert!(
                brute >= exact - 1e-12 && brute - exact <= 1.5 * h + 1e-12,
                "case {case}: exact {exact}, brute {brute}, spacing {h}"
            );
        }
        // Points on the face and at corners are at distance 0.
        let (a, b, c) = ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        assert_eq!(point_triangle_distance([0.25, 0.25, 0.0], a, b, c), 0.0);
        assert_eq!(point_triangle_distance([0.25, 0.25, -2.0], a, b, c), 2.0);
        assert_eq!(point_triangle_distance(b, a, b, c), 0.0);
    }

    #[test]
    fn triangle_index_matches_brute_force() {
        let mut rng = Pcg64::seed_from_u64(11);
        let mut m = Mesh::default();
        for i in 0..3000 {
            // Mostly small triangles, a few huge ones, some degenerate.
            let s = match i % 500 {
                0 => 20.0,
                1 => 3.0,
                _ => 0.05,
            };
            let g = [0; 3].map(|_| rng.random::<f64>() * 4.0);
            let k = m.vertices.len() as u32;
            for _ in 0..3 {
                let d = [0; 3].map(|_| (rng.random::<f64>() - 0.5) * s);
                m.vertices.push(add(g, d));
            }
            m.triangles.push(if i % 97 == 5 {
                [k, k, k + 1]
            } else {
                [k, k + 1, k + 2]
            });
        }
        let index = TriangleIndex::new(&m);
        assert!(!index.large.is_empty());
        for q in 0..400 {
            let p = [0; 3].map(|_| rng.random::<f64>() * 6.0 - 1.0);
            let brute = m
                .triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| m.vertices[i as usize]);
                    point_triangle_distance(p, a, b, c)
                })
                .fold(f64::INFINITY, f64::min);
            assert_eq!(index.distance(p), brute, "query {q}");
        }
        assert_eq!(
            TriangleIndex::new(&Mesh::default()).distance([0.0; 3]),
            f64::INFINITY
        );
    }
}
