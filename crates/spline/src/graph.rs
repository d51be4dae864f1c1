//! The neighbourhood graph of a patch, the input of the spring model (Greiner & Hormann 1997,
//! §4): which points are joined by a spring, and which points lie on the patch's boundary
//! (held fixed in the parameter plane).
//!
//! # From triangles
//!
//! [`Graph::from_triangles`]: the edges are the triangles' edges. An edge used by exactly one
//! triangle is a boundary edge and both its ends are boundary vertices; an edge used by more
//! than two triangles is non-manifold (counted in [`Graph::non_manifold_edges`], still a
//! spring). A triangulation without any boundary edge is closed and cannot be mapped onto a
//! disc: that is an error that tells to fit it in patches (`--patches`). A vertex used by no
//! triangle gets no edge and is not a boundary vertex.
//!
//! # From k nearest neighbours
//!
//! [`Graph::from_knn`]: each point is joined to its `k` nearest other points (exact, a k-d
//! tree; ties at equal distance broken by the smaller index), and the relation is symmetrised
//! (an edge when either end lists the other). A point is on the boundary by the angle-gap
//! criterion: its [`BOUNDARY_K`] nearest neighbours (at least `k`) are projected into its
//! tangent plane (the plane fitted by principal components to the point and those neighbours)
//! and sorted by angle around it; when the largest angle between consecutive neighbours
//! (cyclically) exceeds `π/2`, no neighbour lies on one side and the point is on the boundary.
//! An interior point of a regularly sampled surface sees gaps near `2π/n`, an edge point one
//! near `π`, a corner one near `3π/2`.
//!
//! Why more neighbours than `k` for the boundary: on randomly (Poisson) sampled surfaces the
//! `n` neighbours' angles are independent and uniform, and the largest of their gaps exceeds
//! `π/2` with probability `Σ_j (−1)^{j+1} C(n, j) (1 − j/4)^{n−1}`: 66% of the points for
//! `n = 10`, 0.05% for `n = 40`. The price is a boundary band: a point within about
//! `0.7 √(n/π)` sample spacings of a straight boundary (2.5 for `n = 40`) sees the gap too, and
//! is fixed at its projection by the parameterisation. A flagged point none of whose `k`
//! nearest neighbours is flagged is dropped (a boundary is a curve, an isolated flag is
//! sampling noise). A closed surface (a sphere) then has no boundary point: the same error as
//! above.
//!
//! Both constructions are deterministic: they depend on the points' order and values only.

use std::num::NonZero;
use std::path::Path;

use kiddo::SquaredEuclidean;
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use rayon::prelude::*;

use crate::error::{Error, Result, Setting};
use crate::geom::vec::dot;

/// The number of neighbours [`Graph::from_knn`] is meant to be called with by default.
pub const DEFAULT_K: usize = 10;

/// The number of nearest neighbours the angle-gap criterion looks at (module docs).
pub const BOUNDARY_K: usize = 40;

/// The boundary threshold of the angle-gap criterion: a gap wider than this (radians) between
/// consecutive neighbours around a point makes it a boundary point.
pub const BOUNDARY_GAP: f64 = std::f64::consts::FRAC_PI_2;

/// The neighbourhood graph of a patch's points.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Graph {
    /// Springs as vertex pairs `[i, j]` with `i < j`, sorted, without repeats.
    pub edges: Vec<[u32; 2]>,
    /// Per vertex: true on the patch's boundary.
    pub boundary: Vec<bool>,
    /// The triangles the graph was built from (empty for a k-nearest-neighbour graph), for the
    /// fold-over count of the parameterisation.
    pub triangles: Vec<[u32; 3]>,
    /// Edges used by more than two triangles (0 for a k-nearest-neighbour graph).
    pub non_manifold_edges: usize,
}

/// The message of a patch without boundary.
fn not_a_disc(what: &str) -> String {
    format!(
        "{what} has no boundary: a closed surface is not a disc and cannot be fitted by one \
         surface; use {} to fit it in patches",
        Setting::Patches
    )
}

impl Graph {
    /// The number of vertices.
    pub fn len(&self) -> usize {
        self.boundary.len()
    }

    /// True when the graph has no vertex.
    pub fn is_empty(&self) -> bool {
        self.boundary.is_empty()
    }

