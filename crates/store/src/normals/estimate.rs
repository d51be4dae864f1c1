//! Nearest neighbours and plane fits.
//!
//! The normal at a point is the direction of least variance of its `k` nearest neighbours
//! (the point itself included): the eigenvector of the smallest eigenvalue of their covariance
//! `C = Σ (q − q̄)(q − q̄)ᵀ` (Hoppe et al. 1992, §3.2, "tangent plane estimation"). The fit is
//! done in f64 about the neighbourhood's mean, so it does not lose digits far from the origin.
//!
//! `robust` re-fits once with Cauchy weights `w = 1 / (1 + (r/s)²)` of each neighbour's
//! distance `r` to the first plane, `s` being 1.4826 × the median of those distances: outliers
//! and points of a second sheet within the neighbourhood then pull the plane far less.
//!
//! A store cell is fitted in two steps ([`fit_own`], then [`fit_boundary`] once its halo is
//! known), as the [module docs](super) describe.

use nalgebra::Matrix3;

use crate::geom::least_eigenvector;

use super::{MAX_K_FACTOR, NormalParams, ORIENT_K, TARGET_ANGLE};
use crate::exec::progress::Stage;
use crate::types::Aabb;

/// Points of a cell sampled to measure its noise ([`cell_k`]).
pub const NOISE_SAMPLE: usize = 1024;

/// Slack on a k-th neighbour distance, so that a neighbour at exactly that distance from the
/// box still counts as possibly outside it despite rounding.
const DK_SLACK: f64 = 1e-6;

/// `p` relative to `c`, times `inv` (a power of two, [`unit_inv`]), in f32: a cell's points
/// about its centre lose no digits that matter, and in units of about the cell's edge their
/// squared distances stay inside float32's range whatever the input's scale (an extent of
/// 1e-30 would underflow to zero, one of 1e30 overflow to infinity).
#[inline]
pub fn rel(p: [f64; 3], c: [f64; 3], inv: f64) -> [f32; 3] {
    [
        ((p[0] - c[0]) * inv) as f32,
        ((p[1] - c[1]) * inv) as f32,
        ((p[2] - c[2]) * inv) as f32,
    ]
}

/// The power of two nearest `1/edge`: scaling by it is exact, so a cell's fits are those of
/// its points in units of about its edge (1 for cells of edge 0.71 to 1.41).
pub fn unit_inv(edge: f64) -> f64 {
    let inv = 2f64.powi(-(edge.log2().round() as i32));
    if inv.is_finite() && inv > 0.0 {
        inv
    } else {
        1.0
    }
}

/// Points of other cells near a cell's box, relative to the cell's centre.
#[derive(Debug, Default)]
pub struct Halo {
    /// Positions relative to the cell's centre, in the cell's units ([`rel`]).
    pub pos: Vec<[f32; 3]>,
    /// `(cell, index in that cell)` of each.
    pub origin: Vec<(u32, u32)>,
}

/// A cell after fitting with its own points only.
#[derive(Debug)]
pub struct OwnFit {
    /// Neighbours per fit in this cell.
    pub k: usize,
    /// Typical k-th neighbour distance in the cell, in the units of `rel`.
    pub typical: f32,
    /// Centre of the cell's box, the origin of `rel`.
    pub centre: [f64; 3],
    /// The scale of `rel`, [`unit_inv`] of the cell's edge.
    pub inv: f64,
    /// The cell's points relative to `centre`, times `inv` ([`rel`]).
    pub rel: Vec<[f32; 3]>,
    /// Normal of each point, `None` until fitted or where no plane fits.
    pub normals: Vec<Option<[f32; 3]>>,
    /// [`ORIENT_K`] nearest own neighbours of each point (`u32::MAX` for none).
    pub nbrs: Vec<u32>,
    /// Points whose neighbour ball leaves the box (fit again with the halo).
    pub boundary: Vec<u32>,
    /// The halo's reach: how far beyond the box a boundary point's ball goes, at most one
    /// cell edge.
    pub h: f64,
}

