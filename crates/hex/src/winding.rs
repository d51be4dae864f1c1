//! The generalised winding number of a triangle soup: an inside/outside function that needs no
//! watertight, manifold or even consistent input beyond the triangles' winding.
//!
//! # What it computes
//!
//! Jacobson, Kavan, Sorkine-Hornung, "Robust inside-outside segmentation using generalized
//! winding numbers" (SIGGRAPH 2013), §3: for a point `p`,
//!
//! ```text
//! w(p) = Σ_t Ω_t(p) / 4π
//! ```
//!
//! where `Ω_t(p)` is the signed solid angle triangle `t` subtends at `p`, by the formula of
//! Van Oosterom and Strackee (1983): with `a, b, c` the corners relative to `p`,
//!
//! ```text
//! tan(Ω/2) = det[a b c] / (|a||b||c| + (a·b)|c| + (b·c)|a| + (c·a)|b|).
//! ```
//!
//! For a closed, outward-wound (counter-clockwise seen from outside) surface `w` is 1 inside
//! and 0 outside; for a surface with holes, gaps or overlaps it degrades gracefully (a hole's
//! error at `p` is the solid angle the missing patch subtends, over 4π), which is the point of
//! the method. A clockwise-wound mesh gives −1 inside.
//!
//! # How it is made fast
//!
//! Barill, Dickson, Schmidt, Levin, Jacobson, "Fast winding numbers for soups and clouds"
//! (SIGGRAPH 2018), §3–4: `Ω_t(p) = ∫_t n_t · K(x − p) dA` with the kernel
//! `K(y) = y / |y|³ = ∇(−1/|y|)`, 4π times the gradient of the Green's function
//! `G(y) = −1/(4π|y|)`; `w` is the potential of a dipole layer on the surface. For a cluster of triangles far from `p`, `K(x − p)` is expanded in a Taylor
//! series about the cluster's area-weighted centre `c`: with `r = c − p`, `u = x − c`,
//!
//! ```text
//! K_i(r + u) = K_i(r) + ∂_j K_i(r) u_j + ½ ∂_j ∂_l K_i(r) u_j u_l + O(|u|³ / |r|⁵)
//! ∂_j K_i     = δ_ij / |r|³ − 3 r_i r_j / |r|⁵
//! ∂_j ∂_l K_i = −3 (δ_ij r_l + δ_il r_j + δ_jl r_i) / |r|⁵ + 15 r_i r_j r_l / |r|⁷
//! ```
//!
//! and integrated against the cluster's normals, which leaves per-cluster moments that do not
//! depend on `p` (the paper's zeroth-, first- and second-order terms; `a_t`, `n_t`, `x̄_t`
//! are the area, unit normal and centroid of triangle `t`, sums over repeated indices):
//!
//! ```text
//! order 0 (dipole):  D     = Σ a_t n_t                        Ω ≈ D · r / |r|³
//! order 1:           M_ij  = Σ a_t n_ti (x̄_t − c)_j           + (tr M − 3 rᵀ M r / |r|²) / |r|³
//! order 2:           Q_ijl = Σ n_ti ∫_t u_j u_l dA             + (−3 A − 3/2 B) / |r|⁵ + 15/2 C / |r|⁷
//!                    A = Σ_il Q_iil r_l,   B = Σ_ij r_i Q_ijj,   C = Σ_ijl Q_ijl r_i r_j r_l
//! ```
//!
//! The second moment of a triangle is integrated exactly: with `d_k` its corners and `d̄` its
//! centroid relative to `c`, `∫_t u uᵀ dA = a_t / 12 (Σ_k d_k d_kᵀ + 9 d̄ d̄ᵀ)`.
//!
//! On a curved surface the order-1 term alone does *not* improve on the dipole: the normals
//! vary by `O(R)` across a cluster of radius `R`, so `M` and the second moments in `Q` are
//! both `O(R²)` relative to `D`, and only the sum of orders 1 and 2 cancels the dipole's error
//! (for a spherical cap seen from the sphere's centre the three error terms are
//! `+πθ⁴/4`, `+πθ⁴/2` and `−3πθ⁴/4` to leading order in the cap's angle θ). The truncation
//! error after order `k` is `O((R/|r|)^(k+1))` times the cluster's solid angle, itself
//! `O((R/|r|)²)`: the test `expansion_error_decays_with_the_right_order` checks the rates
//! `(R/|r|)³`, `⁴`, `⁵`.
//!
//! The clusters are the nodes of a bounding-volume hierarchy over the triangles (median
//! splits of the centroids along the longest axis, at most [`LEAF_SIZE`] triangles a leaf).
//! A node is "far" when `|c − p| > β · radius`, the radius being the largest distance from
//! `c` to a corner of the node's triangles (the paper's criterion, with its default β = 2).
//! Evaluation walks the tree from the root: a far node contributes its expansion, a near leaf
//! its triangles' exact solid angles, a near inner node its children.
//! [`WindingNumber::new`] uses β = 2 and order 2, the paper's choices;
//! [`WindingNumber::with_params`] takes others.
//!
//! # Accuracy and speed (tested)
//!
//! With order 2 the error of a far node is about β^−3 of its own contribution, and a node
//! just beyond β radii subtends up to about π/β² steradians, so the worst case is about
//! 1e-2 at β = 2 whatever the triangle count, reached next to the surface. Against
//! the brute-force sum on an icosphere of 20 480 triangles, at points at least 1% of the
//! radius off the surface, inside and out (`fast_matches_brute_force_off_the_surface`
//! asserts the β = 2 figures and order 2 at β = 3; the rest was measured once on the same
//! points):
//!
//! ```text
//!            β = 2 (default)            β = 3                    β = 4
//! order 0    max 5.3e-2, mean 5.7e-3    max 2.0e-2, mean 2.3e-3  max 9.4e-3, mean 1.1e-3
//! order 1    max 5.6e-2, mean 4.8e-3    max 2.8e-2, mean 1.9e-3  max 1.6e-2, mean 1.0e-3
//! order 2    max 6.1e-3, mean 7.4e-4    max 9.0e-4, mean 9.9e-5  max 2.5e-4, mean 3.0e-5
//! ```
//!
//! So the default is good to about 1e-2 everywhere (1e-3 on average), ample for an
//! inside/outside test such as `0.5 − w` (see [`crate::stuffing`]); β = 3 brings the
//! maximum under 1e-3 at about 2.5 times the cost. Points on or within a triangle's size of
//! the surface see their nearby triangles exactly, since every node near them is opened.
//!
//! Speed (release, one core, 20 480 triangles, points in a cube around the sphere): about
//! 0.5 million evaluations a second at β = 2 and 0.2 million at β = 3, against about 2 000
//! for brute force (`speed_on_20k_triangles`, ignored by default; run with `cargo test
//! --release --lib hex::winding -- --ignored --nocapture`).
//!
//! Evaluation is sequential per point and sums in a fixed order, so results do not depend on
//! the thread count of a caller that evaluates points in parallel.

