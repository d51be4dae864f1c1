//! Check 7 of the module docs of [`super`]: the boundary triangles form a closed 2-manifold
//! (every boundary edge in two of them, one fan around every boundary vertex), and its
//! connected components with their Euler characteristic and genus.

use super::checks::face_of;
use super::{BoundarySurface, TetError, find, union};
use crate::mesh::{NO_TET, TetMesh};

/// Boundary surface: a closed 2-manifold. Returns the boundary faces (tetrahedron, corner
/// opposite), which vertices lie on it and its components.
#[allow(clippy::type_complexity)]
pub(super) fn boundary_surfaces(
    mesh: &TetMesh,
    neighbours: &[[u32; 4]],
) -> Result<(Vec<(u32, u8)>, Vec<bool>, Vec<BoundarySurface>), TetError> {
    let nv = mesh.verts.len();
    let mut boundary = Vec::new();
    for (t, nb) in neighbours.iter().enumerate() {
        for (i, &n) in nb.iter().enumerate() {
            if n == NO_TET {
                boundary.push((t as u32, i as u8));
            }
        }
    }
    let tris: Vec<[u32; 3]> = boundary
        .iter()
        .map(|&(t, i)| face_of(mesh, t as usize, i as usize))
        .collect();
    let mut bedges: Vec<(u32, u32, u32)> = Vec::with_capacity(3 * tris.len());
    for (k, tri) in tris.iter().enumerate() {
        for x in 0..3 {
            let (a, b) = (tri[x], tri[(x + 1) % 3]);
            bedges.push((a.min(b), a.max(b), k as u32));
        }
    }
    bedges.sort_unstable();
    let mut tri_parent: Vec<u32> = (0..tris.len() as u32).collect();
    let mut s = 0;
    while s < bedges.len() {
        let mut e = s + 1;
        while e < bedges.len() && bedges[e].0 == bedges[s].0 && bedges[e].1 == bedges[s].1 {
            e += 1;
        }
        if e - s != 2 {
            return Err(TetError::NonManifoldBoundaryEdge {
                edge: [bedges[s].0, bedges[s].1],
                triangles: bedges[s..e].iter().map(|x| tris[x.2 as usize]).collect(),
            });
        }
        union(&mut tri_parent, bedges[s].2, bedges[s + 1].2);
        s = e;
    }
    // Fans: corners (3k + x) joined across the boundary edges at their vertex.
    let mut spokes: Vec<(u32, u32, u32)> = Vec::with_capacity(6 * tris.len());
    for (k, tri) in tris.iter().enumerate() {
        for x in 0..3 {
            let corner = (3 * k + x) as u32;
            spokes.push((tri[x], tri[(x + 1) % 3], corner));
            spokes.push((tri[x], tri[(x + 2) % 3], corner));
        }
    }
    spokes.sort_unstable();
    let mut corner_parent: Vec<u32> = (0..3 * tris.len() as u32).collect();
    for pair in spokes.chunks_exact(2) {
        debug_assert_eq!((pair[0].0, pair[0].1), (pair[1].0, pair[1].1));
        union(&mut corner_parent, pair[0].2, pair[1].2);
    }
    let mut fans: Vec<(u32, u32)> = Vec::with_capacity(3 * tris.len());
    for (k, tri) in tris.iter().enumerate() {
        for x in 0..3 {
            fans.push((tri[x], find(&mut corner_parent, (3 * k + x) as u32)));
        }
    }
    fans.sort_unstable();
    fans.dedup();
    let mut vertex_on_boundary = vec![false; nv];
    let mut s = 0;
    while s < fans.len() {
        let mut e = s + 1;
        while e < fans.len() && fans[e].0 == fans[s].0 {
            e += 1;
        }
        if e - s > 1 {
            return Err(TetError::NonManifoldVertex {
                vertex: fans[s].0,
                fans: e - s,
            });
        }
        vertex_on_boundary[fans[s].0 as usize] = true;
        s = e;
    }
    // Boundary components: F, E = 3F/2, V (each boundary vertex in one component).
    let mut comp_of_root = std::collections::HashMap::new();
    let mut boundary_surfaces: Vec<BoundarySurface> = Vec::new();
    let mut tri_comp = vec![0usize; tris.len()];
    for k in 0..tris.len() {
        let r = find(&mut tri_parent, k as u32);
        let c = *comp_of_root.entry(r).or_insert_with(|| {
            boundary_surfaces.push(BoundarySurface {
                triangles: 0,
                edges: 0,
                vertices: 0,
                euler_characteristic: 0,
                genus: 0,
                first_triangle: k,
            });
            boundary_surfaces.len() - 1
        });
        tri_comp[k] = c;
        boundary_surfaces[c].triangles += 1;
    }
    let mut vertex_seen = vec![false; nv];
    for (k, tri) in tris.iter().enumerate() {
        for &v in tri {
            if !vertex_seen[v as usize] {
                vertex_seen[v as usize] = true;
                boundary_surfaces[tri_comp[k]].vertices += 1;
            }
        }
    }
    for s in &mut boundary_surfaces {
        s.edges = 3 * s.triangles / 2;
        s.euler_characteristic = s.vertices as i64 - s.edges as i64 + s.triangles as i64;
        s.genus = (2 - s.euler_characteristic) / 2;
    }
    Ok((boundary, vertex_on_boundary, boundary_surfaces))
}
