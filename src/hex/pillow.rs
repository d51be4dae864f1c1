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

use super::mesh::HexMesh;
use super::quality::HEX_FACES;

/// How far an inner copy starts from its boundary vertex, as a fraction of the way to the
/// mean centroid of the hexahedra around it.
pub const DEPTH: f64 = 0.5;

/// What [`pillow`] did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct PillowReport {
    /// Boundary quadrilaterals, one new hexahedron each.
    pub boundary_quads: usize,
    /// Boundary vertices, one inner copy each.
    pub boundary_vertices: usize,
    /// Hexahedra before pillowing that had two or more faces on the boundary.
    pub multi_face_hexes: usize,
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
    let mut inner = vec![[0.0; 3]; report.boundary_vertices];
    for v in 0..nv {
        if copy[v] != u32::MAX {
            let (sum, n) = towards[v];
            let p = mesh.verts[v];
            inner[copy[v] as usize - nv] =
                std::array::from_fn(|d| p[d] + DEPTH * (sum[d] / f64::from(n) - p[d]));
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hex::quality::hex_scaled_jacobian;

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
    fn the_volume_is_still_filled_exactly() {
        let mut m = cube_grid(2);
        pillow(&mut m);
        let vol: f64 = m
            .hexes
            .iter()
            .map(|h| crate::hex::quality::hex_volume(&h.map(|v| m.verts[v as usize])))
            .sum();
        assert!((vol - 8.0).abs() < 1e-9, "{vol}");
    }
}
