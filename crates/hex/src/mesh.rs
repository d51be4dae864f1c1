//! The volume meshes the hex stage reads and writes: tetrahedra in, hexahedra out.
//!
//! # Conventions (stated once)
//!
//! * Coordinates are `f64` in input units; vertex indices are 0-based `u32`.
//! * A tetrahedron `[a, b, c, d]` is positively oriented when
//!   `det(b − a, c − a, d − a) > 0` (the right-hand rule: `d` lies on the side of triangle
//!   `a b c` that its counter-clockwise normal points to). MEDIT, gmsh and VTK store
//!   tetrahedra the same way.
//! * A hexahedron `[v0 … v7]` follows VTK's `VTK_HEXAHEDRON` (12), which MEDIT's `Hexahedra`
//!   and gmsh's element type 5 share: `v0 v1 v2 v3` is the bottom face, counter-clockwise
//!   seen from the top, and `v4 … v7` the top face above them (`v4` over `v0`). For the unit
//!   cube, `v0 = (0,0,0)`, `v1 = (1,0,0)`, `v2 = (1,1,0)`, `v3 = (0,1,0)`, `v4 = (0,0,1)`,
//!   `v5 = (1,0,1)`, `v6 = (1,1,1)`, `v7 = (0,1,1)`; its scaled Jacobian is 1 everywhere.

/// An orthonormal frame: `frame[k]` is the k-th axis in space (the direction in which the
/// parameter `u`, `v` or `w` grows), a unit vector; right-handed (`frame[0] × frame[1] =
/// frame[2]`). A frame field holds one per tetrahedron.
pub type Frame = [[f64; 3]; 3];

/// The 6 faces of a hexahedron, each counter-clockwise seen from outside (outward normal by
/// the right-hand rule), in Verdict's order: `y = 0`, `x = 1`, `y = 1`, `x = 0`, bottom, top.
pub const HEX_FACES: [[usize; 4]; 6] = [
    [0, 1, 5, 4],
    [1, 2, 6, 5],
    [2, 3, 7, 6],
    [3, 0, 4, 7],
    [3, 2, 1, 0],
    [4, 5, 6, 7],
];

/// A tetrahedral mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TetMesh {
    /// Vertex positions, input units.
    pub verts: Vec<[f64; 3]>,
    /// Tetrahedra as vertex indices, positively oriented once checked.
    pub tets: Vec<[u32; 4]>,
}

/// A hexahedral mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HexMesh {
    /// Vertex positions, input units.
    pub verts: Vec<[f64; 3]>,
    /// Hexahedra as vertex indices in VTK order (see the module docs).
    pub hexes: Vec<[u32; 8]>,
}

/// Signed volume of the tetrahedron `a b c d`: `det(b − a, c − a, d − a) / 6`.
pub fn tet_volume(a: [f64; 3], b: [f64; 3], c: [f64; 3], d: [f64; 3]) -> f64 {
    let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let w = [d[0] - a[0], d[1] - a[1], d[2] - a[2]];
    (u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
        + u[2] * (v[0] * w[1] - v[1] * w[0]))
        / 6.0
}

impl TetMesh {
    /// The box `[0, n₀h] × [0, n₁h] × [0, n₂h]` as `n₀n₁n₂` cubes of edge `h`, each split into
    /// six tetrahedra around its main diagonal (Kuhn's subdivision: conforming between
    /// cubes), positively oriented.
    pub fn grid_box(n: [usize; 3], h: f64) -> TetMesh {
        let id = |i: usize, j: usize, k: usize| (i + (n[0] + 1) * (j + (n[1] + 1) * k)) as u32;
        let mut verts = Vec::with_capacity((n[0] + 1) * (n[1] + 1) * (n[2] + 1));
        for k in 0..=n[2] {
            for j in 0..=n[1] {
                for i in 0..=n[0] {
                    verts.push([i as f64 * h, j as f64 * h, k as f64 * h]);
                }
            }
        }
        let perms = [
            [0, 1, 2],
            [0, 2, 1],
            [1, 0, 2],
            [1, 2, 0],
            [2, 0, 1],
            [2, 1, 0],
        ];
        let mut tets = Vec::with_capacity(6 * n[0] * n[1] * n[2]);
        for k in 0..n[2] {
            for j in 0..n[1] {
                for i in 0..n[0] {
                    for p in perms {
                        let mut at = [i, j, k];
                        let mut tet = [id(i, j, k); 4];
                        for (s, &axis) in p.iter().enumerate() {
                            at[axis] += 1;
                            tet[s + 1] = id(at[0], at[1], at[2]);
                        }
                        let c = tet.map(|v| verts[v as usize]);
                        if tet_volume(c[0], c[1], c[2], c[3]) < 0.0 {
                            tet.swap(2, 3);
                        }
                        tets.push(tet);
                    }
                }
            }
        }
        TetMesh { verts, tets }
    }

