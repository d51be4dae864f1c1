//! The BCC lattice of step 1 (module docs of [`super`], paper §3, Fig. 2): black vertices at
//! the corners of the cubic grid, red ones at the cube centres, their ids, doubled integer
//! coordinates, positions and neighbours, the long and short edges; the signs of the
//! vertices, the output keys of lattice vertices and cut points, and the lattice over the
//! box checked against the parameters.

use super::{StuffingError, StuffingParams};

/// The lattice: cubes `n[0] × n[1] × n[2]` of edge `h` from `origin`; black ids first
/// (`(n + 1)³` grid corners), then red ids (cube centres).
#[derive(Clone, Debug)]
pub(super) struct Lattice {
    pub(super) n: [usize; 3],
    pub(super) origin: [f64; 3],
    pub(super) h: f64,
    pub(super) blacks: usize,
    pub(super) total: usize,
}

/// Sign of a lattice vertex after warping.
pub(super) const NEG: i8 = -1;
pub(super) const ZERO: i8 = 0;
pub(super) const POS: i8 = 1;

/// Output-vertex key of a lattice vertex (low half all ones) or of a cut point on the edge
/// `(a, b)`, `a < b` (ids fit in 32 bits and stay below `u32::MAX`).
pub(super) fn lkey(v: u32) -> u64 {
    ((v as u64) << 32) | 0xFFFF_FFFF
}
pub(super) fn ckey(a: u32, b: u32) -> u64 {
    let (a, b) = if a < b { (a, b) } else { (b, a) };
    ((a as u64) << 32) | b as u64
}

impl Lattice {
    pub(super) fn black(&self, i: usize, j: usize, k: usize) -> u32 {
        (i + (self.n[0] + 1) * (j + (self.n[1] + 1) * k)) as u32
    }
    pub(super) fn red(&self, i: usize, j: usize, k: usize) -> u32 {
        (self.blacks + i + self.n[0] * (j + self.n[1] * k)) as u32
    }
    pub(super) fn is_red(&self, v: u32) -> bool {
        v as usize >= self.blacks
    }
    /// Doubled integer coordinates: black `(2i, 2j, 2k)`, red `(2i + 1, 2j + 1, 2k + 1)`.
    pub(super) fn doubled(&self, v: u32) -> [i64; 3] {
        let v = v as usize;
        if v < self.blacks {
            let (nx, ny) = (self.n[0] + 1, self.n[1] + 1);
            [
                2 * (v % nx) as i64,
                2 * ((v / nx) % ny) as i64,
                2 * (v / (nx * ny)) as i64,
            ]
        } else {
            let r = v - self.blacks;
            let (nx, ny) = (self.n[0], self.n[1]);
            [
                2 * (r % nx) as i64 + 1,
                2 * ((r / nx) % ny) as i64 + 1,
                2 * (r / (nx * ny)) as i64 + 1,
            ]
        }
    }
    pub(super) fn pos(&self, v: u32) -> [f64; 3] {
        let d = self.doubled(v);
        [0, 1, 2].map(|a| self.origin[a] + d[a] as f64 * 0.5 * self.h)
    }
    /// The lattice neighbours of `v` (6 long, up to 8 short), into `out`; returns the count.
    pub(super) fn neighbours(&self, v: u32, out: &mut [u32; 14]) -> usize {
        let d = self.doubled(v);
        let mut c = 0;
        let n = self.n;
        if !self.is_red(v) {
            let ijk = d.map(|x| (x / 2) as usize);
            for a in 0..3 {
                for s in [-1i64, 1] {
                    let x = ijk[a] as i64 + s;
                    if x >= 0 && x <= n[a] as i64 {
                        let mut q = ijk;
                        q[a] = x as usize;
                        out[c] = self.black(q[0], q[1], q[2]);
                        c += 1;
                    }
                }
            }
            for di in 0..2 {
                for dj in 0..2 {
                    for dk in 0..2 {
                        let q = [ijk[0] as i64 - di, ijk[1] as i64 - dj, ijk[2] as i64 - dk];
                        if (0..3).all(|a| q[a] >= 0 && q[a] < n[a] as i64) {
                            out[c] = self.red(q[0] as usize, q[1] as usize, q[2] as usize);
                            c += 1;
                        }
                    }
                }
            }
        } else {
            let ijk = d.map(|x| ((x - 1) / 2) as usize);
            for a in 0..3 {
                for s in [-1i64, 1] {
                    let x = ijk[a] as i64 + s;
                    if x >= 0 && x < n[a] as i64 {
                        let mut q = ijk;
                        q[a] = x as usize;
                        out[c] = self.red(q[0], q[1], q[2]);
                        c += 1;
                    }
                }
            }
            for di in 0..2 {
                for dj in 0..2 {
                    for dk in 0..2 {
                        out[c] = self.black(ijk[0] + di, ijk[1] + dj, ijk[2] + dk);
                        c += 1;
                    }
                }
            }
        }
        c
    }
    /// Long edge (same colour) or short.
    pub(super) fn is_long(&self, a: u32, b: u32) -> bool {
        self.is_red(a) == self.is_red(b)
    }
    pub(super) fn edge_len(&self, a: u32, b: u32) -> f64 {
        if self.is_long(a, b) {
            self.h
        } else {
            self.h * 3f64.sqrt() * 0.5
        }
    }
    /// Reference position (4× the lattice's half-units) of an output key: a lattice vertex
    /// at its lattice place, a cut point at its edge's midpoint.
    pub(super) fn reference(&self, key: u64) -> [i64; 3] {
        let a = (key >> 32) as u32;
        let b = key as u32;
        let da = self.doubled(a);
        if b == u32::MAX {
            da.map(|x| 2 * x)
        } else {
            let db = self.doubled(b);
            [da[0] + db[0], da[1] + db[1], da[2] + db[2]]
        }
    }
}

