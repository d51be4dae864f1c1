//! The boundary constraint (module docs of [`super`], "Boundary constraint", Huang §4.2,
//! Ray §3.2) and the mesh's weights: per tetrahedron, its interior faces' weights
//! `w_st = A_st / |c_s − c_t|`, its penalty `λₜ`, and whether its frame is free, has one axis
//! along a boundary normal (the circle `z₀ + cos 4θ c + sin 4θ d` of admissible coefficients
//! and the closed-form projection onto it) or is fixed by two sharp normals.

use super::sh::{dot9, frame_about, frame_to_sh, orthonormalise, tangents, unit3};
use super::{SQRT_5_12, SmoothError, SmoothParams};
use crate::geom::vec::{add, cross, dot, norm, scale, sub};
use crate::mesh::{FACE_OPPOSITE, Frame, NO_TET, TetMesh};

/// A constrained tet's axis and the circle of its admissible coefficients.
#[derive(Clone, Debug)]
pub(super) struct Axis {
    pub(super) n: [f64; 3],
    pub(super) t1: [f64; 3],
    pub(super) t2: [f64; 3],
    pub(super) z0: [f64; 9],
    /// Unit directions of the circle's plane.
    pub(super) c: [f64; 9],
    pub(super) d: [f64; 9],
}

impl Axis {
    pub(super) fn new(n: [f64; 3]) -> Axis {
        let (t1, t2) = tangents(n);
        let s0 = frame_to_sh(&frame_about(n, t1, t2, 0.0));
        let s8 = frame_to_sh(&frame_about(n, t1, t2, std::f64::consts::PI / 8.0));
        let s4 = frame_to_sh(&frame_about(n, t1, t2, std::f64::consts::PI / 4.0));
        let mut z0 = [0.0; 9];
        let mut c = [0.0; 9];
        let mut d = [0.0; 9];
        for m in 0..9 {
            z0[m] = 0.5 * (s0[m] + s4[m]);
            c[m] = (0.5 * (s0[m] - s4[m])) / SQRT_5_12;
            d[m] = (s8[m] - z0[m]) / SQRT_5_12;
        }
        Axis {
            n,
            t1,
            t2,
            z0,
            c,
            d,
        }
    }

    /// The frame with axis `n` closest to `q`.
    pub(super) fn project(&self, q: &[f64; 9]) -> Frame {
        let (a, b) = (dot9(&self.c, q), dot9(&self.d, q));
        let theta = if a == 0.0 && b == 0.0 {
            0.0
        } else {
            0.25 * b.atan2(a)
        };
        frame_about(self.n, self.t1, self.t2, theta)
    }

    /// `P⊥ x`: `x` without its components along `c` and `d`.
    pub(super) fn perp(&self, x: &[f64; 9]) -> [f64; 9] {
        let (a, b) = (dot9(&self.c, x), dot9(&self.d, x));
        let mut y = *x;
        for m in 0..9 {
            y[m] -= a * self.c[m] + b * self.d[m];
        }
        y
    }
}

/// What constrains a tet's frame: nothing, one axis along a boundary normal, or two sharp
/// boundary normals (the frame is fixed).
#[derive(Clone, Debug)]
pub(super) enum Kind {
    Free,
    Axis(Box<Axis>),
    Fixed(Frame),
}

/// Geometry and constraints of the mesh.
pub(super) struct Setup {
    pub(super) w: Vec<[f64; 4]>,
    pub(super) deg: Vec<f64>,
    pub(super) lambda: Vec<f64>,
    pub(super) kind: Vec<Kind>,
    /// Boundary faces as (tet, outward unit normal).
    pub(super) bfaces: Vec<(usize, [f64; 3])>,
    pub(super) eps: f64,
}