/// The cell's neighbourhood size: `k`, grown where noise dominates the fits (measured on a
/// sample of up to [`NOISE_SAMPLE`] of its points; see [`TARGET_ANGLE`]).
pub fn cell_k(rel: &[[f32; 3]], k: usize) -> usize {
    let n = rel.len();
    if n <= k {
        return k;
    }
    let sample: Vec<u32> = (0..n as u32).step_by((n / NOISE_SAMPLE).max(1)).collect();
    let mut spreads = Vec::with_capacity(sample.len());
    knn_all(rel, &sample, k, None, |_, nb| {
        if let Some(s) = spread(rel, nb) {
            spreads.push(s);
        }
    });
    if spreads.is_empty() {
        return k;
    }
    spreads.sort_by(|a, b| a.total_cmp(b));
    let err = spreads[spreads.len() / 2] / (k as f64).sqrt();
    let grown = (k as f64 * err / TARGET_ANGLE).ceil() as usize;
    grown.clamp(k, MAX_K_FACTOR * k)
}

/// Fit the points `pos` of a cell with box `bx` among themselves. A point whose k-th
/// neighbour distance `d_k` exceeds its distance `b` to the box faces may have neighbours in
/// other cells: it is left for [`fit_boundary`], and the halo must reach `d_k − b` past the box.
/// Each point looked at is counted in `done` as it is, so progress moves inside a big cell.
pub fn fit_own(pos: &[[f64; 3]], bx: &Aabb, params: &NormalParams, done: &Stage) -> OwnFit {
    let centre = [0, 1, 2].map(|a| 0.5 * (bx.min[a] + bx.max[a]));
    let edge = bx.max[0] - bx.min[0];
    let n = pos.len();
    let inv = unit_inv(edge);
    let rel: Vec<[f32; 3]> = pos.iter().map(|p| rel(*p, centre, inv)).collect();
    let params = &NormalParams {
        k: if params.adaptive {
            cell_k(&rel, params.k)
        } else {
            params.k
        },
        ..*params
    };
    let mut normals = vec![None; n];
    let mut nbrs = vec![u32::MAX; n * ORIENT_K];
    let mut boundary = Vec::new();
    let mut h = 0f64;
    let all: Vec<u32> = (0..n as u32).collect();
    let mut ticker = done.ticker();
    let typical = knn_all(&rel, &all, params.k, None, |i, nb| {
        ticker.tick();
        let i = i as usize;
        let p = pos[i];
        let b = (0..3)
            .map(|a| (p[a] - bx.min[a]).min(bx.max[a] - p[a]))
            .fold(f64::INFINITY, f64::min);
        let dk = if nb.len() < params.k {
            f64::INFINITY
        } else {
            (nb[nb.len() - 1].0 as f64).sqrt() / inv * (1.0 + DK_SLACK)
        };
        if dk > b {
            boundary.push(i as u32);
            h = h.max(dk - b);
            return;
        }
        normals[i] = fit_normal(&rel, nb, params.robust);
        keep_nbrs(&mut nbrs[i * ORIENT_K..(i + 1) * ORIENT_K], i as u32, nb, n);
    });
    OwnFit {
        k: params.k,
        typical,
        centre,
        inv,
        rel,
        normals,
        nbrs,
        boundary,
        h: h.min(edge),
    }
}

/// Fit the boundary points of `f` again among the cell's points and its `halo`. Returns, for
/// each boundary point with a halo point among its neighbours, `(point, index into the halo)`
/// of the nearest one.
pub fn fit_boundary(f: &mut OwnFit, halo: &Halo, params: &NormalParams) -> Vec<(u32, u32)> {
    let mut cross_of: Vec<(u32, u32)> = Vec::new();
    if f.boundary.is_empty() {
        return cross_of;
    }
    let n = f.rel.len();
    let params = &NormalParams { k: f.k, ..*params };
    let mut all = f.rel.clone();
    all.extend_from_slice(&halo.pos);
    let (normals, nbrs) = (&mut f.normals, &mut f.nbrs);
    knn_all(&all, &f.boundary, params.k, Some(f.typical), |i, nb| {
        let iu = i as usize;
        normals[iu] = fit_normal(&all, nb, params.robust);
        keep_nbrs(&mut nbrs[iu * ORIENT_K..(iu + 1) * ORIENT_K], i, nb, n);
        if let Some(&(_, j)) = nb.iter().find(|&&(_, j)| j as usize >= n) {
            cross_of.push((i, j - n as u32));
        }
    });
    cross_of
}

/// The first `dst.len()` neighbours other than `i` itself among the cell's `own` points.
fn keep_nbrs(dst: &mut [u32], i: u32, nb: &[(f32, u32)], own: usize) {
    let mut k = 0;
    for &(_, j) in nb {
        if k == dst.len() {
            break;
        }
        if j != i && (j as usize) < own {
            dst[k] = j;
            k += 1;
        }
    }
}