    /// The graph of a triangulation of `n_vertices` vertices read from `source` (named in
    /// errors). Errors: an index not below `n_vertices`, or no boundary edge (closed).
    pub fn from_triangles(
        source: &Path,
        n_vertices: usize,
        triangles: &[[u32; 3]],
    ) -> Result<Graph> {
        if let Some((t, v)) = triangles.iter().enumerate().find_map(|(t, tri)| {
            tri.iter()
                .find(|&&v| v as usize >= n_vertices)
                .map(|&v| (t, v))
        }) {
            return Err(Error::input(
                source,
                format!("triangle {t}: vertex index {v} is out of range: {n_vertices} vertices"),
            ));
        }
        let mut half: Vec<[u32; 2]> = Vec::with_capacity(triangles.len() * 3);
        for tri in triangles {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                if a != b {
                    half.push([a.min(b), a.max(b)]);
                }
            }
        }
        half.sort_unstable();
        let mut edges = Vec::with_capacity(half.len() / 2 + 1);
        let mut boundary = vec![false; n_vertices];
        let mut non_manifold_edges = 0;
        let mut any_boundary = false;
        for run in half.chunk_by(|a, b| a == b) {
            let e = run[0];
            edges.push(e);
            match run.len() {
                1 => {
                    boundary[e[0] as usize] = true;
                    boundary[e[1] as usize] = true;
                    any_boundary = true;
                }
                2 => {}
                _ => non_manifold_edges += 1,
            }
        }
        if !any_boundary {
            return Err(Error::input(
                source,
                not_a_disc(&format!(
                    "the triangulation ({} triangles)",
                    triangles.len()
                )),
            ));
        }
        Ok(Graph {
            edges,
            boundary,
            triangles: triangles.to_vec(),
            non_manifold_edges,
        })
    }

    /// The symmetrised `k`-nearest-neighbour graph of `points` read from `source` (named in
    /// errors), boundary by the angle gap ([`BOUNDARY_GAP`]). Errors: fewer than `k + 1`
    /// points, `k < 3`, a coordinate that is not finite, or no boundary point (closed).
    pub fn from_knn(source: &Path, points: &[[f64; 3]], k: usize) -> Result<Graph> {
        if k < 3 {
            return Err(Error::Usage(format!(
                "a neighbourhood graph needs k >= 3 neighbours, got {k}"
            )));
        }
        if points.len() <= k {
            return Err(Error::input(
                source,
                format!(
                    "{} points are too few for a graph of {k} nearest neighbours (at least {})",
                    points.len(),
                    k + 1
                ),
            ));
        }
        if u32::try_from(points.len()).is_err() {
            return Err(Error::input(
                source,
                format!("{} points: a patch holds at most 2^32 - 1", points.len()),
            ));
        }
        if let Some(i) = points.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
            return Err(Error::input(
                source,
                format!("point {i} has a coordinate that is not finite"),
            ));
        }
        let tree: ImmutableKdTree<f64, u32, 3, 32> = ImmutableKdTree::new_from_slice(points);
        let kb = BOUNDARY_K.max(k).min(points.len() - 1);
        let neighbours: Vec<(Vec<u32>, bool)> = (0..points.len())
            .into_par_iter()
            .map(|i| {
                let mut nb = nearest(&tree, points, i, kb);
                let b = angle_gap(points, i, &nb) > BOUNDARY_GAP;
                nb.truncate(k);
                (nb, b)
            })
            .collect();
        let mut pairs: Vec<[u32; 2]> = Vec::with_capacity(points.len() * k);
        let mut boundary = Vec::with_capacity(points.len());
        for (i, (nb, b)) in neighbours.iter().enumerate() {
            pairs.extend(nb.iter().map(|&j| [(i as u32).min(j), (i as u32).max(j)]));
            boundary.push(*b && nb.iter().any(|&j| neighbours[j as usize].1));
        }
        drop(neighbours);
        pairs.par_sort_unstable();
        pairs.dedup();
        if !boundary.contains(&true) {
            return Err(Error::input(
                source,
                not_a_disc(&format!(
                    "the point set ({} points, {k} nearest neighbours)",
                    points.len()
                )),
            ));
        }
        Ok(Graph {
            edges: pairs,
            boundary,
            triangles: Vec::new(),
            non_manifold_edges: 0,
        })
    }
}

