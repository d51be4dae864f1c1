//! Pillowing: one layer of hexahedra along the boundary (Mitchell & Tautges, "Pillowing
//! doublets: refining a mesh to ensure that faces share at most one edge", IMR 1995, §3).
//!
//! A polycube map puts the cube's corners and edges where the solid is round: the hexahedra
//! there have two or three faces on the boundary, nearly coplanar, and come out flat or
//! inverted however the vertices are moved, since their boundary faces must stay on the
//! surface. Pillowing gives every boundary quadrilateral a hexahedron of its own: each
//! boundary vertex `v` gets an inner copy `v'`, every old hexahedron is rewired to the
//! copies, and each boundary quadrilateral `a b c d` (outward) becomes the hexahedron
//! `a' b' c' d' a b c d` (its inner copy as the bottom, so the VTK order holds). Afterwards no
//! old hexahedron touches the boundary and each new one has exactly one boundary face, so
//! the relaxation ([`super::relax`]) can square the old corner hexahedra up.
//!
//! The copies start a fraction [`DEPTH`] of the way from `v` to the mean of the centroids
//! of the hexahedra around it: inwards even at corners and edges, where a normal is not
//! defined.

use super::mesh::HEX_FACES;
use super::mesh::{HexMesh, quad_normal};
use crate::geom::vec::{add, dot, scale, sub};

/// How far an inner copy starts from its boundary vertex, as a fraction of the way to the
/// mean centroid of the hexahedra around it.
pub const DEPTH: f64 = 0.5;

/// A copy's way in must make at least this cosine with the inward normal of every boundary
/// quadrilateral at its vertex, or the quadrilaterals' mean normal is added to it.
const INWARD: f64 = 0.1;

/// Two boundary quadrilaterals at a vertex whose normals' cosine is below minus this face
/// opposite ways ([`make_pillowable`]).
pub const OPPOSED: f64 = 0.5;

/// What [`pillow`] did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct PillowReport {
    /// Boundary quadrilaterals, one new hexahedron each.
    pub boundary_quads: usize,
    /// Boundary vertices, one inner copy each.
    pub boundary_vertices: usize,
    /// Hexahedra before pillowing that had two or more faces on the boundary.
    pub multi_face_hexes: usize,
    /// Hexahedra removed first so that the boundary could be pillowed ([`make_pillowable`];
    /// only for a grid's staircase).
    pub removed: usize,
}

