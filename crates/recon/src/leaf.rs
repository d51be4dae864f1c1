//! One leaf's solve (step 2 of the two-level scheme): its fine and coarse local solves, their
//! difference on the cell and its overlap, and the paper's refinement test.

pub use super::checkpoint::LeafDetail;
use super::coarse::CoarseGrid;
use super::fft_solve::Solver;
use super::gpu_solve::{GpuSolveStats, GpuSolver};
use super::grid::{LocalGrid, splat};
use super::plan::Plan;
use super::screen::{Screen, ScreenBuilder};
use super::voxel_sum::{OnLattice, VOXEL_SUM_BYTES, VoxelSum, restrict, splat_voxels};
use crate::extract::gpu::GpuMode;
use crate::pou::quantise_detail;
use crate::types::CellKey;

/// The points a leaf solves: those of its cell first, then those of the rest of its 1.3125× box.
/// A leaf of a level above the finest reads dense store cells summed per voxel of its
/// lattice instead ([`VoxelSum`]), in the same order: the cell's first.
#[derive(Debug, Default)]
pub struct LeafPoints {
    /// Positions, world frame.
    pub pos: Vec<[f64; 3]>,
    /// Unit normals.
    pub nrm: Vec<[f32; 3]>,
    /// How many of the points (the first ones) lie in the cell itself.
    pub own: usize,
    /// The samples of dense store cells, summed per voxel of the leaf's lattice.
    pub voxels: Vec<VoxelSum>,
    /// How many of `voxels` (the first ones) lie in the cell itself.
    pub own_voxels: usize,
}

/// Bytes a point of [`LeafPoints`] holds: position f64×3 and normal f32×3.
pub const LEAF_POINT_BYTES: u64 = 36;

impl LeafPoints {
    /// The samples in the cell itself, points and summed alike.
    pub fn own_count(&self) -> u64 {
        self.own as u64
            + self.voxels[..self.own_voxels]
                .iter()
                .map(|s| s.count as u64)
                .sum::<u64>()
    }

    /// Bytes the samples hold.
    pub fn bytes(&self) -> u64 {
        self.pos.len() as u64 * LEAF_POINT_BYTES + self.voxels.len() as u64 * VOXEL_SUM_BYTES
    }

    /// The splatted normals on `grid`, placed on the leaf's lattice by `on`.
    fn splat(&self, grid: &LocalGrid, on: OnLattice) -> Vec<[f32; 3]> {
        let mut v = vec![[0f32; 3]; grid.len()];
        splat(grid, &self.pos, &self.nrm, &mut v);
        splat_voxels(grid, on, &self.voxels, &mut v);
        v
    }

    /// The screening of the samples on `grid` (placed by `on`) with weight `alpha`.
    fn screen(&self, grid: &LocalGrid, on: OnLattice, alpha: f64) -> Screen {
        if alpha <= 0.0 {
            return ScreenBuilder::new(grid).finish(alpha);
        }
        let mut b = ScreenBuilder::dense(grid);
        b.add(&self.pos);
        b.add_voxels(on, &self.voxels);
        b.finish(alpha)
    }

    /// `Σ f(p)` over the cell's samples: each point once, each voxel's mean as many times as
    /// it sums points.
    fn own_sum(&self, mut f: impl FnMut([f64; 3]) -> f64) -> f64 {
        let mut sum = 0.0;
        for p in &self.pos[..self.own] {
            sum += f(*p);
        }
        for s in &self.voxels[..self.own_voxels] {
            sum += s.count as f64 * f(s.mean);
        }
        sum
    }
}

/// The two solvers every leaf uses: its fine grid and its coarse local grid.
pub struct LeafSolvers {
    fine: Solver,
    coarse: Solver,
    /// The fine solves on a GPU (`--gpu-solve`), when one was opened.
    gpu: Option<GpuSolver>,
}

impl LeafSolvers {
    /// The solvers of `plan`'s leaves (all leaves share one grid size).
    pub fn new(plan: &Plan) -> LeafSolvers {
        let fine = plan.leaf_fine_grid(CellKey::new(plan.leaf_level, [0; 3]));
        LeafSolvers {
            fine: Solver::new(&fine, plan.sigma_vox),
            coarse: Solver::new(&leaf_coarse_grid(plan, &fine), plan.coarse_sigma_vox),
            gpu: None,
        }
    }

    /// The fine solves on a GPU as `mode` says ([`GpuSolver::new`]).
    pub fn with_gpu(mut self, mode: GpuMode) -> crate::error::Result<LeafSolvers> {
        self.gpu = GpuSolver::new(mode, &self.fine)?;
        Ok(self)
    }

    /// What the GPU did, when the fine solves run on one.
    pub fn gpu_stats(&self) -> Option<(String, GpuSolveStats)> {
        self.gpu
            .as_ref()
            .map(|g| (g.adapter_name().to_string(), g.stats()))
    }
}