pub(super) fn det_i(a: [i64; 3], b: [i64; 3], c: [i64; 3], d: [i64; 3]) -> i64 {
    let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let w = [d[0] - a[0], d[1] - a[1], d[2] - a[2]];
    u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
        + u[2] * (v[0] * w[1] - v[1] * w[0])
}

/// The lattice over the box, checked against the parameters.
pub(super) fn lattice(
    bbox_min: [f64; 3],
    bbox_max: [f64; 3],
    params: &StuffingParams,
) -> Result<Lattice, StuffingError> {
    let bad = |m: String| Err(StuffingError::BadInput(m));
    let h = params.h;
    if !h.is_finite() || h <= 0.0 {
        return bad(format!("spacing h is {h}, expected a finite number > 0"));
    }
    for (name, a) in [
        ("alpha_long", params.alpha_long),
        ("alpha_short", params.alpha_short),
    ] {
        if a.is_nan() || a <= 0.0 || a >= 0.5 {
            return bad(format!("{name} is {a}, expected a number in (0, 0.5)"));
        }
    }
    if !params.root_tol.is_finite() || params.root_tol <= 0.0 {
        return bad(format!(
            "root_tol is {}, expected a finite number > 0",
            params.root_tol
        ));
    }
    for a in 0..3 {
        if !(bbox_min[a].is_finite() && bbox_max[a].is_finite()) || bbox_min[a] > bbox_max[a] {
            return bad(format!(
                "box {bbox_min:?} – {bbox_max:?} is not a finite box with min <= max on every axis"
            ));
        }
    }
    let cubes = [0, 1, 2].map(|a| ((bbox_max[a] - bbox_min[a]) / h).ceil() + 2.0);
    // Vertices: (n + 1)³ blacks and n³ reds, counted in f64 first against overflow.
    let count_f =
        (cubes[0] + 1.0) * (cubes[1] + 1.0) * (cubes[2] + 1.0) + cubes[0] * cubes[1] * cubes[2];
    let limit = params.max_lattice_vertices.min(u32::MAX as u64 - 1);
    if count_f.is_nan() || count_f > limit as f64 {
        return Err(StuffingError::TooLarge {
            needed: if count_f.is_finite() && count_f < u64::MAX as f64 {
                count_f as u64
            } else {
                u64::MAX
            },
            limit: params.max_lattice_vertices,
        });
    }
    let n = cubes.map(|c| c as usize);
    let blacks = (n[0] + 1) * (n[1] + 1) * (n[2] + 1);
    Ok(Lattice {
        n,
        origin: [0, 1, 2].map(|a| bbox_min[a] - h),
        h,
        blacks,
        total: blacks + n[0] * n[1] * n[2],
    })
}