use crate::geom::vec::{cross, dot, norm, sub};
use std::f64::consts::PI;

/// Most triangles in a leaf of the hierarchy.
pub const LEAF_SIZE: usize = 8;

/// The accuracy parameter β of Barill et al. (their default): a node is expanded instead of
/// opened when the point is farther than β times its radius from its centre.
pub const BETA: f64 = 2.0;

/// The symmetric index pairs `(j, l)` of a 3×3 symmetric matrix stored as 6 numbers.
const SYM: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)];

/// One node of the hierarchy.
#[derive(Clone, Debug)]
struct Node {
    /// Area-weighted centre of its triangles.
    centre: [f64; 3],
    /// Largest distance from `centre` to a corner of its triangles.
    radius: f64,
    /// Σ a_t n_t (the dipole moment; half the summed cross products).
    dipole: [f64; 3],
    /// Σ a_t n_t ⊗ (x̄_t − centre): `second[i][j]` = Σ a_t n_{t,i} (x̄_t − c)_j.
    second: [[f64; 3]; 3],
    /// Σ n_t ⊗ ∫_t (x − centre)(x − centre)ᵀ dA: `third[i][s]` for the normal's component
    /// `i` and the symmetric index pair `SYM[s]`.
    third: [[f64; 6]; 3],
    /// Leaf: first triangle and count; inner: `first` is the left child and `count` is 0
    /// (the right child is `right`).
    first: u32,
    count: u32,
    right: u32,
}