/// Exact k-nearest neighbours of the points `queries` (indices into `pts`), handed to `f` as
/// `(squared distance, index)` lists, nearest first, ties by index.
///
/// Points are bucketed in a hashed-free sparse grid (sorted voxel keys) of voxels 1.5× the
/// typical k-th neighbour distance (measured on a sample). Queries are taken voxel by voxel:
/// the points of the 27 voxels around a voxel are gathered once and serve every query in it.
/// A query's answer is final when its k-th distance is within the block's reach (the distance
/// from the query to the block's faces); the rare rest fall back to a kd-tree.
/// `typical` is the typical k-th neighbour distance when the caller knows it (it is measured
/// on a sample otherwise); returns the one used.
pub fn knn_all(
    pts: &[[f32; 3]],
    queries: &[u32],
    k: usize,
    typical: Option<f32>,
    mut f: impl FnMut(u32, &[(f32, u32)]),
) -> f32 {
    let n = pts.len();
    let k = k.min(n);
    if k == 0 || queries.is_empty() {
        for &q in queries {
            f(q, &[]);
        }
        return typical.unwrap_or(0.0);
    }
    let mut lo = [f32::INFINITY; 3];
    for p in pts {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
        }
    }
    let typical = typical
        .filter(|t| *t > 0.0)
        .unwrap_or_else(|| sampled_kth_distance(pts, k));
    let mut d2: Vec<f32> = Vec::new();
    let mut prev_dk2 = typical * typical;
    let mut s = 1.2 * typical;
    let span = pts
        .iter()
        .map(|p| (0..3).map(|a| p[a] - lo[a]).fold(0f32, f32::max))
        .fold(0f32, f32::max);
    // At most 2^20 voxels per axis; a positive size.
    s = s.max(span / ((1u32 << 20) - 2) as f32);
    if s.is_nan() || s <= 0.0 {
        s = 1.0;
    }
    let inv = 1.0 / s;
    let vox = |p: [f32; 3]| -> [u32; 3] { [0, 1, 2].map(|a| ((p[a] - lo[a]) * inv) as u32 + 1) };
    let key = |c: [u32; 3]| -> u64 { ((c[2] as u64) << 42) | ((c[1] as u64) << 21) | c[0] as u64 };
    let mut by_key: Vec<(u64, u32)> = pts
        .iter()
        .enumerate()
        .map(|(i, p)| (key(vox(*p)), i as u32))
        .collect();
    radix_sort(&mut by_key);
    let mut keys: Vec<u64> = Vec::new();
    let mut start: Vec<u32> = Vec::new();
    for (j, &(kk, _)) in by_key.iter().enumerate() {
        if keys.last() != Some(&kk) {
            keys.push(kk);
            start.push(j as u32);
        }
    }
    start.push(n as u32);
    let mut qs: Vec<(u64, u32)> = queries
        .iter()
        .map(|&q| (key(vox(pts[q as usize])), q))
        .collect();
    radix_sort(&mut qs);
    let mut tree: Option<kiddo::immutable::float::kdtree::ImmutableKdTree<f32, u32, 3, 32>> = None;
    let mut cand: Vec<([f32; 3], u32)> = Vec::new();
    let mut best: Vec<(f32, u32)> = Vec::new();
    let (mut cx, mut cy, mut cz) = (Vec::new(), Vec::new(), Vec::new());
    let mut g = 0;
    while g < qs.len() {
        let kk = qs[g].0;
        let mut e = g;
        while e < qs.len() && qs[e].0 == kk {
            e += 1;
        }
        let c = [kk & 0x1f_ffff, (kk >> 21) & 0x1f_ffff, kk >> 42].map(|v| v as u32);
        cand.clear();
        for dz in 0..3u32 {
            for dy in 0..3u32 {
                let row = key([c[0] - 1, c[1] + dy - 1, c[2] + dz - 1]);
                // The three voxels of a row are consecutive keys.
                let from = keys.partition_point(|&x| x < row);
                let to = keys.partition_point(|&x| x < row + 3);
                if from < to {
                    for &(_, i) in &by_key[start[from] as usize..start[to] as usize] {
                        cand.push((pts[i as usize], i));
                    }
                }
            }
        }
        let vlo = [0, 1, 2].map(|a| lo[a] + (c[a] - 1) as f32 * s);
        cx.clear();
        cy.clear();
        cz.clear();
        for &(cp, _) in &cand {
            cx.push(cp[0]);
            cy.push(cp[1]);
            cz.push(cp[2]);
        }
        for &(_, q) in &qs[g..e] {
            let p = pts[q as usize];
            d2.clear();
            d2.extend(cx.iter().zip(&cy).zip(&cz).map(|((x, y), z)| {
                let d = [x - p[0], y - p[1], z - p[2]];
                d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
            }));
            // A guess of the k-th distance from the previous query (neighbouring queries have
            // similar ones): when at least k candidates lie within it, the k nearest are among
            // them, so the guess prunes without changing the answer; otherwise all are kept.
            let tau = prev_dk2 * 1.35;
            best.resize(cand.len(), (0.0, 0));
            let mut m = 0;
            for (&d, c) in d2.iter().zip(&cand) {
                best[m] = (d, c.1);
                m += (d <= tau) as usize;
            }
            best.truncate(m);
            if m < k {
                best.clear();
                best.extend(d2.iter().zip(&cand).map(|(&d, c)| (d, c.1)));
            }
            let by = |a: &(f32, u32), b: &(f32, u32)| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1));
            if best.len() > 2 * k {
                best.select_nth_unstable_by(k - 1, by);
                best.truncate(k);
            }
            insertion_sort(&mut best, by);
            best.truncate(k);
            if best.len() == k {
                prev_dk2 = best[k - 1].0;
            }
            let inner = (0..3)
                .map(|a| (p[a] - vlo[a]).min(vlo[a] + s - p[a]))
                .fold(f32::INFINITY, f32::min)
                .max(0.0);
            let reach = s + inner;
            if best.len() == k && best[k - 1].0 <= reach * reach {
                f(q, &best);
                continue;
            }
            let t = tree.get_or_insert_with(|| {
                kiddo::immutable::float::kdtree::ImmutableKdTree::new_from_slice(pts)
            });
            best.clear();
            let kz = std::num::NonZero::new(k).unwrap_or(std::num::NonZero::<usize>::MIN);
            for nb in t.nearest_n::<kiddo::SquaredEuclidean>(&p, kz) {
                best.push((nb.distance, nb.item));
            }
            best.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            f(q, &best);
        }
        g = e;
    }
    typical
}

