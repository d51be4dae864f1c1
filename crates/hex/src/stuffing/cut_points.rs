//! Steps 2 and 3 of the module docs of [`super`] (paper §3): the signs of `f` at the lattice
//! vertices, the cut points on the edges from − to + (Illinois regula falsi with a bisection
//! every third step), and the warping of each violated vertex onto its closest violating cut
//! point.

use rayon::prelude::*;

use super::lattice::{Lattice, NEG, POS, ZERO, ckey};
use super::{StuffingError, StuffingParams};

/// The root of `f` on the segment `a`–`b` as a parameter in `[0, 1]` from `a`, where
/// `fa = f(a) ≤ 0 < fb = f(b)`: Illinois regula falsi with a bisection every third step.
pub(super) fn root(
    f: &(dyn Fn([f64; 3]) -> f64 + Sync),
    a: [f64; 3],
    b: [f64; 3],
    fa: f64,
    fb: f64,
    tol: f64,
    max_iter: u32,
) -> f64 {
    if fa == 0.0 {
        return 0.0;
    }
    let (mut lo, mut hi, mut flo, mut fhi) = (0.0f64, 1.0f64, fa, fb);
    let mut side = 0i8;
    for it in 0..max_iter {
        if hi - lo <= tol {
            break;
        }
        let mid = 0.5 * (lo + hi);
        let mut t = if it % 3 == 2 {
            mid
        } else {
            (lo * fhi - hi * flo) / (fhi - flo)
        };
        if t.is_nan() || t <= lo || t >= hi {
            t = mid;
        }
        let p = [0, 1, 2].map(|k| a[k] + t * (b[k] - a[k]));
        let ft = f(p);
        if ft.is_nan() {
            return mid;
        }
        if ft == 0.0 {
            return t;
        }
        if ft < 0.0 {
            lo = t;
            flo = ft;
            if side == -1 {
                fhi *= 0.5;
            }
            side = -1;
        } else {
            hi = t;
            fhi = ft;
            if side == 1 {
                flo *= 0.5;
            }
            side = 1;
        }
    }
    let t = (lo * fhi - hi * flo) / (fhi - flo);
    if t >= lo && t <= hi {
        t
    } else {
        0.5 * (lo + hi)
    }
}

/// Signs: `f` at every lattice vertex, and each vertex's sign (`NEG` where `f <= 0`).
pub(super) fn signs(
    f: &(dyn Fn([f64; 3]) -> f64 + Sync),
    lat: &Lattice,
    params: &StuffingParams,
) -> Result<(Vec<f64>, Vec<i8>), StuffingError> {
    let total = lat.total;
    let values: Vec<f64> = (0..total as u32)
        .into_par_iter()
        .map(|v| f(lat.pos(v)))
        .collect();
    if let Some(v) = values.iter().position(|x| x.is_nan()) {
        return Err(StuffingError::NotANumber {
            at: lat.pos(v as u32),
        });
    }
    let sign: Vec<i8> = values
        .par_iter()
        .map(|&x| if x <= 0.0 { NEG } else { POS })
        .collect();
    if !sign.par_iter().any(|&s| s == NEG) {
        return Err(StuffingError::NothingInside { h: params.h });
    }
    Ok((values, sign))
}

/// Cut points on − to + edges, found from their − end: (key, parameter from the key's
/// smaller id, position), unsorted.
pub(super) fn cut_points(
    f: &(dyn Fn([f64; 3]) -> f64 + Sync),
    lat: &Lattice,
    values: &[f64],
    sign: &[i8],
    params: &StuffingParams,
) -> Vec<(u64, f64, [f64; 3])> {
    let total = lat.total;
    (0..total as u32)
        .into_par_iter()
        .filter(|&v| sign[v as usize] == NEG)
        .flat_map_iter(|v| {
            let mut nb = [0u32; 14];
            let n = lat.neighbours(v, &mut nb);
            let mut found = Vec::new();
            for &u in &nb[..n] {
                if sign[u as usize] != POS {
                    continue;
                }
                let (pa, pb) = (lat.pos(v), lat.pos(u));
                let t = root(
                    f,
                    pa,
                    pb,
                    values[v as usize],
                    values[u as usize],
                    params.root_tol,
                    params.max_root_iter,
                );
                let p = [0, 1, 2].map(|k| pa[k] + t * (pb[k] - pa[k]));
                let t_min = if v < u { t } else { 1.0 - t };
                found.push((ckey(v, u), t_min, p));
            }
            found
        })
        .collect()
}

/// Warping: each violated vertex moves to its closest violating cut point and its sign
/// becomes `ZERO`. Returns the warps and the cut points left on edges between two unwarped
/// vertices (key, position); `cuts` comes sorted by key.
#[allow(clippy::type_complexity)]
pub(super) fn warp(
    lat: &Lattice,
    cuts: Vec<(u64, f64, [f64; 3])>,
    sign: &mut [i8],
    params: &StuffingParams,
) -> (Vec<(u32, [f64; 3])>, Vec<(u64, [f64; 3])>) {
    let mut cand: Vec<(u32, f64, u64)> = cuts
        .par_iter()
        .flat_map_iter(|&(key, t_min, _)| {
            let (a, b) = ((key >> 32) as u32, key as u32);
            let len = lat.edge_len(a, b);
            let alpha = if lat.is_long(a, b) {
                params.alpha_long
            } else {
                params.alpha_short
            };
            let mut c = Vec::new();
            if t_min < alpha {
                c.push((a, t_min * len, key));
            } else if 1.0 - t_min < alpha {
                c.push((b, (1.0 - t_min) * len, key));
            }
            c
        })
        .collect();
    cand.par_sort_unstable_by(|x, y| x.0.cmp(&y.0).then(x.1.total_cmp(&y.1)).then(x.2.cmp(&y.2)));
    let mut warps: Vec<(u32, [f64; 3])> = Vec::new();
    for (i, c) in cand.iter().enumerate() {
        if i > 0 && cand[i - 1].0 == c.0 {
            continue;
        }
        let at = cuts[cuts.binary_search_by_key(&c.2, |x| x.0).unwrap_or(0)].2;
        warps.push((c.0, at));
    }
    drop(cand);
    for &(v, _) in &warps {
        sign[v as usize] = ZERO;
    }
    let cuts: Vec<(u64, [f64; 3])> = cuts
        .into_iter()
        .filter(|&(key, _, _)| {
            sign[(key >> 32) as usize] != ZERO && sign[(key as u32) as usize] != ZERO
        })
        .map(|(key, _, p)| (key, p))
        .collect();
    (warps, cuts)
}