/// The `k` nearest other points of every point (exact, ties by the smaller index), as one
/// array of `points.len() × k` indices; fewer than `k` other points repeat none and leave the
/// row short, filled with `u32::MAX`. Points must be finite and fewer than `2^32 - 1`.
pub fn knn(points: &[[f64; 3]], k: usize) -> Vec<u32> {
    if points.is_empty() || k == 0 {
        return Vec::new();
    }
    let tree: ImmutableKdTree<f64, u32, 3, 32> = ImmutableKdTree::new_from_slice(points);
    let rows: Vec<Vec<u32>> = (0..points.len())
        .into_par_iter()
        .map(|i| {
            let mut nb = nearest(&tree, points, i, k.min(points.len() - 1));
            nb.resize(k, u32::MAX);
            nb
        })
        .collect();
    rows.concat()
}

/// The `k` nearest other points of point `i`, nearest first, ties by index.
fn nearest(
    tree: &ImmutableKdTree<f64, u32, 3, 32>,
    points: &[[f64; 3]],
    i: usize,
    k: usize,
) -> Vec<u32> {
    let want = NonZero::new(k + 1).unwrap_or(NonZero::<usize>::MIN);
    let mut found: Vec<(f64, u32)> = tree
        .nearest_n::<SquaredEuclidean>(&points[i], want)
        .into_iter()
        .filter(|n| n.item as usize != i)
        .map(|n| (n.distance, n.item))
        .collect();
    found.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    found.truncate(k);
    found.into_iter().map(|(_, j)| j).collect()
}