/// The generalised winding number of a triangle soup with a hierarchy for fast evaluation.
#[derive(Clone, Debug)]
pub struct WindingNumber {
    /// Triangle corners in hierarchy order.
    tris: Vec<[[f64; 3]; 3]>,
    nodes: Vec<Node>,
    beta: f64,
    order: u8,
}

/// The signed solid angle triangle `t` subtends at `p` (Van Oosterom–Strackee), in
/// steradians: positive when `p` lies behind the triangle's counter-clockwise normal.
pub fn solid_angle(t: &[[f64; 3]; 3], p: [f64; 3]) -> f64 {
    let a = sub(t[0], p);
    let b = sub(t[1], p);
    let c = sub(t[2], p);
    let (la, lb, lc) = (norm(a), norm(b), norm(c));
    let det = dot(a, cross(b, c));
    let den = la * lb * lc + dot(a, b) * lc + dot(b, c) * la + dot(c, a) * lb;
    2.0 * det.atan2(den)
}

impl WindingNumber {
    /// Build the hierarchy over `triangles` (indices into `vertices`), with β = [`BETA`] and
    /// expansions of order 2 (see the module docs). An index at or beyond `vertices.len()` or a corner that is not
    /// finite is an error naming the triangle; a soup without triangles gives w = 0 everywhere.
    pub fn new(vertices: &[[f64; 3]], triangles: &[[u32; 3]]) -> Result<WindingNumber, String> {
        WindingNumber::with_params(vertices, triangles, BETA, 2)
    }

    /// [`WindingNumber::new`] with another β (> 0; larger is more accurate and slower) and
    /// expansion order (0: the dipole alone, 1: with the first-order term, 2: with the first-
    /// and second-order terms; see the module docs).
    pub fn with_params(
        vertices: &[[f64; 3]],
        triangles: &[[u32; 3]],
        beta: f64,
        order: u8,
    ) -> Result<WindingNumber, String> {
        if !beta.is_finite() || beta <= 0.0 {
            return Err(format!("beta is {beta}, expected a finite number > 0"));
        }
        if order > 2 {
            return Err(format!("expansion order is {order}, expected 0, 1 or 2"));
        }
        let n = vertices.len();
        let mut tris = Vec::with_capacity(triangles.len());
        for (t, tri) in triangles.iter().enumerate() {
            let mut c = [[0.0; 3]; 3];
            for k in 0..3 {
                let i = tri[k] as usize;
                if i >= n {
                    return Err(format!(
                        "triangle {t} has vertex index {i}, expected one below {n} (the vertex count)"
                    ));
                }
                let v = vertices[i];
                if !v.iter().all(|x| x.is_finite()) {
                    return Err(format!(
                        "triangle {t} has vertex {i} at ({}, {}, {}), expected finite coordinates",
                        v[0], v[1], v[2]
                    ));
                }
                c[k] = v;
            }
            tris.push(c);
        }
        if tris.len() >= u32::MAX as usize {
            return Err(format!(
                "{} triangles, expected fewer than {}",
                tris.len(),
                u32::MAX
            ));
        }
        let mut w = WindingNumber {
            tris,
            nodes: Vec::new(),
            beta,
            order,
        };
        if !w.tris.is_empty() {
            let mut order_idx: Vec<u32> = (0..w.tris.len() as u32).collect();
            let cents: Vec<[f64; 3]> = w
                .tris
                .iter()
                .map(|t| {
                    let mut c = [0.0; 3];
                    for k in 0..3 {
                        c[k] = (t[0][k] + t[1][k] + t[2][k]) / 3.0;
                    }
                    c
                })
                .collect();
            w.nodes.reserve(2 * w.tris.len() / LEAF_SIZE + 2);
            w.build(&mut order_idx, 0, &cents);
            let sorted: Vec<[[f64; 3]; 3]> =
                order_idx.iter().map(|&i| w.tris[i as usize]).collect();
            w.tris = sorted;
            w.fill_moments(0);
        }
        Ok(w)
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.tris.len()
    }

