//! Step 1 of the module docs of [`super`]: the checked input ([`Ctx`]: the charts, the face
//! neighbours and the face back from each) and each tetrahedron's chart in parameter space,
//! its barycentric coordinates, tolerances, validity and grid points; with the doubled
//! coordinates on which the transitions act exactly.

use rayon::prelude::*;

use super::{DEGENERATE_PARAM_VOLUME, ExtractError, MAX_POINTS_PER_TET, REL_EPS};
use crate::geom::vec::{cross, dot, norm, sub};
use crate::mesh::{FACE_OPPOSITE, NO_TET, TetMesh, tet_neighbours};
use crate::param::{GridMap, Transition};

pub(super) fn half(d: [i64; 3]) -> [f64; 3] {
    d.map(|x| x as f64 * 0.5)
}

/// A transition acting on doubled coordinates: `2x ↦ R (2x) + 2 shift`.
pub(super) fn apply_doubled(tr: &Transition, d: [i64; 3]) -> [i64; 3] {
    let r = tr.rot.apply_i(d);
    [0, 1, 2].map(|k| r[k] + 2 * i64::from(tr.shift[k]))
}

/// One tetrahedron in parameter space.
#[derive(Clone, Copy, Debug)]
pub(super) struct Chart {
    /// Its corners' parameters.
    pub(super) p: [[f64; 3]; 4],
    /// `λ_i(x) = g[i] · (x − p[FACE_OPPOSITE[i][0]])`, the barycentric coordinates.
    pub(super) g: [[f64; 3]; 4],
    /// The tolerance on `λ_i`: `ε |g_i|` (a distance `ε` to face `i`).
    pub(super) tol: [f64; 4],
    /// Absolute tolerance `ε` (parameter units).
    pub(super) eps: f64,
    /// Signed volume.
    pub(super) volume: f64,
    /// Largest edge.
    pub(super) diam: f64,
    /// Whether the chart is usable (volume above the degenerate bound).
    pub(super) valid: bool,
}

impl Chart {
    pub(super) fn new(p: [[f64; 3]; 4]) -> Chart {
        let mut diam: f64 = 0.0;
        let mut maxabs: f64 = 0.0;
        for a in 0..4 {
            for k in 0..3 {
                maxabs = maxabs.max(p[a][k].abs());
            }
            for b in a + 1..4 {
                diam = diam.max(norm(sub(p[b], p[a])));
            }
        }
        let volume = crate::mesh::tet_volume(p[0], p[1], p[2], p[3]);
        let valid = volume > DEGENERATE_PARAM_VOLUME * diam * diam * diam && diam > 0.0;
        let eps = REL_EPS * diam + 1e-13 * maxabs;
        let mut g = [[0.0; 3]; 4];
        let mut tol = [0.0; 4];
        if valid {
            for (i, f) in FACE_OPPOSITE.iter().enumerate() {
                let n = cross(sub(p[f[1]], p[f[0]]), sub(p[f[2]], p[f[0]]));
                let h = dot(n, sub(p[i], p[f[0]]));
                g[i] = n.map(|x| x / h);
                tol[i] = eps * norm(g[i]);
            }
        }
        Chart {
            p,
            g,
            tol,
            eps,
            volume,
            diam,
            valid,
        }
    }

    pub(super) fn bary(&self, x: [f64; 3]) -> [f64; 4] {
        [0, 1, 2, 3].map(|i| dot(self.g[i], sub(x, self.p[FACE_OPPOSITE[i][0]])))
    }

    pub(super) fn contains(&self, l: &[f64; 4]) -> bool {
        (0..4).all(|i| l[i] >= -self.tol[i])
    }

    pub(super) fn on_face(&self, l: &[f64; 4], i: usize) -> bool {
        l[i] <= self.tol[i]
    }

