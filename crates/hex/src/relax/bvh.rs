//! The surface queries of step 3 of the module docs of [`super`]: a bounding-volume
//! hierarchy over the boundary triangles (axis-aligned boxes, median splits) for the closest
//! point, over all triangles or those facing a direction, and the closest point on one
//! triangle (Ericson, "Real-Time Collision Detection", 2005, §5.1.5).

use super::dist2;
use crate::geom::vec::{add, cross, dot, scale, sub};
use crate::types::Aabb;

/// The closest point to `p` on triangle `a b c` (Ericson's region test).
pub fn closest_on_triangle(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [f64; 3] {
    let ab = sub(b, a);
    let ac = sub(c, a);
    let ap = sub(p, a);
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = sub(p, b);
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return add(a, scale(ab, v));
    }
    let cp = sub(p, c);
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return add(a, scale(ac, w));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return add(b, scale(sub(c, b), w));
    }
    let denom = va + vb + vc;
    let out = add(a, add(scale(ab, vb / denom), scale(ac, vc / denom)));
    if out.iter().all(|x| x.is_finite()) {
        out
    } else {
        // A degenerate triangle: its nearest corner.
        [a, b, c]
            .into_iter()
            .min_by(|x, y| dist2(*x, p).total_cmp(&dist2(*y, p)))
            .unwrap_or(a)
    }
}

/// A node of [`Bvh`]: a box and either two children (`count == 0`, children at `first` and
/// `first + 1`) or a leaf's triangles `order[first..first + count]`.
#[derive(Clone, Copy, Debug)]
struct BvhNode {
    lo: [f64; 3],
    hi: [f64; 3],
    first: u32,
    count: u32,
}

/// A bounding-volume hierarchy over a triangle soup for closest-point queries.
#[derive(Clone, Debug)]
pub struct Bvh {
    tris: Vec<[[f64; 3]; 3]>,
    order: Vec<u32>,
    nodes: Vec<BvhNode>,
}

const LEAF_SIZE: usize = 4;

impl Bvh {
    /// Builds the hierarchy of the triangles `tris` over `verts`.
    ///
    /// # Panics
    /// If a triangle names a vertex beyond `verts`.
    pub fn new(verts: &[[f64; 3]], tris: &[[u32; 3]]) -> Bvh {
        let tris: Vec<[[f64; 3]; 3]> = tris.iter().map(|t| t.map(|v| verts[v as usize])).collect();
        let centroid: Vec<[f64; 3]> = tris
            .iter()
            .map(|t| scale(add(add(t[0], t[1]), t[2]), 1.0 / 3.0))
            .collect();
        let mut order: Vec<u32> = (0..tris.len() as u32).collect();
        let mut nodes = Vec::new();
        if tris.is_empty() {
            return Bvh { tris, order, nodes };
        }
        nodes.push(BvhNode {
            lo: [0.0; 3],
            hi: [0.0; 3],
            first: 0,
            count: 0,
        });
        // (node, start, end) still to fill in.
        let mut todo = vec![(0usize, 0usize, tris.len())];
        while let Some((node, start, end)) = todo.pop() {
            let mut lo = [f64::INFINITY; 3];
            let mut hi = [f64::NEG_INFINITY; 3];
            let mut clo = [f64::INFINITY; 3];
            let mut chi = [f64::NEG_INFINITY; 3];
            for &t in &order[start..end] {
                for p in &tris[t as usize] {
                    for k in 0..3 {
                        lo[k] = lo[k].min(p[k]);
                        hi[k] = hi[k].max(p[k]);
                    }
                }
                let c = centroid[t as usize];
                for k in 0..3 {
                    clo[k] = clo[k].min(c[k]);
                    chi[k] = chi[k].max(c[k]);
                }
            }
            nodes[node].lo = lo;
            nodes[node].hi = hi;
            if end - start <= LEAF_SIZE {
                nodes[node].first = start as u32;
                nodes[node].count = (end - start) as u32;
                continue;
            }
            let axis = (0..3)
                .max_by(|&a, &b| (chi[a] - clo[a]).total_cmp(&(chi[b] - clo[b])))
                .unwrap_or(0);
            let mid = (start + end) / 2;
            order[start..end].select_nth_unstable_by(mid - start, |&a, &b| {
                centroid[a as usize][axis]
                    .total_cmp(&centroid[b as usize][axis])
                    .then(a.cmp(&b))
            });
            let left = nodes.len();
            for _ in 0..2 {
                nodes.push(BvhNode {
                    lo: [0.0; 3],
                    hi: [0.0; 3],
                    first: 0,
                    count: 0,
                });
            }
            nodes[node].first = left as u32;
            todo.push((left, start, mid));
            todo.push((left + 1, mid, end));
        }
        Bvh { tris, order, nodes }
    }

    /// Whether there are no triangles.
    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    fn box_dist2(n: &BvhNode, p: [f64; 3]) -> f64 {
        Aabb {
            min: n.lo,
            max: n.hi,
        }
        .dist2(p)
    }

    /// The closest point to `p` on the triangles and its squared distance; `None` without
    /// triangles. Ties go to the triangle met first in a fixed traversal order.
    pub fn closest(&self, p: [f64; 3]) -> Option<([f64; 3], f64)> {
        self.closest_where(p, |_| true)
    }

    /// As [`Bvh::closest`], over the triangles whose normal (from their vertex order) makes
    /// an acute angle with `n`: the near side of a thin part, not its far side nor a
    /// neighbouring part's face turned towards it. `None` when no triangle faces `n`.
    pub fn closest_facing(&self, p: [f64; 3], n: [f64; 3]) -> Option<([f64; 3], f64)> {
        self.closest_where(p, |[a, b, c]| dot(cross(sub(*b, *a), sub(*c, *a)), n) > 0.0)
    }

    fn closest_where(
        &self,
        p: [f64; 3],
        keep: impl Fn(&[[f64; 3]; 3]) -> bool,
    ) -> Option<([f64; 3], f64)> {
        if self.nodes.is_empty() {
            return None;
        }
        let mut best = ([0.0; 3], f64::INFINITY);
        let mut stack = vec![0usize];
        while let Some(i) = stack.pop() {
            let n = &self.nodes[i];
            if Self::box_dist2(n, p) >= best.1 {
                continue;
            }
            if n.count > 0 {
                let (a, b) = (n.first as usize, (n.first + n.count) as usize);
                for &t in &self.order[a..b] {
                    if !keep(&self.tris[t as usize]) {
                        continue;
                    }
                    let [x, y, z] = self.tris[t as usize];
                    let q = closest_on_triangle(p, x, y, z);
                    let d = dist2(p, q);
                    if d < best.1 {
                        best = (q, d);
                    }
                }
            } else {
                let (l, r) = (n.first as usize, n.first as usize + 1);
                let (dl, dr) = (
                    Self::box_dist2(&self.nodes[l], p),
                    Self::box_dist2(&self.nodes[r], p),
                );
                // Nearer child on top of the stack.
                if dl <= dr {
                    stack.push(r);
                    stack.push(l);
                } else {
                    stack.push(l);
                    stack.push(r);
                }
            }
        }
        best.1.is_finite().then_some(best)
    }
}
