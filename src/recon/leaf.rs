//! One leaf's solve (step 2 of the two-level scheme): its fine and coarse local solves, their
//! difference on the cell and its overlap, and the paper's refinement test.

use super::coarse::CoarseGrid;
use super::fft_solve::{LocalGrid, Solver};
use super::gpu_solve::{GpuSolveStats, GpuSolver};
use super::plan::Plan;
use crate::extract::gpu::GpuMode;
use crate::recon::pou::quantise_detail;
use crate::types::{CellKey, Detail};

/// The points a leaf solves: those of its cell first, then those of the rest of its 1.8125× box.
#[derive(Debug, Default)]
pub struct LeafPoints {
    /// Positions, world frame.
    pub pos: Vec<[f64; 3]>,
    /// Unit normals.
    pub nrm: Vec<[f32; 3]>,
    /// How many of the points (the first ones) lie in the cell itself.
    pub own: usize,
}

/// A leaf's detail grid in the blend's fixed point (none for a leaf left to the coarse
/// solution) and its share of the iso-value.
#[derive(Debug)]
pub struct LeafDetail {
    /// The detail, `detail_n³` nodes (none: the leaf is left to the coarse solution).
    pub detail: Option<Detail>,
    /// Sum of the field at the cell's samples.
    pub iso_sum: f64,
    /// Number of the cell's samples.
    pub iso_count: u64,
    /// Conjugate-gradient iterations of the leaf's screened fine solve (0 for a leaf left to
    /// the coarse solution, or read back from a checkpoint).
    pub iterations: u32,
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
            coarse: Solver::new(&leaf_coarse_grid(plan, &fine), plan.sigma_vox),
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
    let (f, conv) = match &solvers.gpu {
        Some(g) => g.solve_points(&solvers.fine, &fine, &pts.pos, &pts.nrm, alpha),
        None => solvers.fine.solve_points(&fine, &pts.pos, &pts.nrm, alpha),
    };
    let (c, _) = solvers
        .coarse
        .solve_points(&coarse_local, &pts.pos, &pts.nrm, alpha);
    let m = plan.detail_n();
    let nc = coarse_local.n;
    // Per axis, detail node s sits on fine node q = E/2 − ov + s, between coarse nodes
    // ⌊q/r⌋ and ⌊q/r⌋ + 1 (clamped) with weights 1 − t and t, t = (q mod r)/r.
    let r = plan.coarse_ratio as i64;
    let q0 = (plan.leaf_voxels / 2) as i64 - plan.overlap_voxels as i64;
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
    let mut iso_sum = 0.0;
    for p in &pts.pos[..pts.own] {
        iso_sum += coarse.eval(*p) + fine.eval(&f, *p) - coarse_local.eval(&c, *p);
    }
    LeafDetail {
        detail: Some(quantise_detail(&detail, unit)),
        iso_sum,
        iso_count: pts.own as u64,
        iterations: conv.iterations,
    }
}

/// The paper's refinement test against the coarse solution: the mean distance of a 10%
/// sample of the cell's points (every tenth) to the coarse field's level set through them,
/// to first order `|F(p) − F̄| / |∇F(p)|`, with `F̄` the mean of `F` over the sample.
pub fn coarse_error(coarse: &CoarseGrid, pts: &LeafPoints) -> f64 {
    let own = &pts.pos[..pts.own];
    let sample: Vec<[f64; 3]> = own.iter().step_by(10).copied().collect();
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
        iso_sum: pts.pos[..pts.own].iter().map(|p| coarse.eval(*p)).sum(),
        iso_count: pts.own as u64,
        iterations: 0,
    }
}