    /// The four corners of tetrahedron `t`.
    pub fn corners(&self, t: usize) -> [[f64; 3]; 4] {
        self.tets[t].map(|i| self.verts[i as usize])
    }

    /// Signed volume of tetrahedron `t`.
    pub fn volume(&self, t: usize) -> f64 {
        let [a, b, c, d] = self.corners(t);
        tet_volume(a, b, c, d)
    }
}

/// The normal of quadrilateral `x` (corners in order), not normalised: the cross product of
/// its diagonals, twice its area for a planar one, pointing the way the order turns.
pub fn quad_normal(x: [[f64; 3]; 4]) -> [f64; 3] {
    use crate::geom::vec::{cross, sub};
    cross(sub(x[2], x[0]), sub(x[3], x[1]))
}

impl HexMesh {
    /// Per vertex, the unit outward normals ([`quad_normal`]) of the boundary quadrilaterals
    /// at it, in [`HexMesh::boundary_quads`]' order; a zero vector for a collapsed one. Empty
    /// for a vertex off the boundary.
    pub fn boundary_normals(&self) -> Vec<Vec<[f64; 3]>> {
        use crate::geom::vec::{norm, scale};
        let mut normals = vec![Vec::new(); self.verts.len()];
        for (h, f) in self.boundary_quads() {
            let q = HEX_FACES[f as usize].map(|i| self.hexes[h as usize][i]);
            let n = quad_normal(q.map(|v| self.verts[v as usize]));
            let len = norm(n);
            let n = if len > 0.0 { scale(n, 1.0 / len) } else { n };
            for v in q {
                normals[v as usize].push(n);
            }
        }
        normals
    }

    /// The boundary quadrilaterals (faces of exactly one hexahedron) as (hexahedron, local
    /// face of [`HEX_FACES`], outward), sorted.
    pub fn boundary_quads(&self) -> Vec<(u32, u8)> {
        let mut faces: Vec<([u32; 4], u32, u8)> = Vec::with_capacity(6 * self.hexes.len());
        for (h, hex) in self.hexes.iter().enumerate() {
            for (f, face) in HEX_FACES.iter().enumerate() {
                let mut key = face.map(|i| hex[i]);
                key.sort_unstable();
                faces.push((key, h as u32, f as u8));
            }
        }
        faces.sort_unstable();
        let mut out = Vec::new();
        for run in faces.chunk_by(|a, b| a.0 == b.0) {
            if let [(_, h, f)] = run {
                out.push((*h, *f));
            }
        }
        out.sort_unstable();
        out
    }
}

impl TetMesh {
    /// Splits each of `edges` at its midpoint: every tetrahedron around the edge becomes two
    /// (the edge's ends replaced by the midpoint in turn, which keeps the orientation), so the
    /// mesh stays conforming. Edges are split one after another; an edge no tetrahedron has
    /// any more (it cannot happen for distinct edges of a conforming mesh) is skipped. Returns
    /// the number of new vertices.
    pub fn split_edges(&mut self, edges: &[[u32; 2]]) -> usize {
        let mut at: Vec<Vec<u32>> = vec![Vec::new(); self.verts.len()];
        for (t, tet) in self.tets.iter().enumerate() {
            for &v in tet {
                at[v as usize].push(t as u32);
            }
        }
        let mut added = 0;
        for &[a, b] in edges {
            let around: Vec<u32> = at[a as usize]
                .iter()
                .copied()
                .filter(|&t| self.tets[t as usize].contains(&b))
                .collect();
            if around.is_empty() {
                continue;
            }
            let (pa, pb) = (self.verts[a as usize], self.verts[b as usize]);
            let m = self.verts.len() as u32;
            self.verts.push([0, 1, 2].map(|k| 0.5 * (pa[k] + pb[k])));
            at.push(Vec::new());
            added += 1;
            for t in around {
                let tet = self.tets[t as usize];
                let lower = tet.map(|v| if v == b { m } else { v });
                let upper = tet.map(|v| if v == a { m } else { v });
                let u = self.tets.len() as u32;
                self.tets[t as usize] = lower;
                self.tets.push(upper);
                at[b as usize].retain(|&x| x != t);
                at[b as usize].push(u);
                at[m as usize].extend([t, u]);
                for v in tet {
                    if v != a && v != b {
                        at[v as usize].push(u);
                    }
                }
            }
        }
        added
    }
}

