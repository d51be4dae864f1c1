//! An upper level's samples summed per voxel of its lattice: what a leaf of a level above the
//! finest reads where its store cell is dense, instead of every point.
//!
//! A leaf uses its samples three ways, and each is a sum of a function of the sample that is
//! **multilinear** (of degree at most one in each coordinate) within a voxel of the leaf's
//! fine lattice:
//!
//! - the **splat** (Kazhdan 2005, §4; [`super::grid::splat`]): sample `i` in the voxel
//!   with lowest node `g` and offset `f_i ∈ [0, 1)³` adds `n_i w_c(f_i)` to node `g + c`,
//!   `w_c(f) = Π_a (c_a ? f_a : 1 − f_a)`, for the 8 corners `c`. Summed over the voxel's
//!   samples that is 8 vectors `N_c = Σ_i n_i w_c(f_i)`, each added to its node: the same
//!   splat. On the leaf's coarse local grid (`r` lattice spacings to its own), a sample's
//!   coarse trilinear weights are multilinear in `f_i` too, so they are reproduced exactly by
//!   trilinear interpolation between the fine voxel's corners: splatting `N_c` at corner
//!   `g + c` onto the coarse grid is the coarse splat of the samples (the full-weighting
//!   restriction of multigrid).
//! - the **screening** (Kazhdan & Hoppe 2013, §4; [`super::screen::ScreenBuilder`]): the
//!   samples are already aggregated per voxel of each grid, by their count and the sum of
//!   their offsets. A fine voxel's sums give those of the coarse voxel holding it:
//!   `Σ_i (j + f_i)/r = (j·count + Σ_i f_i)/r` for its position `j` in the coarse voxel.
//! - the **iso-value and the refinement test** ([`super::leaf`]): read at the voxel's mean
//!   sample, weighted by its count. Neither is exact there, and neither needs to be: an upper
//!   level's iso-value is not used (the finest level's is), and the refinement test is a
//!   mean distance, here over the voxels' means instead of every tenth point.
//!
//! So a voxel summed is 8 normals, a count, an offset sum and a mean: 176 bytes against 36 a
//! point. A level two octaves above the finest has 16 times the finest's points per voxel,
//! and every point is read by each leaf whose box (1.3125 times its cell) holds it, 1 to 3
//! leaves: there the leaves read and splat one sum where they read, splatted and
//! aggregated tens of points on two grids. Measured on 2 cores: a 100M-point sphere at depth
//! 11 reads 10.7M sums at depth 9 where it read 3.3 times its points, and that level's leaves
//! take 16 s instead of 68; at 10M points (6 a voxel) the level costs what it did. The finest
//! level always reads points: its iso-value and the vertex fit need them.

use super::grid::LocalGrid;
use crate::types::{Cube, wrap};

/// The samples of one voxel of a level's lattice, summed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoxelSum {
    /// The voxel's lowest node on the level's lattice (node `g` at `cube.origin + h·g`).
    pub at: [i64; 3],
    /// Per corner `c = x + 2y + 4z`, `Σ_i n_i w_c(f_i)`: the samples' weighed normals times
    /// their trilinear weights on that corner (unscaled by the grid's `1/h³`).
    pub corner: [[f32; 3]; 8],
    /// `Σ_i f_i`: the samples' offsets in the voxel, in voxels.
    pub offset: [f64; 3],
    /// The samples' mean position (world frame).
    pub mean: [f64; 3],
    /// Samples summed.
    pub count: u32,
}

/// Bytes of one [`VoxelSum`].
pub const VOXEL_SUM_BYTES: u64 = std::mem::size_of::<VoxelSum>() as u64;

/// A store cell's points are read summed per voxel where it holds at least this many points
/// a voxel: there a sum (176 bytes) costs no more memory than its points (36 bytes each in
/// the pipeline's sorted cells). Its splat is 8 node additions on the fine grid and a share
/// of one restriction per leaf on the coarse one, against 16 additions a point.
pub const SUM_MIN_POINTS_PER_VOXEL: usize = 5;