pub(super) fn setup(
    mesh: &TetMesh,
    nb: &[[u32; 4]],
    params: &SmoothParams,
) -> Result<Setup, SmoothError> {
    let n = mesh.tets.len();
    if nb.len() != n {
        return Err(SmoothError::NeighbourCount {
            got: nb.len(),
            tets: n,
        });
    }
    let nv = mesh.verts.len();
    let mut centroid = vec![[0.0; 3]; n];
    for (t, tet) in mesh.tets.iter().enumerate() {
        if tet.iter().any(|&v| v as usize >= nv) {
            return Err(SmoothError::BadTet(t));
        }
        let c = mesh.corners(t);
        if c.iter().flatten().any(|x| !x.is_finite())
            || mesh.volume(t).is_nan()
            || mesh.volume(t) <= 0.0
        {
            return Err(SmoothError::BadTet(t));
        }
        centroid[t] = scale(add(add(c[0], c[1]), add(c[2], c[3])), 0.25);
        for &u in &nb[t] {
            if u == NO_TET {
                continue;
            }
            let u = u as usize;
            if u >= n || u == t || !nb[u].contains(&(t as u32)) {
                return Err(SmoothError::Neighbours(t));
            }
        }
    }
    let cos_sharp = params.sharp_angle_deg.to_radians().cos();
    let mut w = vec![[0.0; 4]; n];
    let mut lambda = vec![0.0; n];
    let mut kind = vec![Kind::Free; n];
    let mut bfaces = Vec::new();
    for t in 0..n {
        let c = mesh.corners(t);
        let mut faces: Vec<([f64; 3], f64)> = Vec::new();
        for (i, f) in FACE_OPPOSITE.iter().enumerate() {
            let (a, b, cc) = (c[f[0]], c[f[1]], c[f[2]]);
            let nrm = cross(sub(b, a), sub(cc, a));
            let area = 0.5 * norm(nrm);
            if area.is_nan() || area <= 0.0 {
                return Err(SmoothError::BadTet(t));
            }
            let u = nb[t][i];
            if u == NO_TET {
                let nu = unit3(nrm);
                let h = dot(sub(a, centroid[t]), nu).abs();
                lambda[t] += params.boundary_weight * area / h;
                faces.push((nu, area));
                bfaces.push((t, nu));
            } else {
                let dist = norm(sub(centroid[u as usize], centroid[t]));
                if dist.is_nan() || dist <= 0.0 {
                    return Err(SmoothError::BadTet(t));
                }
                w[t][i] = area / dist;
            }
        }
        if faces.is_empty() {
            continue;
        }
        // Largest first; the sort is stable so ties keep the face order.
        faces.sort_by(|a, b| b.1.total_cmp(&a.1));
        let n1 = faces[0].0;
        let sharp = faces[1..]
            .iter()
            .find(|f| dot(f.0, n1).abs() < cos_sharp)
            .map(|f| f.0);
        kind[t] = match sharp {
            Some(n2) => {
                let v = if dot(n1, n2) < 0.0 {
                    scale(n2, -1.0)
                } else {
                    n2
                };
                let a = unit3(add(n1, v));
                let b = unit3(sub(n1, v));
                let s = std::f64::consts::FRAC_1_SQRT_2;
                let e1 = scale(add(a, b), s);
                let e2 = scale(sub(a, b), s);
                Kind::Fixed(orthonormalise([e1, e2, cross(e1, e2)]))
            }
            None => {
                let mut m = [0.0; 3];
                for f in &faces {
                    let sg = if dot(f.0, n1) < 0.0 { -1.0 } else { 1.0 };
                    m = add(m, scale(f.0, sg * f.1));
                }
                Kind::Axis(Box::new(Axis::new(unit3(m))))
            }
        };
    }
    let deg: Vec<f64> = w.iter().map(|r| r.iter().sum()).collect();
    let mean = deg.iter().chain(lambda.iter()).sum::<f64>() / n as f64;
    Ok(Setup {
        w,
        deg,
        lambda,
        kind,
        bfaces,
        eps: 1e-10 * mean.max(1e-300),
    })
}