    /// Split `idx` (the triangles of a new node starting at `offset` in the final order)
    /// recursively; returns the node's index.
    fn build(&mut self, idx: &mut [u32], offset: usize, cents: &[[f64; 3]]) -> u32 {
        let me = self.nodes.len() as u32;
        self.nodes.push(Node {
            centre: [0.0; 3],
            radius: 0.0,
            dipole: [0.0; 3],
            second: [[0.0; 3]; 3],
            third: [[0.0; 6]; 3],
            first: offset as u32,
            count: idx.len() as u32,
            right: 0,
        });
        if idx.len() <= LEAF_SIZE {
            return me;
        }
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for &i in idx.iter() {
            let c = cents[i as usize];
            for k in 0..3 {
                lo[k] = lo[k].min(c[k]);
                hi[k] = hi[k].max(c[k]);
            }
        }
        let ext = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
        let axis = if ext[0] >= ext[1] && ext[0] >= ext[2] {
            0
        } else if ext[1] >= ext[2] {
            1
        } else {
            2
        };
        let mid = idx.len() / 2;
        idx.select_nth_unstable_by(mid, |&a, &b| {
            cents[a as usize][axis]
                .total_cmp(&cents[b as usize][axis])
                .then(a.cmp(&b))
        });
        let (l, r) = idx.split_at_mut(mid);
        let left = self.build(l, offset, cents);
        let right = self.build(r, offset + mid, cents);
        let node = &mut self.nodes[me as usize];
        node.first = left;
        node.count = 0;
        node.right = right;
        me
    }

    /// The triangles of node `n` as a range into `tris` (inner nodes cover their subtree).
    fn range(&self, n: usize) -> std::ops::Range<usize> {
        let node = &self.nodes[n];
        if node.count > 0 {
            node.first as usize..(node.first + node.count) as usize
        } else {
            let a = self.range(node.first as usize).start;
            let b = self.range(node.right as usize).end;
            a..b
        }
    }

    /// Centre, radius and moments of node `n` and its subtree, from its triangles directly
    /// (each level sums its own triangles, in order, so the sums are exact of the layout).
    fn fill_moments(&mut self, n: usize) {
        let node = self.nodes[n].clone();
        if node.count == 0 {
            self.fill_moments(node.first as usize);
            self.fill_moments(node.right as usize);
        }
        let range = self.range(n);
        let tris = &self.tris[range];
        let mut area = 0.0;
        let mut wc = [0.0; 3];
        let mut plain = [0.0; 3];
        let mut dipole = [0.0; 3];
        for t in tris {
            let an = cross(sub(t[1], t[0]), sub(t[2], t[0]));
            let a = 0.5 * norm(an);
            area += a;
            for k in 0..3 {
                let c = (t[0][k] + t[1][k] + t[2][k]) / 3.0;
                wc[k] += a * c;
                plain[k] += c;
                dipole[k] += 0.5 * an[k];
            }
        }
        let centre = if area > 0.0 {
            wc.map(|x| x / area)
        } else {
            plain.map(|x| x / tris.len() as f64)
        };
        let mut radius: f64 = 0.0;
        let mut second = [[0.0; 3]; 3];
        let mut third = [[0.0; 6]; 3];
        for t in tris {
            for v in t {
                radius = radius.max(norm(sub(*v, centre)));
            }
            // a_t n_t = half the cross product.
            let an = cross(sub(t[1], t[0]), sub(t[2], t[0])).map(|x| 0.5 * x);
            let c = t.map(|v| sub(v, centre));
            let d = [0, 1, 2].map(|k| (c[0][k] + c[1][k] + c[2][k]) / 3.0);
            for i in 0..3 {
                for j in 0..3 {
                    second[i][j] += an[i] * d[j];
                }
            }
            // ∫_t u uᵀ dA = a_t/12 (Σ_k d_k d_kᵀ + 9 d̄ d̄ᵀ), u = x − centre, exact for a
            // triangle; times the unit normal this is an[i]/12 (…).
            for (s, &(j, l)) in SYM.iter().enumerate() {
                let m =
                    c[0][j] * c[0][l] + c[1][j] * c[1][l] + c[2][j] * c[2][l] + 9.0 * d[j] * d[l];
                for i in 0..3 {
                    third[i][s] += an[i] * m / 12.0;
                }
            }
        }
        let node = &mut self.nodes[n];
        node.centre = centre;
        node.radius = radius;
        node.dipole = dipole;
        node.second = second;
        node.third = third;
    }