/// Points sampled by [`sampled_kth_distance`].
const TYPICAL_SAMPLE: usize = 9;

/// The median k-th neighbour distance (`1 <= k <= pts.len()`) of up to [`TYPICAL_SAMPLE`]
/// evenly spaced points, by brute force.
fn sampled_kth_distance(pts: &[[f32; 3]], k: usize) -> f32 {
    let n = pts.len();
    let mut radii = Vec::new();
    let mut d2: Vec<f32> = Vec::with_capacity(n);
    for i in (0..n)
        .step_by((n / TYPICAL_SAMPLE).max(1))
        .take(TYPICAL_SAMPLE)
    {
        d2.clear();
        let q = pts[i];
        d2.extend(pts.iter().map(|p| dist2(*p, q)));
        let (_, v, _) = d2.select_nth_unstable_by(k - 1, |a, b| a.total_cmp(b));
        radii.push(v.sqrt());
    }
    radii.sort_by(|a, b| a.total_cmp(b));
    radii[radii.len() / 2]
}

/// Sort a short slice in place (a few dozen entries: fewer moves than a general sort).
#[inline]
fn insertion_sort<T: Copy>(v: &mut [T], by: impl Fn(&T, &T) -> std::cmp::Ordering) {
    for i in 1..v.len() {
        let x = v[i];
        let mut j = i;
        while j > 0 && by(&x, &v[j - 1]).is_lt() {
            v[j] = v[j - 1];
            j -= 1;
        }
        v[j] = x;
    }
}

/// Stable least-significant-digit radix sort of `(key, value)` pairs by key, a byte at a
/// time, skipping the bytes every key shares (voxel keys use few of their 64 bits).
fn radix_sort(v: &mut Vec<(u64, u32)>) {
    let (mut or, mut and) = (0u64, u64::MAX);
    for &(k, _) in v.iter() {
        or |= k;
        and &= k;
    }
    let varying = or ^ and;
    let mut tmp = vec![(0u64, 0u32); v.len()];
    for byte in 0..8 {
        let shift = 8 * byte;
        if (varying >> shift) & 0xff == 0 {
            continue;
        }
        let mut count = [0usize; 257];
        for &(k, _) in v.iter() {
            count[((k >> shift) & 0xff) as usize + 1] += 1;
        }
        for i in 0..256 {
            count[i + 1] += count[i];
        }
        for &x in v.iter() {
            let b = ((x.0 >> shift) & 0xff) as usize;
            tmp[count[b]] = x;
            count[b] += 1;
        }
        std::mem::swap(v, &mut tmp);
    }
}