/// Where a local grid sits on a level's lattice: its node 0 on lattice node `origin`, one
/// grid spacing `step` lattice spacings (1 for a leaf's fine grid, `r` for its coarse one).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OnLattice {
    /// The lattice node of the grid's node 0.
    pub origin: [i64; 3],
    /// Lattice spacings a grid spacing.
    pub step: i64,
}

impl OnLattice {
    /// Lattice node `g` in grid coordinates, per axis: the grid voxel holding it and the
    /// offset in it, `(g − origin)/step` split into floor and fraction (exact: `step` is a
    /// power of two).
    fn locate(&self, g: [i64; 3]) -> ([i64; 3], [f64; 3]) {
        let mut v = [0i64; 3];
        let mut f = [0f64; 3];
        for a in 0..3 {
            let d = g[a] - self.origin[a];
            v[a] = d.div_euclid(self.step);
            f[a] = d.rem_euclid(self.step) as f64 / self.step as f64;
        }
        (v, f)
    }
}

/// Sum the points `pos`/`nrm` (weighed normals) per voxel of `cube`'s lattice at `depth`
/// (`2^depth` voxels an edge). `voxel` gives each point's voxel as
/// [`Cube::cell_coords`] does (offsets are clamped into it); the points of one voxel must be
/// consecutive. In the points' order: the same sums for the same points.
pub fn sum_voxels(
    pos: &[[f64; 3]],
    nrm: &[[f32; 3]],
    voxel: &[[u32; 3]],
    cube: &Cube,
    depth: u32,
) -> Vec<VoxelSum> {
    // As `Cube::cell_coords` scales: the voxel and the offset from one product.
    let inv = (1u64 << depth) as f64 / cube.size;
    let mut out = Vec::new();
    let mut s = 0;
    while s < pos.len() {
        let mut e = s + 1;
        while e < pos.len() && voxel[e] == voxel[s] {
            e += 1;
        }
        let at = voxel[s].map(|v| v as i64);
        let mut corner = [[0f64; 3]; 8];
        let mut offset = [0f64; 3];
        let mut sum = [0f64; 3];
        for (p, nn) in pos[s..e].iter().zip(&nrm[s..e]) {
            let mut w = [[0f64; 2]; 3];
            for a in 0..3 {
                let f = ((p[a] - cube.origin[a]) * inv - at[a] as f64).clamp(0.0, 1.0);
                offset[a] += f;
                sum[a] += p[a];
                w[a] = [1.0 - f, f];
            }
            for (c, acc) in corner.iter_mut().enumerate() {
                let wc = w[0][c & 1] * w[1][(c >> 1) & 1] * w[2][(c >> 2) & 1];
                for a in 0..3 {
                    acc[a] += wc * nn[a] as f64;
                }
            }
        }
        let m = (e - s) as f64;
        out.push(VoxelSum {
            at,
            corner: corner.map(|c| c.map(|v| v as f32)),
            offset,
            mean: sum.map(|v| v / m),
            count: (e - s) as u32,
        });
        s = e;
    }
    out
}

/// Add the summed normals of `voxels` to `v` (one `[f32; 3]` per node of `grid`, placed on
/// the lattice by `on`) as a density: the splat of the samples they sum
/// ([`super::grid::splat`], module docs). On a grid of the lattice's own spacing each
/// corner is one node; on a coarser one, [`restrict`] the fine splat instead where it is at
/// hand (the same sums, a tenth of the work).
pub fn splat_voxels(grid: &LocalGrid, on: OnLattice, voxels: &[VoxelSum], v: &mut [[f32; 3]]) {
    let scale = grid.splat_scale();
    let n = grid.n as i64;
    for s in voxels {
        for (c, nn) in s.corner.iter().enumerate() {
            let g = [0, 1, 2].map(|a| s.at[a] + ((c >> a) & 1) as i64);
            if on.step == 1 {
                let [x, y, z] = [0, 1, 2].map(|a| wrap(g[a] - on.origin[a], n) as usize);
                let cell = &mut v[(z * grid.n + y) * grid.n + x];
                for a in 0..3 {
                    cell[a] += scale * nn[a];
                }
            } else {
                let (at, f) = on.locate(g);
                let u = [0, 1, 2].map(|a| at[a] as f64 + f[a]);
                super::grid::splat_node(grid.n, u, *nn, scale, v);
            }
        }
    }
}