/// Adds a layer of hexahedra along the boundary of `mesh` (module docs).
pub fn pillow(mesh: &mut HexMesh) -> PillowReport {
    let nv = mesh.verts.len();
    let boundary = mesh.boundary_quads();
    let mut report = PillowReport {
        boundary_quads: boundary.len(),
        ..PillowReport::default()
    };
    let mut per_hex = vec![0u8; mesh.hexes.len()];
    for &(h, _) in &boundary {
        per_hex[h as usize] += 1;
    }
    report.multi_face_hexes = per_hex.iter().filter(|&&n| n >= 2).count();

    // Inner copies.
    let mut copy = vec![u32::MAX; nv];
    for &(h, f) in &boundary {
        for i in HEX_FACES[f as usize] {
            let v = mesh.hexes[h as usize][i] as usize;
            if copy[v] == u32::MAX {
                copy[v] = (nv + report.boundary_vertices) as u32;
                report.boundary_vertices += 1;
            }
        }
    }
    let mut towards = vec![([0.0f64; 3], 0u32); nv];
    for hex in &mesh.hexes {
        let mut c = [0.0; 3];
        for &v in hex {
            for d in 0..3 {
                c[d] += mesh.verts[v as usize][d] / 8.0;
            }
        }
        for &v in hex {
            let t = &mut towards[v as usize];
            for d in 0..3 {
                t.0[d] += c[d];
            }
            t.1 += 1;
        }
    }
    // The unit normals of each boundary vertex's quadrilaterals (collapsed ones left out).
    let mut normals = mesh.boundary_normals();
    for ns in &mut normals {
        ns.retain(|&n| n != [0.0; 3]);
    }
    let mut inner = vec![[0.0; 3]; report.boundary_vertices];
    for v in 0..nv {
        if copy[v] != u32::MAX {
            let (sum, n) = towards[v];
            let p = mesh.verts[v];
            let mut d = sub(scale(sum, 1.0 / f64::from(n)), p);
            // Where the hexahedra around `v` lie beside one of its quadrilaterals rather than
            // behind it (a saddle of a staircase boundary), the mean centroid is in that
            // quadrilateral's plane and its new hexahedron would be flat: push the copy
            // in, against the quadrilaterals' mean normal, as well.
            let len = dot(d, d).sqrt();
            if normals[v].iter().any(|&nq| dot(d, nq) > -INWARD * len) {
                let m = normals[v].iter().fold([0.0; 3], |a, &b| add(a, b));
                let ml = dot(m, m).sqrt();
                if ml > 0.0 {
                    d = add(d, scale(m, -0.5 * len / ml));
                }
            }
            inner[copy[v] as usize - nv] = add(p, scale(d, DEPTH));
        }
    }
    mesh.verts.extend(inner);
    // The new layer, then the old hexahedra rewired to the copies.
    let layer: Vec<[u32; 8]> = boundary
        .iter()
        .map(|&(h, f)| {
            let q = HEX_FACES[f as usize].map(|i| mesh.hexes[h as usize][i]);
            [
                copy[q[0] as usize],
                copy[q[1] as usize],
                copy[q[2] as usize],
                copy[q[3] as usize],
                q[0],
                q[1],
                q[2],
                q[3],
            ]
        })
        .collect();
    for hex in &mut mesh.hexes {
        for v in hex.iter_mut() {
            if copy[*v as usize] != u32::MAX {
                *v = copy[*v as usize];
            }
        }
    }
    mesh.hexes.extend(layer);
    report
}