#[inline(always)]
fn dist2(a: [f32; 3], b: [f32; 3]) -> f32 {
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
}

/// Unit normal of the plane through `nbrs` (indices into `pts`); `None` when fewer than three
/// points or when they span no plane (all on one line or one point).
pub fn fit_normal(pts: &[[f32; 3]], nbrs: &[(f32, u32)], robust: bool) -> Option<[f32; 3]> {
    if nbrs.len() < 3 {
        return None;
    }
    let n = plane(pts, nbrs, None)?;
    if !robust {
        return Some(n.1);
    }
    let (c, nrm) = n;
    let mut r: Vec<f64> = nbrs
        .iter()
        .map(|&(_, i)| {
            let p = pts[i as usize];
            ((p[0] as f64 - c[0]) * nrm[0] as f64
                + (p[1] as f64 - c[1]) * nrm[1] as f64
                + (p[2] as f64 - c[2]) * nrm[2] as f64)
                .abs()
        })
        .collect();
    let mut sorted = r.clone();
    sorted.sort_by(|a, b| a.total_cmp(b));
    let s = 1.4826 * sorted[sorted.len() / 2];
    if s <= 0.0 {
        return Some(nrm);
    }
    for v in &mut r {
        *v = 1.0 / (1.0 + (*v / s) * (*v / s));
    }
    Some(plane(pts, nbrs, Some(&r)).map_or(nrm, |p| p.1))
}

/// Weighted mean and least-variance direction of the neighbours.
fn plane(pts: &[[f32; 3]], nbrs: &[(f32, u32)], w: Option<&[f64]>) -> Option<([f64; 3], [f32; 3])> {
    let (m, c) = covariance(pts, nbrs, w)?;
    let v = least_eigenvector(&c)?;
    Some((m, [v[0] as f32, v[1] as f32, v[2] as f32]))
}

/// Weighted mean and scatter matrix `Σ wⱼ (q − q̄)(q − q̄)ᵀ` of the neighbours (weights 1
/// without `w`); `None` when the weights sum to nothing.
fn covariance(
    pts: &[[f32; 3]],
    nbrs: &[(f32, u32)],
    w: Option<&[f64]>,
) -> Option<([f64; 3], Matrix3<f64>)> {
    let mut sw = 0.0;
    let mut m = [0f64; 3];
    for (j, &(_, i)) in nbrs.iter().enumerate() {
        let wj = w.map_or(1.0, |w| w[j]);
        let p = pts[i as usize];
        sw += wj;
        for a in 0..3 {
            m[a] += wj * p[a] as f64;
        }
    }
    if sw <= 0.0 {
        return None;
    }
    m = m.map(|v| v / sw);
    let mut c = [0f64; 6];
    for (j, &(_, i)) in nbrs.iter().enumerate() {
        let wj = w.map_or(1.0, |w| w[j]);
        let p = pts[i as usize];
        let d = [p[0] as f64 - m[0], p[1] as f64 - m[1], p[2] as f64 - m[2]];
        c[0] += wj * d[0] * d[0];
        c[1] += wj * d[0] * d[1];
        c[2] += wj * d[0] * d[2];
        c[3] += wj * d[1] * d[1];
        c[4] += wj * d[1] * d[2];
        c[5] += wj * d[2] * d[2];
    }
    let mat = Matrix3::new(c[0], c[1], c[2], c[1], c[3], c[4], c[2], c[4], c[5]);
    Some((m, mat))
}