/// A leaf's coarse local grid: its fine grid at the coarse spacing (node `J` on fine node `rJ`).
fn leaf_coarse_grid(plan: &Plan, fine: &LocalGrid) -> LocalGrid {
    LocalGrid {
        n: fine.n / plan.coarse_ratio as usize,
        h: fine.h * plan.coarse_ratio as f64,
        origin: fine.origin,
        unit: fine.unit,
    }
}

/// Solve leaf `key` on its points `pts`: the detail (fine minus upsampled coarse local
/// solution) in fixed point `unit`, and the cell's samples' share of the iso-value.
pub fn solve_leaf(
    plan: &Plan,
    unit: f32,
    solvers: &LeafSolvers,
    key: CellKey,
    pts: &LeafPoints,
    coarse: &CoarseGrid,
) -> LeafDetail {
    let fine = plan.leaf_fine_grid(key);
    let coarse_local = leaf_coarse_grid(plan, &fine);
    let alpha = plan.point_weight;
    let origin = plan.leaf_lattice(key);
    let on_fine = OnLattice { origin, step: 1 };
    let on_coarse = OnLattice {
        origin,
        step: plan.coarse_ratio as i64,
    };
    let v = pts.splat(&fine, on_fine);
    // The coarse local splat: the fine one restricted where the leaf reads sums (a sum's
    // corners are fine nodes, [`restrict`]); the points themselves otherwise.
    let vc = if pts.voxels.is_empty() {
        pts.splat(&coarse_local, on_coarse)
    } else {
        restrict(&v, fine.n, plan.coarse_ratio as usize)
    };
    let screen = pts.screen(&fine, on_fine, alpha);
    let (f, conv) = match &solvers.gpu {
        Some(g) => g.solve_splatted(&solvers.fine, &fine, v, &screen),
        None => solvers.fine.solve_screened(&fine, v, &screen),
    };
    drop(screen);
    let (c, _) = solvers.coarse.solve_screened(
        &coarse_local,
        vc,
        &pts.screen(&coarse_local, on_coarse, alpha),
    );
    let m = plan.detail_n();
    let nc = coarse_local.n;
    // Per axis, detail node s sits on fine node q = pad − ov + s, between coarse nodes
    // ⌊q/r⌋ and ⌊q/r⌋ + 1 (clamped) with weights 1 − t and t, t = (q mod r)/r.
    let r = plan.coarse_ratio as i64;
    let q0 = plan.leaf_pad() as i64 - plan.overlap_voxels as i64;
    let axis: Vec<([usize; 2], [f32; 2])> = (0..m as i64)
        .map(|s| {
            let q = q0 + s;
            let j = q.div_euclid(r);
            let t = q.rem_euclid(r) as f32 / r as f32;
            let at = |d: i64| (j + d).min(nc as i64 - 1) as usize;
            ([at(0), at(1)], [1.0 - t, t])
        })
        .collect();
    let mut detail = Vec::with_capacity(m * m * m);
    for sz in 0..m {
        let (iz, wz) = axis[sz];
        for sy in 0..m {
            let (iy, wy) = axis[sy];
            let frow = ((q0 as usize + sz) * fine.n + q0 as usize + sy) * fine.n + q0 as usize;
            for (sx, &(ix, wx)) in axis.iter().enumerate() {
                let fv = f[frow + sx];
                // Coarse local, upsampled trilinearly (a zero weight adds a zero).
                let mut acc = 0f32;
                for cc in 0..8 {
                    let (dx, dy, dz) = (cc & 1, (cc >> 1) & 1, (cc >> 2) & 1);
                    let w = wx[dx] * wy[dy] * wz[dz];
                    acc += w * c[(iz[dz] * nc + iy[dy]) * nc + ix[dx]];
                }
                detail.push(fv - acc);
            }
        }
    }
    let iso_sum = pts.own_sum(|p| coarse.eval(p) + fine.eval(&f, p) - coarse_local.eval(&c, p));
    LeafDetail {
        detail: Some(quantise_detail(&detail, unit)),
        iso_sum,
        iso_count: pts.own_count(),
        iterations: conv.iterations,
    }
}

/// The paper's refinement test against the coarse solution: the mean distance of a 10%
/// sample of the cell's points (every tenth) to the coarse field's level set through them,
/// to first order `|F(p) − F̄| / |∇F(p)|`, with `F̄` the mean of `F` over the sample. Where
/// the cell's points are summed per voxel, each voxel's mean joins the sample.
pub fn coarse_error(coarse: &CoarseGrid, pts: &LeafPoints) -> f64 {
    let own = &pts.pos[..pts.own];
    let sample: Vec<[f64; 3]> = own
        .iter()
        .step_by(10)
        .copied()
        .chain(pts.voxels[..pts.own_voxels].iter().map(|s| s.mean))
        .collect();
    if sample.is_empty() {
        return 0.0;
    }
    let vals: Vec<f64> = sample.iter().map(|p| coarse.eval(*p)).collect();
    let level = vals.iter().sum::<f64>() / vals.len() as f64;
    let d = 0.5 * coarse.grid().h;
    let mut sum = 0.0;
    for (p, v) in sample.iter().zip(&vals) {
        let mut g2 = 0.0;
        for a in 0..3 {
            let mut hi = *p;
            let mut lo = *p;
            hi[a] += d;
            lo[a] -= d;
            let g = (coarse.eval(hi) - coarse.eval(lo)) / (2.0 * d);
            g2 += g * g;
        }
        let g = g2.sqrt();
        sum += if g > 0.0 {
            (v - level).abs() / g
        } else {
            f64::INFINITY
        };
    }
    sum / sample.len() as f64
}