/// Removes hexahedra until the boundary can be pillowed: it is a manifold (every boundary
/// edge in exactly two boundary quadrilaterals, the quadrilaterals around every boundary
/// vertex one fan joined through their edges), and no two quadrilaterals at a vertex face
/// opposite ways (cosine below `−`[`OPPOSED`]), since its one inner copy could not lie
/// behind both. A staircase of cubes cut from a grid
/// ([`super::extract`] keeps only the cubes wholly inside) can touch itself along an edge
/// or at a corner, or wrap around a vertex; pillowing such a vertex would give its two sides
/// one inner copy. Of the hexahedra at each such edge or vertex, the one with the fewest face neighbours goes
/// (ties: the lowest index), and the test runs again until nothing is found. Unused vertices
/// are dropped, the others keep their order. Returns the hexahedra removed.
pub fn make_pillowable(mesh: &mut HexMesh) -> usize {
    let mut removed = 0;
    loop {
        let boundary = mesh.boundary_quads();
        let mut faces_free = vec![0u8; mesh.hexes.len()];
        for &(h, _) in &boundary {
            faces_free[h as usize] += 1;
        }
        let quads: Vec<[u32; 4]> = boundary
            .iter()
            .map(|&(h, f)| HEX_FACES[f as usize].map(|i| mesh.hexes[h as usize][i]))
            .collect();
        // Groups of hexahedra of which one must go: at non-manifold edges, then vertices.
        let mut groups: Vec<Vec<u32>> = Vec::new();
        let mut edges: Vec<([u32; 2], u32)> = Vec::with_capacity(4 * quads.len());
        let mut at: Vec<(u32, u32)> = Vec::with_capacity(4 * quads.len());
        for (k, q) in quads.iter().enumerate() {
            for i in 0..4 {
                let (a, b) = (q[i], q[(i + 1) % 4]);
                edges.push(([a.min(b), a.max(b)], boundary[k].0));
                at.push((q[i], k as u32));
            }
        }
        edges.sort_unstable();
        for run in edges.chunk_by(|a, b| a.0 == b.0) {
            if run.len() != 2 {
                groups.push(run.iter().map(|e| e.1).collect());
            }
        }
        at.sort_unstable();
        for run in at.chunk_by(|a, b| a.0 == b.0) {
            let v = run[0].0;
            // Quadrilaterals around `v` joined through the edges at `v` they share.
            let mut parent: Vec<usize> = (0..run.len()).collect();
            let mut by_end: Vec<(u32, usize)> = Vec::with_capacity(2 * run.len());
            for (j, &(_, k)) in run.iter().enumerate() {
                let q = quads[k as usize];
                let i = q.iter().position(|&x| x == v).expect("a corner");
                by_end.push((q[(i + 1) % 4], j));
                by_end.push((q[(i + 3) % 4], j));
            }
            by_end.sort_unstable();
            for pair in by_end.chunk_by(|a, b| a.0 == b.0) {
                for w in pair.windows(2) {
                    let (a, b) = (root(&mut parent, w[0].1), root(&mut parent, w[1].1));
                    parent[a.max(b)] = a.min(b);
                }
            }
            // A vertex whose quadrilaterals face opposite ways (a staircase that wraps
            // around it) has no way in that suits them all: its copy would flatten one.
            let facing = |k: u32| quad_normal(quads[k as usize].map(|w| mesh.verts[w as usize]));
            let opposed = run.iter().enumerate().any(|(j, &(_, a))| {
                let na = facing(a);
                run[j + 1..].iter().any(|&(_, b)| {
                    let nb = facing(b);
                    dot(na, nb) < -OPPOSED * (dot(na, na) * dot(nb, nb)).sqrt()
                })
            });
            if opposed || (0..run.len()).any(|j| root(&mut parent, j) != 0) {
                let mut hs: Vec<u32> = run.iter().map(|&(_, k)| boundary[k as usize].0).collect();
                hs.sort_unstable();
                hs.dedup();
                groups.push(hs);
            }
        }
        if groups.is_empty() {
            break;
        }
        let mut gone = vec![false; mesh.hexes.len()];
        for g in &groups {
            if g.iter().any(|&h| gone[h as usize]) {
                continue;
            }
            let h = *g
                .iter()
                .min_by_key(|&&h| (6 - faces_free[h as usize], h))
                .expect("a group has hexahedra");
            gone[h as usize] = true;
            removed += 1;
        }
        let mut k = 0;
        mesh.hexes.retain(|_| {
            k += 1;
            !gone[k - 1]
        });
    }
    if removed > 0 {
        let mut new_index = vec![u32::MAX; mesh.verts.len()];
        for h in &mesh.hexes {
            for &v in h {
                new_index[v as usize] = 0;
            }
        }
        let mut verts = Vec::new();
        for (v, slot) in new_index.iter_mut().enumerate() {
            if *slot == 0 {
                *slot = verts.len() as u32;
                verts.push(mesh.verts[v]);
            }
        }
        for h in &mut mesh.hexes {
            *h = h.map(|v| new_index[v as usize]);
        }
        mesh.verts = verts;
    }
    removed
}