    /// The winding number at `p`, fast (see the module docs for the accuracy).
    pub fn eval(&self, p: [f64; 3]) -> f64 {
        if self.nodes.is_empty() {
            return 0.0;
        }
        // Summed in steradians (exact solid angles and expansions alike), over 4π at the end.
        let mut sum = 0.0;
        let mut stack = [0u32; 64];
        let mut top = 1usize;
        stack[0] = 0;
        while top > 0 {
            top -= 1;
            let node = &self.nodes[stack[top] as usize];
            let r = sub(node.centre, p);
            let d2 = dot(r, r);
            if d2 > (self.beta * node.radius) * (self.beta * node.radius) {
                sum += self.expansion(node, r, d2);
            } else if node.count > 0 {
                let a = node.first as usize;
                let b = a + node.count as usize;
                let mut s = 0.0;
                for t in &self.tris[a..b] {
                    s += solid_angle(t, p);
                }
                sum += s;
            } else {
                // The stack holds at most depth + 1 nodes; median splits keep the depth at
                // about log2(n / LEAF_SIZE) + 1, at most 30 for u32 triangle counts.
                stack[top] = node.right;
                stack[top + 1] = node.first;
                top += 2;
            }
        }
        sum / (4.0 * PI)
    }

    /// The far-field expansion of `node` (its solid angle, in steradians) at the point
    /// `p = centre − r`, `d2 = |r|²`, to the order chosen (see the module docs).
    fn expansion(&self, node: &Node, r: [f64; 3], d2: f64) -> f64 {
        let inv2 = 1.0 / d2;
        let inv3 = inv2 / d2.sqrt();
        // Order 0: the dipole, Σ a n · ∇ₓK.
        let mut w = dot(node.dipole, r) * inv3;
        if self.order >= 1 {
            let m = &node.second;
            let tr = m[0][0] + m[1][1] + m[2][2];
            let mut rmr = 0.0;
            for i in 0..3 {
                for j in 0..3 {
                    rmr += r[i] * m[i][j] * r[j];
                }
            }
            w += (tr - 3.0 * rmr * inv2) * inv3;
        }
        if self.order >= 2 {
            let q = &node.third;
            // A = Σ_{i,l} Q_{iil} r_l, B = Σ_i r_i Σ_j Q_{ijj}, C = Q(r, r, r).
            let mut a = 0.0;
            let mut b = 0.0;
            let mut c = 0.0;
            for i in 0..3 {
                for (s, &(j, l)) in SYM.iter().enumerate() {
                    let mult = if j == l { 1.0 } else { 2.0 };
                    if j == i {
                        a += mult * 0.5 * q[i][s] * r[l];
                    }
                    if l == i {
                        a += mult * 0.5 * q[i][s] * r[j];
                    }
                    if j == l {
                        b += r[i] * q[i][s];
                    }
                    c += mult * q[i][s] * r[i] * r[j] * r[l];
                }
            }
            w += ((-3.0 * a - 1.5 * b) + 7.5 * c * inv2) * inv2 * inv3;
        }
        w
    }