/// A leaf left to the coarse solution: no detail, its samples' share of the iso-value.
pub fn coarse_only(pts: &LeafPoints, coarse: &CoarseGrid) -> LeafDetail {
    LeafDetail {
        detail: None,
        iso_sum: pts.own_sum(|p| coarse.eval(p)),
        iso_count: pts.own_count(),
        iterations: 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::coarse::CoarseField;
    use crate::types::Cube;
    use crate::voxel_sum::sum_voxels;

    type Sample = (bool, [u32; 3], [f64; 3], [f32; 3]);

    #[test]
    fn a_leaf_solves_the_same_from_its_points_and_from_their_voxel_sums() {
        // A sphere of radius 0.3 in the unit cube at depth 7 (r = 4, leaves of 32 voxels),
        // 400K points: about 25 a voxel. The leaf holding (0.8, 0.5, 0.5) reads the points
        // of its 1.3125× box one by one, then summed per voxel.
        let cube = Cube {
            origin: [0.0; 3],
            size: 1.0,
        };
        let plan = Plan::with_ratio(cube, 7, 1.0, 4.0, None, 4);
        let key = CellKey::new(
            plan.leaf_level,
            cube.cell_coords([0.8, 0.5, 0.5], plan.leaf_level),
        );
        let cell = cube.cell_box(key);
        let reach = cell.grown(crate::plan::LEAF_REACH * (cell.max[0] - cell.min[0]));
        let n = 400_000;
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        // (beyond the cell, voxel z y x, position, normal)
        let mut sample: Vec<Sample> = Vec::new();
        for i in 0..n {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let t = golden * i as f64;
            let d = [r * t.cos(), r * t.sin(), z];
            let p = d.map(|v| 0.5 + 0.3 * v);
            if reach.contains(p) {
                let own = cube.cell_coords(p, plan.leaf_level) == key.decode().1;
                let v = cube.cell_coords(p, plan.depth);
                sample.push((!own, [v[2], v[1], v[0]], p, d.map(|v| v as f32)));
            }
        }
        // Own first (as `PointSource::gather_wave` hands them), then by voxel.
        sample.sort_by_key(|a| (a.0, a.1));
        let own = sample.iter().filter(|s| !s.0).count();
        let pos: Vec<[f64; 3]> = sample.iter().map(|s| s.2).collect();
        let nrm: Vec<[f32; 3]> = sample.iter().map(|s| s.3).collect();
        let vox: Vec<[u32; 3]> = sample.iter().map(|s| [s.1[2], s.1[1], s.1[0]]).collect();
        let points = LeafPoints {
            pos: pos.clone(),
            nrm: nrm.clone(),
            own,
            ..LeafPoints::default()
        };
        let (own_v, rest_v) = (
            sum_voxels(&pos[..own], &nrm[..own], &vox[..own], &cube, plan.depth),
            sum_voxels(&pos[own..], &nrm[own..], &vox[own..], &cube, plan.depth),
        );
        assert!(
            own_v.len() * 10 < own,
            "{} sums of {own} points",
            own_v.len()
        );
        let sums = LeafPoints {
            own_voxels: own_v.len(),
            voxels: [own_v, rest_v].concat(),
            ..LeafPoints::default()
        };
        assert_eq!(sums.own_count(), own as u64);
        let nodes = plan.coarse_nodes as usize;
        let field = CoarseField::new(&plan, vec![0.0; nodes * nodes * nodes]);
        let lo = plan.leaf_node(key);
        let coarse = field.local(lo, lo.map(|v| v + 32)).unwrap();
        let solvers = LeafSolvers::new(&plan);
        let unit = 1e-3;
        let a = solve_leaf(&plan, unit, &solvers, key, &points, &coarse);
        let b = solve_leaf(&plan, unit, &solvers, key, &sums, &coarse);
        assert_eq!(a.iterations, b.iterations);
        assert_eq!(a.iso_count, b.iso_count);
        let values = |d: &LeafDetail| {
            let d = d.detail.as_ref().unwrap();
            let s = (1u64 << d.shift) as f64;
            d.values.iter().map(|&v| v as f64 * s).collect::<Vec<f64>>()
        };
        let (va, vb) = (values(&a), values(&b));
        let big = va.iter().fold(0f64, |m, v| m.max(v.abs()));
        let err = va
            .iter()
            .zip(&vb)
            .fold(0f64, |m, (x, y)| m.max((x - y).abs()));
        assert!(big > 0.0 && err <= 1e-4 * big, "{err} of {big}");
    }
}