fn root(parent: &mut [usize], mut i: usize) -> usize {
    while parent[i] != i {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    i
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quality::hex_scaled_jacobian;

    fn cube_grid(n: usize) -> HexMesh {
        let id = |i: usize, j: usize, k: usize| (i + (n + 1) * (j + (n + 1) * k)) as u32;
        let mut m = HexMesh::default();
        for k in 0..=n {
            for j in 0..=n {
                for i in 0..=n {
                    m.verts.push([i as f64, j as f64, k as f64]);
                }
            }
        }
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    m.hexes.push([
                        id(i, j, k),
                        id(i + 1, j, k),
                        id(i + 1, j + 1, k),
                        id(i, j + 1, k),
                        id(i, j, k + 1),
                        id(i + 1, j, k + 1),
                        id(i + 1, j + 1, k + 1),
                        id(i, j + 1, k + 1),
                    ]);
                }
            }
        }
        m
    }

    #[test]
    fn a_pillowed_grid_gains_one_hex_per_boundary_quad_and_none_inverted() {
        let mut m = cube_grid(3);
        let r = pillow(&mut m);
        assert_eq!(r.boundary_quads, 54);
        assert_eq!(r.boundary_vertices, 56);
        // Corner hexes have 3 boundary faces, edge hexes 2: 8 + 12.
        assert_eq!(r.multi_face_hexes, 20);
        assert_eq!(m.hexes.len(), 27 + 54);
        assert_eq!(m.verts.len(), 64 + 56);
        for h in &m.hexes {
            let c = h.map(|v| m.verts[v as usize]);
            assert!(hex_scaled_jacobian(&c) > 0.0, "{h:?}");
        }
        // Every hexahedron now has at most one face on the boundary.
        let again = pillow(&mut m.clone());
        assert_eq!(again.multi_face_hexes, 0);
        assert_eq!(again.boundary_quads, 54);
    }

    #[test]
    fn cubes_touching_along_an_edge_or_at_a_corner_lose_one() {
        // Two cubes of a 2³ grid diagonal across an edge, then across a corner only.
        for keep in [[0usize, 3], [0, 7]] {
            let g = cube_grid(2);
            let mut m = HexMesh {
                verts: g.verts.clone(),
                hexes: keep.iter().map(|&k| g.hexes[k]).collect(),
            };
            assert_eq!(make_pillowable(&mut m), 1, "{keep:?}");
            assert_eq!(m.hexes.len(), 1);
            assert_eq!(m.verts.len(), 8, "unused vertices are dropped");
            // Neither has a face neighbour: the lower index goes, the other is intact.
            assert_eq!(
                m.hexes[0].map(|v| m.verts[v as usize]),
                g.hexes[keep[1]].map(|v| g.verts[v as usize])
            );
        }
        // A manifold staircase (an L of three cubes) is left alone.
        let g = cube_grid(2);
        let mut m = HexMesh {
            verts: g.verts.clone(),
            hexes: vec![g.hexes[0], g.hexes[1], g.hexes[2]],
        };
        assert_eq!(make_pillowable(&mut m), 0);
        assert_eq!(m.verts.len(), 27);
    }

    #[test]
    fn a_saddle_vertex_gets_a_copy_that_makes_no_flat_hexahedron() {
        // Three cubes of a 2³ grid around one axis-aligned L and one above: every pillow
        // hexahedron comes out with a positive scaled Jacobian.
        let g = cube_grid(2);
        // Cubes (i, j, k) = (0,0,0), (1,0,0), (0,1,0), (0,0,1): index i + 2j + 4k.
        let mut m = HexMesh {
            verts: g.verts.clone(),
            hexes: [0usize, 1, 2, 4].iter().map(|&k| g.hexes[k]).collect(),
        };
        assert_eq!(make_pillowable(&mut m), 0);
        pillow(&mut m);
        for h in &m.hexes {
            let c = h.map(|v| m.verts[v as usize]);
            assert!(
                hex_scaled_jacobian(&c) > 0.05,
                "{h:?}: {}",
                hex_scaled_jacobian(&c)
            );
        }
    }

    #[test]
    fn the_volume_is_still_filled_exactly() {
        let mut m = cube_grid(2);
        pillow(&mut m);
        let vol: f64 = m
            .hexes
            .iter()
            .map(|h| crate::quality::hex_volume(&h.map(|v| m.verts[v as usize])))
            .sum();
        assert!((vol - 8.0).abs() < 1e-9, "{vol}");
    }
}