/// The largest angle (radians) between cyclically consecutive neighbours of point `i` seen in
/// its tangent plane; `2π` with fewer than two usable neighbours.
fn angle_gap(points: &[[f64; 3]], i: usize, nb: &[u32]) -> f64 {
    let p = points[i];
    let frame = super::frame::pca_frame(
        std::iter::once(p).chain(nb.iter().map(|&j| points[j as usize])),
        nb.len() + 1,
    );
    let mut angles: Vec<f64> = nb
        .iter()
        .filter_map(|&j| {
            let q = points[j as usize];
            let d = [q[0] - p[0], q[1] - p[1], q[2] - p[2]];
            let x = dot(d, frame.axes[0]);
            let y = dot(d, frame.axes[1]);
            (x != 0.0 || y != 0.0).then(|| y.atan2(x))
        })
        .collect();
    if angles.len() < 2 {
        return std::f64::consts::TAU;
    }
    angles.sort_unstable_by(f64::total_cmp);
    let wrap = angles[0] + std::f64::consts::TAU - angles[angles.len() - 1];
    angles.windows(2).map(|w| w[1] - w[0]).fold(wrap, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn src() -> &'static Path {
        Path::new("patch.ply")
    }

    /// A `w × h` grid of unit spacing in the plane z = 0, two triangles per cell.
    pub(crate) fn grid_triangles(w: u32, h: u32) -> Vec<[u32; 3]> {
        let mut t = Vec::new();
        for y in 0..h - 1 {
            for x in 0..w - 1 {
                let a = y * w + x;
                t.push([a, a + 1, a + w + 1]);
                t.push([a, a + w + 1, a + w]);
            }
        }
        t
    }

    #[test]
    fn triangle_graph_edges_and_boundary_ring() {
        let (w, h) = (5u32, 4u32);
        let g = Graph::from_triangles(src(), (w * h) as usize, &grid_triangles(w, h)).unwrap();
        // Edges of a triangulated grid: horizontal, vertical, one diagonal per cell.
        let want = ((w - 1) * h + w * (h - 1) + (w - 1) * (h - 1)) as usize;
        assert_eq!(g.edges.len(), want);
        assert!(g.edges.windows(2).all(|e| e[0] < e[1]));
        assert!(g.edges.iter().all(|e| e[0] < e[1]));
        for y in 0..h {
            for x in 0..w {
                let ring = x == 0 || y == 0 || x == w - 1 || y == h - 1;
                assert_eq!(g.boundary[(y * w + x) as usize], ring, "{x} {y}");
            }
        }
        assert_eq!(g.non_manifold_edges, 0);
    }

    #[test]
    fn closed_triangulation_is_not_a_disc() {
        let oct = scanflow_formats::mesh::Mesh::octahedron();
        let t = oct.triangles;
        assert_eq!(oct.vertices.len(), 6);
        let e = Graph::from_triangles(src(), 6, &t).unwrap_err().to_string();
        assert!(
            e.contains("patch.ply") && e.contains("no boundary") && e.contains("`patches`"),
            "{e}"
        );
        let e = Graph::from_triangles(src(), 5, &t).unwrap_err().to_string();
        assert!(
            e.contains("triangle 4: vertex index 5 is out of range"),
            "{e}"
        );
    }

    #[test]
    fn non_manifold_edges_are_counted() {
        // Three triangles on the edge (0, 1).
        let t = [[0, 1, 2], [1, 0, 3], [0, 1, 4]];
        let g = Graph::from_triangles(src(), 5, &t).unwrap();
        assert_eq!(g.non_manifold_edges, 1);
        assert!(g.boundary.iter().all(|&b| b));
        assert_eq!(g.edges.len(), 7);
    }

    #[test]
    fn knn_grid_boundary_is_a_band_along_the_rim() {
        let (w, h) = (17usize, 15usize);
        // Tilted plane, so the tangent frame is not the coordinate frame.
        let pts: Vec<[f64; 3]> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                [x, 0.6 * y, 0.8 * y + 0.1 * x]
            })
            .collect();
        let g = Graph::from_knn(src(), &pts, 8).unwrap();
        for i in 0..w * h {
            let (x, y) = (i % w, i / w);
            let rim = x.min(y).min(w - 1 - x).min(h - 1 - y);
            if rim == 0 {
                assert!(g.boundary[i], "{x} {y}");
            }
            if rim >= 3 {
                assert!(!g.boundary[i], "{x} {y}");
            }
        }
        assert!(g.edges.windows(2).all(|e| e[0] < e[1]));
        assert!(g.edges.iter().all(|e| e[0] < e[1]));
        // Symmetrised: every point keeps its 8 nearest at least.
        let mut deg = vec![0; w * h];
        for e in &g.edges {
            deg[e[0] as usize] += 1;
            deg[e[1] as usize] += 1;
        }
        assert!(deg.iter().all(|&d| d >= 8), "{deg:?}");
    }

    /// `n` points uniformly at random on the unit sphere (fixed seed): Poisson sampling, the
    /// hard case of the angle gap.
    pub(crate) fn sphere(n: usize) -> Vec<[f64; 3]> {
        let mut s = 0x2545_F491_4F6C_DD1Du64;
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        (0..n)
            .map(|_| {
                let z = 2.0 * next() - 1.0;
                let t = std::f64::consts::TAU * next();
                let r = (1.0 - z * z).sqrt();
                [r * t.cos(), r * t.sin(), z]
            })
            .collect()
    }

    #[test]
    fn knn_sphere_has_no_boundary() {
        let pts = sphere(5000);
        let e = Graph::from_knn(src(), &pts, DEFAULT_K)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("patch.ply") && e.contains("no boundary") && e.contains("`patches`"),
            "{e}"
        );
    }

    #[test]
    fn knn_hemisphere_has_a_boundary_near_the_rim_only() {
        let pts: Vec<[f64; 3]> = sphere(4000).into_iter().filter(|p| p[2] > 0.0).collect();
        let g = Graph::from_knn(src(), &pts, DEFAULT_K).unwrap();
        let n_b = g.boundary.iter().filter(|&&b| b).count();
        assert!(n_b > 20, "{n_b}");
        for (p, &b) in pts.iter().zip(&g.boundary) {
            if b {
                assert!(p[2] < 0.25, "a boundary point far from the rim: {p:?}");
            }
        }
    }

    #[test]
    fn knn_bad_input_is_an_error() {
        let pts = sphere(20);
        assert!(Graph::from_knn(src(), &pts[..5], 8).is_err());
        assert!(Graph::from_knn(src(), &pts, 2).is_err());
        let mut bad = pts.clone();
        bad[3][1] = f64::NAN;
        let e = Graph::from_knn(src(), &bad, 8).unwrap_err().to_string();
        assert!(e.contains("point 3"), "{e}");
    }
}