    /// The winding number at `p` by the brute-force sum over every triangle (for tests and
    /// for checking the fast evaluation).
    pub fn eval_exact(&self, p: [f64; 3]) -> f64 {
        let mut s = 0.0;
        for t in &self.tris {
            s += solid_angle(t, p);
        }
        s / (4.0 * PI)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// An icosphere of radius `r` about the origin, `level` times subdivided (20·4^level
    /// triangles), wound counter-clockwise seen from outside.
    pub(crate) fn icosphere(level: u32, r: f64) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        let t = (1.0 + 5f64.sqrt()) / 2.0;
        let mut v: Vec<[f64; 3]> = vec![
            [-1.0, t, 0.0],
            [1.0, t, 0.0],
            [-1.0, -t, 0.0],
            [1.0, -t, 0.0],
            [0.0, -1.0, t],
            [0.0, 1.0, t],
            [0.0, -1.0, -t],
            [0.0, 1.0, -t],
            [t, 0.0, -1.0],
            [t, 0.0, 1.0],
            [-t, 0.0, -1.0],
            [-t, 0.0, 1.0],
        ];
        let mut f: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for p in v.iter_mut() {
            let n = norm(*p);
            *p = p.map(|x| x / n);
        }
        for _ in 0..level {
            let mut mid = std::collections::HashMap::new();
            let mut nf = Vec::with_capacity(f.len() * 4);
            let mut midpoint = |a: u32, b: u32, v: &mut Vec<[f64; 3]>| -> u32 {
                *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    let (p, q) = (v[a as usize], v[b as usize]);
                    let m = [p[0] + q[0], p[1] + q[1], p[2] + q[2]];
                    let n = norm(m);
                    v.push(m.map(|x| x / n));
                    (v.len() - 1) as u32
                })
            };
            for &[a, b, c] in &f {
                let ab = midpoint(a, b, &mut v);
                let bc = midpoint(b, c, &mut v);
                let ca = midpoint(c, a, &mut v);
                nf.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
            }
            f = nf;
        }
        for p in v.iter_mut() {
            *p = p.map(|x| x * r);
        }
        (v, f)
    }

    /// Deterministic points in a cube of half-width `s` (a small LCG).
    fn points(n: usize, s: f64, seed: u64) -> Vec<[f64; 3]> {
        let mut x = seed;
        let mut next = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((x >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        (0..n)
            .map(|_| [next() * s, next() * s, next() * s])
            .collect()
    }

    #[test]
    fn one_triangle_solid_angle_and_orientation() {
        // A point behind an outward normal sees a positive solid angle; an infinitesimally
        // close point sees ±2π.
        let t = [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]];
        assert!(solid_angle(&t, [0.0; 3]) > 0.0);
        assert!(solid_angle(&t, [0.0, 0.0, 2.0]) < 0.0);
        let near = solid_angle(&t, [0.2, 0.2, 1.0 - 1e-9]);
        assert!((near - 2.0 * PI).abs() < 1e-6, "{near}");
        // The octant triangle subtends 1/8 of the sphere.
        let o = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert!((solid_angle(&o, [0.0; 3]) - 4.0 * PI / 8.0).abs() < 1e-12);
    }

    #[test]
    fn inside_is_one_outside_is_zero() {
        let (v, f) = icosphere(3, 1.0);
        let w = WindingNumber::new(&v, &f).unwrap();
        // Exactly (brute force) 1 inside and 0 outside; the fast evaluation within its
        // documented 1e-2 at the default β.
        for p in [[0.0; 3], [0.5, -0.3, 0.2], [0.0, 0.0, 0.9]] {
            assert!(
                (w.eval_exact(p) - 1.0).abs() < 1e-9,
                "{p:?}: {}",
                w.eval_exact(p)
            );
            assert!((w.eval(p) - 1.0).abs() < 1e-2, "{p:?}: {}", w.eval(p));
        }
        for p in [[2.0, 0.0, 0.0], [1.1, 0.3, -0.2], [10.0, 10.0, 10.0]] {
            assert!(w.eval_exact(p).abs() < 1e-9, "{p:?}: {}", w.eval_exact(p));
            assert!(w.eval(p).abs() < 1e-2, "{p:?}: {}", w.eval(p));
        }
        // Far away the whole sphere is one expansion, whose dipole is 0 for a closed surface.
        assert!(w.eval([10.0, 10.0, 10.0]).abs() < 1e-9);
        // Reversed winding gives −1 inside.
        let rev: Vec<[u32; 3]> = f.iter().map(|t| [t[0], t[2], t[1]]).collect();
        let wr = WindingNumber::new(&v, &rev).unwrap();
        assert!((wr.eval_exact([0.1, 0.0, 0.0]) + 1.0).abs() < 1e-9);
        assert!((wr.eval([0.1, 0.0, 0.0]) + 1.0).abs() < 1e-2);
    }

    /// Largest and mean |fast − exact| over `pts`, with `exact` precomputed.
    fn errors(w: &WindingNumber, pts: &[[f64; 3]], exact: &[f64]) -> (f64, f64) {
        let mut worst: f64 = 0.0;
        let mut sum = 0.0;
        for (p, e) in pts.iter().zip(exact) {
            let d = (w.eval(*p) - e).abs();
            worst = worst.max(d);
            sum += d;
        }
        (worst, sum / pts.len() as f64)
    }

    #[test]
    fn fast_matches_brute_force_off_the_surface() {
        let (v, f) = icosphere(5, 1.0);
        assert_eq!(f.len(), 20480);
        // Points in a cube around the sphere, at least 1% of the radius off it.
        let pts: Vec<[f64; 3]> = points(300, 1.6, 7)
            .into_iter()
            .filter(|p| (norm(*p) - 1.0).abs() >= 0.01)
            .collect();
        assert!(pts.len() > 200);
        // And a shell 1% inside and outside (about one triangle size off).
        let shell: Vec<[f64; 3]> = points(200, 1.0, 11)
            .into_iter()
            .filter(|p| norm(*p) > 0.1)
            .enumerate()
            .map(|(i, p)| {
                let s = if i % 2 == 0 { 0.99 } else { 1.01 } / norm(p);
                p.map(|x| x * s)
            })
            .collect();
        let w = WindingNumber::new(&v, &f).unwrap();
        let exact: Vec<f64> = pts.iter().map(|&p| w.eval_exact(p)).collect();
        let exact_shell: Vec<f64> = shell.iter().map(|&p| w.eval_exact(p)).collect();
        let (max2, mean2) = errors(&w, &pts, &exact);
        let (max_shell, _) = errors(&w, &shell, &exact_shell);
        let err = |beta: f64, order: u8| {
            errors(
                &WindingNumber::with_params(&v, &f, beta, order).unwrap(),
                &pts,
                &exact,
            )
        };
        let (max0, mean0) = err(BETA, 0);
        let (max1, mean1) = err(BETA, 1);
        let (max3, mean3) = err(3.0, 2);
        eprintln!(
            "max (mean) |fast - exact| at beta 2: order 0 {max0:.2e} ({mean0:.2e}), \
             order 1 {max1:.2e} ({mean1:.2e}), order 2 {max2:.2e} ({mean2:.2e}), \
             shell {max_shell:.2e}; beta 3, order 2: {max3:.2e} ({mean3:.2e})"
        );
        // The module docs' figures, with a margin.
        assert!(max2 < 1e-2 && mean2 < 1e-3, "order 2: {max2} ({mean2})");
        assert!(max_shell < 1e-2, "order 2 near the surface: {max_shell}");
        assert!(max3 < 1e-3 && mean3 < 2e-4, "beta 3: {max3} ({mean3})");
        // The second-order term is what makes the expansion accurate on a curved surface.
        assert!(
            max2 < max0 / 5.0 && max2 < max1 / 5.0,
            "{max0} {max1} {max2}"
        );
        assert!(mean2 < mean0 / 5.0 && mean2 < mean1 / 5.0);
    }

    #[test]
    fn expansion_error_decays_with_the_right_order() {
        // A curved patch of 8 triangles (one leaf, so the root is the only node); with a tiny
        // β the root is always expanded. The error after order k must fall at least as
        // (R / |r|)^(k + 3) when the distance doubles (a wrong order-k term would leave an
        // error falling as (R / |r|)^(k + 2); in some directions the leading error term
        // vanishes by symmetry and the fall is faster).
        let mut v = Vec::new();
        for j in 0..3 {
            for i in 0..3 {
                let (x, y) = (0.3 * (i as f64 - 1.0), 0.3 * (j as f64 - 1.0));
                v.push([x, y, (1.0 - x * x - y * y).sqrt()]);
            }
        }
        let mut f = Vec::new();
        for j in 0..2u32 {
            for i in 0..2u32 {
                let a = 3 * j + i;
                f.push([a, a + 1, a + 4]);
                f.push([a, a + 4, a + 3]);
            }
        }
        for order in 0..=2u8 {
            let w = WindingNumber::with_params(&v, &f, 1e-6, order).unwrap();
            assert_eq!(w.nodes.len(), 1);
            let (c, r) = (w.nodes[0].centre, w.nodes[0].radius);
            let expected = 2f64.powi(order as i32 + 3);
            for dir in [[0.3, -0.5, 0.8], [1.0, 0.2, 0.1], [-0.2, 0.4, -0.9]] {
                let n = norm(dir);
                let err = |dist: f64| {
                    let p = [0, 1, 2].map(|k| c[k] + dist * r * dir[k] / n);
                    (w.eval(p) - w.eval_exact(p)).abs()
                };
                let ratio = err(16.0) / err(32.0);
                assert!(
                    ratio > 0.7 * expected,
                    "order {order}, direction {dir:?}: error ratio {ratio}, expected {expected}"
                );
            }
        }
    }

    #[test]
    fn a_small_hole_still_reads_inside() {
        let (v, f) = icosphere(4, 1.0);
        // Drop the triangles around the +z pole (about 0.3% of the surface).
        let kept: Vec<[u32; 3]> = f
            .iter()
            .copied()
            .filter(|t| {
                let z = (v[t[0] as usize][2] + v[t[1] as usize][2] + v[t[2] as usize][2]) / 3.0;
                z < 0.99
            })
            .collect();
        assert!(kept.len() < f.len());
        let w = WindingNumber::new(&v, &kept).unwrap();
        for p in [[0.0; 3], [0.3, 0.2, -0.4], [0.0, 0.0, 0.5], [0.6, 0.0, 0.0]] {
            let x = w.eval(p);
            assert!(x > 0.9 && x < 1.01, "{p:?}: {x}");
            assert!((x - w.eval_exact(p)).abs() < 1e-2);
        }
        for p in [[0.0, 0.0, 1.5], [2.0, 0.0, 0.0], [0.0, 0.0, -1.2]] {
            let x = w.eval(p);
            assert!(x.abs() < 0.1, "{p:?}: {x}");
        }
        // Right at the hole's centre it reads about one half.
        let x = w.eval([0.0, 0.0, 0.995]);
        assert!(x > 0.3 && x < 0.7, "{x}");
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        let v = vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let e = WindingNumber::new(&v, &[[0, 1, 3]]).unwrap_err();
        assert!(e.contains("triangle 0 has vertex index 3"), "{e}");
        let bad = vec![[0.0; 3], [f64::NAN, 0.0, 0.0], [0.0, 1.0, 0.0]];
        assert!(WindingNumber::new(&bad, &[[0, 1, 2]]).is_err());
        assert!(WindingNumber::with_params(&v, &[[0, 1, 2]], 0.0, 2).is_err());
        let empty = WindingNumber::new(&v, &[]).unwrap();
        assert_eq!(empty.eval([0.0; 3]), 0.0);
        // Degenerate (zero-area) triangles are harmless.
        let w = WindingNumber::new(&v, &[[0, 0, 1], [0, 1, 2]]).unwrap();
        assert!(w.eval([0.2, 0.2, 1.0]).is_finite());
    }

    #[test]
    #[ignore]
    fn speed_on_20k_triangles() {
        let (v, f) = icosphere(5, 1.0);
        let w = WindingNumber::new(&v, &f).unwrap();
        let w3 = WindingNumber::with_params(&v, &f, 3.0, 2).unwrap();
        let pts = points(200_000, 1.5, 3);
        let t = std::time::Instant::now();
        let mut s = 0.0;
        for &p in &pts {
            s += w.eval(p);
        }
        let dt = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        for &p in &pts {
            s += w3.eval(p);
        }
        let dt3 = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        for &p in &pts[..200] {
            s += w.eval_exact(p);
        }
        let dt_exact = t.elapsed().as_secs_f64() / 200.0;
        eprintln!(
            "{} triangles: {:.0} evaluations/s fast (beta 2), {:.0}/s (beta 3), {:.0}/s brute \
             force ({s})",
            f.len(),
            pts.len() as f64 / dt,
            pts.len() as f64 / dt3,
            1.0 / dt_exact
        );
    }
}