    /// The doubled integer points of the given parity (0: all even, 1: all odd) inside.
    pub(super) fn points(&self, parity: i64, tet: usize) -> Result<Vec<[i64; 3]>, ExtractError> {
        let margin = 1e3 * self.eps;
        let mut lo = [0i64; 3];
        let mut hi = [0i64; 3];
        let mut count: u64 = 1;
        for k in 0..3 {
            let mn = self.p.iter().map(|q| q[k]).fold(f64::INFINITY, f64::min) - margin;
            let mx = self
                .p
                .iter()
                .map(|q| q[k])
                .fold(f64::NEG_INFINITY, f64::max)
                + margin;
            let mut a = (2.0 * mn).ceil() as i64;
            if (a - parity).rem_euclid(2) != 0 {
                a += 1;
            }
            let b = (2.0 * mx).floor() as i64;
            lo[k] = a;
            hi[k] = b;
            let n = if b >= a { ((b - a) / 2 + 1) as u64 } else { 0 };
            count = count.saturating_mul(n);
        }
        if count > MAX_POINTS_PER_TET {
            return Err(ExtractError::TooManyGridPoints { tet, points: count });
        }
        let mut out = Vec::new();
        let mut d0 = lo[0];
        while d0 <= hi[0] {
            let mut d1 = lo[1];
            while d1 <= hi[1] {
                let mut d2 = lo[2];
                while d2 <= hi[2] {
                    let d = [d0, d1, d2];
                    if self.contains(&self.bary(half(d))) {
                        out.push(d);
                    }
                    d2 += 2;
                }
                d1 += 2;
            }
            d0 += 2;
        }
        Ok(out)
    }
}

/// The checked input: charts, neighbours and the face back from each neighbour.
pub(super) struct Ctx<'a> {
    pub(super) mesh: &'a TetMesh,
    pub(super) map: &'a GridMap,
    pub(super) charts: Vec<Chart>,
    pub(super) nb: Vec<[u32; 4]>,
    /// `back[t][i]`: the local face of `nb[t][i]` that is face `i` of `t`.
    pub(super) back: Vec<[u8; 4]>,
}

/// Checks the input and builds the charts and the face adjacency.
pub(super) fn context<'a>(mesh: &'a TetMesh, map: &'a GridMap) -> Result<Ctx<'a>, ExtractError> {
    let nt = mesh.tets.len();
    if map.uvw.len() != nt || map.transitions.len() != nt {
        return Err(ExtractError::SizeMismatch {
            tets: nt,
            uvw: map.uvw.len(),
            transitions: map.transitions.len(),
        });
    }
    for (t, tet) in mesh.tets.iter().enumerate() {
        if let Some(&v) = tet.iter().find(|&&v| v as usize >= mesh.verts.len()) {
            return Err(ExtractError::VertexIndex {
                tet: t,
                vertex: v,
                count: mesh.verts.len(),
            });
        }
        if map.uvw[t].iter().flatten().any(|x| !x.is_finite()) {
            return Err(ExtractError::NonFiniteParam { tet: t });
        }
        for (i, tr) in map.transitions[t].iter().enumerate() {
            if tr.rot.0 >= 24 {
                return Err(ExtractError::BadRotation {
                    tet: t,
                    face: i,
                    rot: tr.rot.0,
                });
            }
        }
    }
    let nb = tet_neighbours(mesh).map_err(|f| ExtractError::NonManifoldFace {
        vertices: f.vertices,
        tets: f.tets,
    })?;
    let mut back = vec![[0u8; 4]; nt];
    for t in 0..nt {
        for i in 0..4 {
            let s = nb[t][i];
            if s == NO_TET {
                continue;
            }
            let s = s as usize;
            let mut key = FACE_OPPOSITE[i].map(|j| mesh.tets[t][j]);
            key.sort_unstable();
            let j = (0..4)
                .find(|&j| {
                    let mut k = FACE_OPPOSITE[j].map(|m| mesh.tets[s][m]);
                    k.sort_unstable();
                    k == key && nb[s][j] as usize == t
                })
                .expect("neighbours pair up");
            back[t][i] = j as u8;
            if map.transitions[s][j] != map.transitions[t][i].inverse() {
                return Err(ExtractError::InconsistentTransition {
                    tet: t,
                    face: i,
                    neighbour: s,
                });
            }
        }
    }
    let charts = map.uvw.par_iter().map(|&p| Chart::new(p)).collect();
    Ok(Ctx {
        mesh,
        map,
        charts,
        nb,
        back,
    })
}
