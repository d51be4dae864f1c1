//! The element checks of the module docs of [`super`]: counts, vertex indices, finite
//! coordinates and repeated vertices (checks 1–4), volumes against the bounding box (5),
//! consistently oriented faces (6, after the neighbour search has found the non-manifold
//! ones) and one face-connected solid (9).

use super::{DEGENERATE_VOLUME, TetError};
use crate::mesh::{FACE_OPPOSITE, NO_TET, TetMesh};

/// The face of tetrahedron `t` opposite its corner `i`, oriented outwards.
pub(super) fn face_of(mesh: &TetMesh, t: usize, i: usize) -> [u32; 3] {
    FACE_OPPOSITE[i].map(|j| mesh.tets[t][j])
}

/// Whether `b` is a cyclic rotation of `a` (the same oriented triangle).
pub(super) fn same_cycle(a: [u32; 3], b: [u32; 3]) -> bool {
    b == a || b == [a[1], a[2], a[0]] || b == [a[2], a[0], a[1]]
}

/// Counts, vertex indices in range, finite coordinates, no repeated vertex in a
/// tetrahedron: the first checks of the module docs.
pub(super) fn check_indices(mesh: &TetMesh) -> Result<(), TetError> {
    let nt = mesh.tets.len();
    let nv = mesh.verts.len();
    if nt == 0 {
        return Err(TetError::NoTetrahedra);
    }
    if nt >= NO_TET as usize {
        return Err(TetError::TooManyTetrahedra { count: nt });
    }
    for (t, tet) in mesh.tets.iter().enumerate() {
        if let Some(&v) = tet.iter().find(|&&v| v as usize >= nv) {
            return Err(TetError::VertexOutOfRange {
                tet: t,
                verts: *tet,
                vertex: v,
                vertex_count: nv,
            });
        }
    }
    for (i, p) in mesh.verts.iter().enumerate() {
        if !p.iter().all(|x| x.is_finite()) {
            return Err(TetError::NonFiniteVertex {
                vertex: i,
                coords: *p,
            });
        }
    }
    for (t, tet) in mesh.tets.iter().enumerate() {
        for x in 0..4 {
            if tet[x + 1..].contains(&tet[x]) {
                return Err(TetError::RepeatedVertex {
                    tet: t,
                    verts: *tet,
                    vertex: tet[x],
                });
            }
        }
    }
    Ok(())
}

/// Volumes against the bounding box of the used vertices: no inverted or degenerate
/// tetrahedron. Returns which vertices the tetrahedra use.
pub(super) fn check_volumes(mesh: &TetMesh) -> Result<Vec<bool>, TetError> {
    let nt = mesh.tets.len();
    let nv = mesh.verts.len();
    let mut used = vec![false; nv];
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for tet in &mesh.tets {
        for &v in tet {
            if !used[v as usize] {
                used[v as usize] = true;
                let p = mesh.verts[v as usize];
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
        }
    }
    let diag = ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2) + (hi[2] - lo[2]).powi(2)).sqrt();
    let min_volume = DEGENERATE_VOLUME * diag.powi(3);
    for t in 0..nt {
        let volume = mesh.volume(t);
        if volume < -min_volume {
            return Err(TetError::Inverted {
                tet: t,
                verts: mesh.tets[t],
                volume,
            });
        }
        if volume.is_nan() || volume <= min_volume {
            return Err(TetError::Degenerate {
                tet: t,
                verts: mesh.tets[t],
                volume,
                min_volume,
            });
        }
    }
    Ok(used)
}

/// Faces: manifold (checked by the neighbour search) and consistently oriented, i.e. no two
/// tetrahedra on the same side of a shared face.
pub(super) fn check_orientation(mesh: &TetMesh, neighbours: &[[u32; 4]]) -> Result<(), TetError> {
    let nt = mesh.tets.len();
    for t in 0..nt {
        for i in 0..4 {
            let n = neighbours[t][i];
            if n == NO_TET || (n as usize) < t {
                continue;
            }
            let f = face_of(mesh, t, i);
            let ntet = &mesh.tets[n as usize];
            let j = (0..4)
                .find(|&j| !f.contains(&ntet[j]))
                .expect("shared face");
            if same_cycle(f, face_of(mesh, n as usize, j)) {
                let mut face = f;
                face.sort_unstable();
                return Err(TetError::OverlappingTets {
                    face,
                    tets: [t as u32, n],
                });
            }
        }
    }
    Ok(())
}

/// One solid: the tetrahedra are face-connected.
pub(super) fn check_one_solid(neighbours: &[[u32; 4]]) -> Result<(), TetError> {
    let nt = neighbours.len();
    let mut comp = vec![u32::MAX; nt];
    let mut components = 0usize;
    let mut second = None;
    let mut queue = Vec::new();
    for seed in 0..nt {
        if comp[seed] != u32::MAX {
            continue;
        }
        if components == 1 {
            second = Some(seed as u32);
        }
        comp[seed] = components as u32;
        queue.push(seed as u32);
        while let Some(t) = queue.pop() {
            for &n in &neighbours[t as usize] {
                if n != NO_TET && comp[n as usize] == u32::MAX {
                    comp[n as usize] = components as u32;
                    queue.push(n);
                }
            }
        }
        components += 1;
    }
    if let Some(second) = second {
        return Err(TetError::Disconnected { components, second });
    }
    Ok(())
}