/// The splat on the grid `r` times coarser over the same periodic domain (`n/r` nodes an
/// edge, node `J` on fine node `rJ`) from the splat `fine` on `n³` nodes: the full-weighting
/// restriction `coarse[J] = r⁻³ Σ_g W_J(g) fine[g]`, `W_J` the coarse trilinear hat
/// (`Π_a (1 − |g_a − rJ_a|/r)`), one axis at a time. A coarse hat is multilinear on each fine
/// voxel, so trilinear interpolation between the fine nodes reproduces it: this is the
/// coarse splat of the samples themselves, and `r⁻³` the ratio of the two grids' densities
/// (`1/h³`).
pub fn restrict(fine: &[[f32; 3]], n: usize, r: usize) -> Vec<[f32; 3]> {
    assert!(
        n.is_multiple_of(r) && fine.len() == n * n * n,
        "{n}³ nodes restricted by {r}"
    );
    let m = n / r;
    // Taps d = −(r − 1)..=(r − 1) with weights 1 − |d|/r, and the density ratio on the last.
    let taps: Vec<(i64, f32)> = (1 - r as i64..r as i64)
        .map(|d| (d, 1.0 - d.unsigned_abs() as f32 / r as f32))
        .collect();
    // Restrict along the axis of stride `stride` (length n → m), the others of extents
    // `outer` (slowest) and `inner` (fastest) kept.
    let pass = |src: &[[f32; 3]], outer: usize, inner: usize, scale: f32| {
        let mut out = vec![[0f32; 3]; outer * m * inner];
        for o in 0..outer {
            for j in 0..m {
                for i in 0..inner {
                    let mut acc = [0f32; 3];
                    for &(d, w) in &taps {
                        let q = (j as i64 * r as i64 + d).rem_euclid(n as i64) as usize;
                        let x = src[(o * n + q) * inner + i];
                        for a in 0..3 {
                            acc[a] += w * x[a];
                        }
                    }
                    out[(o * m + j) * inner + i] = acc.map(|v| v * scale);
                }
            }
        }
        out
    };
    // x (fastest) first: n² rows of n; then y over m·n… ; then z.
    let a = pass(fine, n * n, 1, 1.0);
    let b = pass(&a, n, m, 1.0);
    let rr = r as f32;
    pass(&b, 1, m * m, 1.0 / (rr * rr * rr))
}