/// Thickness of the neighbourhood relative to its extent, `√(λ₀/λ₁)` of its covariance (the
/// two smallest eigenvalues): about `2σ/r` for points with noise `σ` on a plane over a
/// neighbourhood of radius `r`, and the normal's angular error is about that over `√k`.
pub fn spread(pts: &[[f32; 3]], nbrs: &[(f32, u32)]) -> Option<f64> {
    if nbrs.len() < 3 {
        return None;
    }
    let (_, c) = covariance(pts, nbrs, None)?;
    let mut ev: Vec<f64> = c.symmetric_eigenvalues().iter().copied().collect();
    ev.sort_by(|a, b| a.total_cmp(b));
    (ev[1] > 0.0).then(|| (ev[0].max(0.0) / ev[1]).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cell_fit_counts_its_points_as_it_goes() {
        use crate::exec::progress::{Progress, Ticker};
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        let n = 3 * Ticker::BATCH as usize + 17;
        let pos: Vec<[f64; 3]> = (0..n)
            .map(|_| [rng.random::<f64>(), rng.random::<f64>(), 0.5])
            .collect();
        let bx = Aabb {
            min: [0.0; 3],
            max: [1.0; 3],
        };
        let progress = Progress::quiet();
        let stage = progress.stage("normals", Some(n as u64), "points");
        let f = fit_own(&pos, &bx, &NormalParams::default(), &stage);
        assert_eq!(stage.done(), n as u64);
        assert_eq!(f.normals.len(), n);
    }

    #[test]
    fn grid_knn_equals_brute_force() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        // A curved sheet plus a few far points and duplicates.
        let mut pts: Vec<[f32; 3]> = (0..3000)
            .map(|_| {
                let (u, v): (f32, f32) = (rng.random(), rng.random());
                [u, v, 0.3 * (4.0 * u).sin() * v]
            })
            .collect();
        pts.extend([[5.0, 5.0, 5.0], [-3.0, 0.0, 1.0], pts[10], pts[10]]);
        let queries: Vec<u32> = (0..pts.len() as u32).step_by(37).collect();
        for k in [1, 7, 20, 64] {
            let mut answers = Vec::new();
            knn_all(&pts, &queries, k, None, |q, l| {
                answers.push((q, l.to_vec()))
            });
            assert_eq!(answers.len(), queries.len());
            for (qi, got) in answers {
                let q = &pts[qi as usize];
                let mut want: Vec<(f32, u32)> = pts
                    .iter()
                    .enumerate()
                    .map(|(i, p)| (dist2(*p, *q), i as u32))
                    .collect();
                want.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                want.truncate(k);
                assert_eq!(got, want, "query {qi}, k {k}");
            }
        }
        // The far points too.
        knn_all(&pts, &[3000], 5, None, |_, l| assert_eq!(l[0], (0.0, 3000)));
    }

    #[test]
    fn plane_normal_of_a_tilted_grid() {
        // Points on z = 0.5 x + 0.25 y: normal ∝ (-0.5, -0.25, 1).
        let mut pts = Vec::new();
        for i in 0..10 {
            for j in 0..10 {
                let (x, y) = (i as f32 * 0.1, j as f32 * 0.1);
                pts.push([x, y, 0.5 * x + 0.25 * y]);
            }
        }
        let mut nb = Vec::new();
        knn_all(&pts, &[55], 20, None, |_, l| nb = l.to_vec());
        assert_eq!(nb.len(), 20);
        assert_eq!(nb[0].1, 55);
        let want = {
            let v = [-0.5f32, -0.25, 1.0];
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            v.map(|c| c / l)
        };
        for robust in [false, true] {
            let n = fit_normal(&pts, &nb, robust).unwrap();
            let dot = (n[0] * want[0] + n[1] * want[1] + n[2] * want[2]).abs();
            assert!(dot > 0.99999, "{n:?}");
        }
    }

    #[test]
    fn robust_fit_ignores_an_outlier() {
        let mut pts = Vec::new();
        for i in 0..5 {
            for j in 0..4 {
                pts.push([i as f32 * 0.1, j as f32 * 0.1, 0.0]);
            }
        }
        pts.push([0.45, 0.35, 0.3]);
        let nb: Vec<(f32, u32)> = (0..pts.len() as u32).map(|i| (0.0, i)).collect();
        let plain = fit_normal(&pts, &nb, false).unwrap();
        let robust = fit_normal(&pts, &nb, true).unwrap();
        assert!(robust[2].abs() > plain[2].abs());
        assert!(robust[2].abs() > 0.999, "{robust:?}");
    }

    #[test]
    fn a_line_has_no_normal() {
        let pts: Vec<[f32; 3]> = (0..10).map(|i| [i as f32, 2.0 * i as f32, 0.0]).collect();
        let nb: Vec<(f32, u32)> = (0..10).map(|i| (0.0, i)).collect();
        assert!(fit_normal(&pts, &nb, false).is_none());
        assert!(fit_normal(&pts[..2], &nb[..2], false).is_none());
    }
}