/// No neighbour (a boundary face) in [`tet_neighbours`].
pub const NO_TET: u32 = u32::MAX;

/// The face of a tetrahedron opposite its local vertex `i`, as local vertex indices, ordered
/// so that its counter-clockwise normal points out of a positively oriented tetrahedron.
pub const FACE_OPPOSITE: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];

/// A face shared by more than two tetrahedra: its sorted vertices and the tetrahedra on it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NonManifoldFace {
    /// The face's vertices, ascending.
    pub vertices: [u32; 3],
    /// The tetrahedra that have it as a face.
    pub tets: Vec<u32>,
}

/// For each tetrahedron and each local vertex `i`, the tetrahedron across the face opposite
/// `i` ([`FACE_OPPOSITE`]), or [`NO_TET`] on the boundary. A face shared by more than two
/// tetrahedra (non-manifold) is an error naming it.
pub fn tet_neighbours(m: &TetMesh) -> Result<Vec<[u32; 4]>, NonManifoldFace> {
    let mut faces: Vec<([u32; 3], u32, u8)> = Vec::with_capacity(4 * m.tets.len());
    for (t, tet) in m.tets.iter().enumerate() {
        for (i, f) in FACE_OPPOSITE.iter().enumerate() {
            let mut k = f.map(|j| tet[j]);
            k.sort_unstable();
            faces.push((k, t as u32, i as u8));
        }
    }
    faces.sort_unstable();
    let mut nb = vec![[NO_TET; 4]; m.tets.len()];
    let mut s = 0;
    while s < faces.len() {
        let mut e = s + 1;
        while e < faces.len() && faces[e].0 == faces[s].0 {
            e += 1;
        }
        match e - s {
            1 => {}
            2 => {
                let (a, b) = (faces[s], faces[s + 1]);
                nb[a.1 as usize][a.2 as usize] = b.1;
                nb[b.1 as usize][b.2 as usize] = a.1;
            }
            _ => {
                return Err(NonManifoldFace {
                    vertices: faces[s].0,
                    tets: faces[s..e].iter().map(|f| f.1).collect(),
                });
            }
        }
        s = e;
    }
    Ok(nb)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reference_tet_has_volume_one_sixth() {
        let m = TetMesh {
            verts: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            tets: vec![[0, 1, 2, 3]],
        };
        assert!((m.volume(0) - 1.0 / 6.0).abs() < 1e-15);
    }

    #[test]
    fn faces_opposite_point_outwards_and_neighbours_pair_up() {
        // Two tets sharing face 1 2 3.
        let m = TetMesh {
            verts: vec![
                [0.0; 3],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
                [1.0, 1.0, 1.0],
            ],
            tets: vec![[0, 1, 2, 3], [4, 1, 3, 2]],
        };
        assert!(m.volume(0) > 0.0 && m.volume(1) > 0.0);
        for t in 0..2 {
            let c = m.corners(t);
            for (i, f) in FACE_OPPOSITE.iter().enumerate() {
                // The opposite vertex lies behind the face's outward normal.
                assert!(tet_volume(c[f[0]], c[f[1]], c[f[2]], c[i]) < 0.0);
            }
        }
        let nb = tet_neighbours(&m).unwrap();
        assert_eq!(nb[0], [1, NO_TET, NO_TET, NO_TET]);
        assert_eq!(nb[1], [0, NO_TET, NO_TET, NO_TET]);
    }

    #[test]
    fn splitting_edges_keeps_volume_orientation_and_conformity() {
        let mut m = TetMesh::grid_box([2, 2, 2], 1.0);
        let total: f64 = (0..m.tets.len()).map(|t| m.volume(t)).sum();
        let n = m.tets.len();
        // The main diagonal of the first cube (in all six of its tetrahedra), then an edge
        // made by that split.
        let d = [0, 13];
        let mid = m.verts.len() as u32;
        assert_eq!(m.split_edges(&[d, [0, mid]]), 2);
        assert_eq!(m.tets.len(), n + 12);
        let after: f64 = (0..m.tets.len()).map(|t| m.volume(t)).sum();
        assert!((after - total).abs() < 1e-12);
        assert!((0..m.tets.len()).all(|t| m.volume(t) > 0.0));
        assert!(m.tets.iter().all(|t| !(t.contains(&0) && t.contains(&13))));
        assert!(crate::topology::check_tets(&m).is_ok());
    }
}