/// The voxel of a grid placed by `on` holding lattice voxel `s`, wrapped into the grid as its
/// nodes are, and the sum of `s`'s samples' offsets in it (in grid voxels): what
/// [`super::screen::ScreenBuilder`] aggregates per voxel.
pub fn screen_voxel(n: usize, on: OnLattice, s: &VoxelSum) -> ([usize; 3], [f64; 3]) {
    let (at, _) = on.locate(s.at);
    let mut v = [0usize; 3];
    let mut off = [0f64; 3];
    for a in 0..3 {
        let j = (s.at[a] - on.origin[a]).rem_euclid(on.step) as f64;
        off[a] = (j * s.count as f64 + s.offset[a]) / on.step as f64;
        v[a] = wrap(at[a], n as i64) as usize;
    }
    (v, off)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fft_solve::splat;
    use crate::screen::ScreenBuilder;

    /// Positions, normals and voxels.
    type Cloud = (Vec<[f64; 3]>, Vec<[f32; 3]>, Vec<[u32; 3]>);

    /// The unit cube from the origin.
    fn cube() -> Cube {
        Cube {
            origin: [0.0; 3],
            size: 1.0,
        }
    }

    /// A cloud of points on a tilted wavy sheet in a 16³-voxel block of a depth-6 lattice of
    /// spacing 1/64 from the origin, sorted by voxel, with unit-ish normals.
    fn cloud() -> Cloud {
        let mut pts: Vec<([u32; 3], [f64; 3], [f32; 3])> = Vec::new();
        // A low-discrepancy sequence (the plastic number's): spread, not on a lattice.
        let (a1, a2) = (0.754_877_666_246_692_7, 0.569_840_290_998_053_3);
        for i in 0..20000 {
            let (x, y) = (
                0.25 + 0.25 * (i as f64 * a1).fract(),
                0.25 + 0.25 * (i as f64 * a2).fract(),
            );
            let z = 0.37 + 0.1 * x + 0.02 * (40.0 * y).sin();
            let p = [x, y, z];
            let n = [-0.1f32, -(0.8 * (40.0 * y).cos()) as f32, 1.0];
            pts.push((cube().cell_coords(p, 6), p, n));
        }
        pts.sort_by(|a, b| (a.0[2], a.0[1], a.0[0]).cmp(&(b.0[2], b.0[1], b.0[0])));
        (
            pts.iter().map(|p| p.1).collect(),
            pts.iter().map(|p| p.2).collect(),
            pts.iter().map(|p| p.0).collect(),
        )
    }

    /// `got` is `want` up to float rounding (relative to its largest value).
    fn assert_close(want: &[[f32; 3]], got: &[[f32; 3]], what: &str) {
        let big = want.iter().flatten().fold(0f32, |m, v| m.max(v.abs()));
        let err = want
            .iter()
            .flatten()
            .zip(got.iter().flatten())
            .fold(0f32, |m, (a, b)| m.max((a - b).abs()));
        assert!(big > 0.0 && err < 1e-5 * big, "{what}: {err} of {big}");
    }

    #[test]
    fn voxel_sums_splat_and_screen_as_their_points_on_fine_and_coarse_grids() {
        let (pos, nrm, vox) = cloud();
        let h = 1.0 / 64.0;
        let sums = sum_voxels(&pos, &nrm, &vox, &cube(), 6);
        assert!(sums.len() * 10 < pos.len(), "{} voxels", sums.len());
        assert_eq!(
            sums.iter().map(|s| s.count as usize).sum::<usize>(),
            pos.len()
        );
        // A fine grid (one lattice spacing) and a coarse one (four), both from lattice node
        // (8, 8, 16): their node 0 sits there, and points beyond them wrap.
        for step in [1i64, 4] {
            let on = OnLattice {
                origin: [8, 8, 16],
                step,
            };
            let grid = LocalGrid {
                n: 32 / step as usize,
                h: h * step as f64,
                origin: on.origin.map(|g| g as f64 * h),
                unit: 1.0,
            };
            let mut want = vec![[0f32; 3]; grid.len()];
            splat(&grid, &pos, &nrm, &mut want);
            let mut got = vec![[0f32; 3]; grid.len()];
            splat_voxels(&grid, on, &sums, &mut got);
            assert_close(&want, &got, &format!("step {step}"));
            if step > 1 {
                // The fine splat restricted: the coarse splat, from points or from sums.
                let fine = LocalGrid { n: 32, h, ..grid };
                let mut v = vec![[0f32; 3]; fine.len()];
                splat(&fine, &pos, &nrm, &mut v);
                assert_close(&want, &restrict(&v, 32, 4), "the restricted points");
                let mut v = vec![[0f32; 3]; fine.len()];
                let on1 = OnLattice { step: 1, ..on };
                splat_voxels(&fine, on1, &sums, &mut v);
                assert_close(&want, &restrict(&v, 32, 4), "the restricted sums");
            }
            // The screening: the same aggregates, up to rounding.
            let mut a = ScreenBuilder::new(&grid);
            a.add(&pos);
            let mut b = ScreenBuilder::new(&grid);
            b.add_voxels(on, &sums);
            let (sa, sb) = (a.finish(1.0), b.finish(1.0));
            assert_eq!(sa.len(), sb.len());
            assert_eq!(sa.nodes(), sb.nodes());
            assert_eq!(sa.gamma(), sb.gamma());
            for (wa, wb) in sa.weights().iter().zip(sb.weights()) {
                for (x, y) in wa.iter().zip(wb) {
                    assert!((x - y).abs() < 1e-5, "{wa:?} {wb:?}");
                }
            }
        }
    }
}
