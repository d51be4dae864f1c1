//! The coarse global solution (step 1 of the two-level scheme) and the check that the input
//! spans a volume.

use std::path::Path;

use super::fft_solve::LocalGrid;
use super::plan::Plan;
use crate::error::{Error, Result};
use crate::recon::pou::quantise;
use crate::types::Axis;

/// The coarse global solution.
pub struct CoarseField {
    grid: LocalGrid,
    values: Vec<f32>,
    r: i64,
    pad: i64,
}

impl CoarseField {
    /// The solution `values` on `plan`'s coarse grid.
    pub fn new(plan: &Plan, values: Vec<f32>) -> CoarseField {
        CoarseField {
            grid: plan.coarse_grid(),
            values,
            r: plan.coarse_ratio as i64,
            pad: plan.coarse_pad as i64,
        }
    }

    /// The coarse grid.
    pub fn grid(&self) -> &LocalGrid {
        &self.grid
    }

    /// What a block of `dims` fine nodes from node `lo` reads of the coarse solution, for
    /// [`crate::types::Blend`]: the coarse nodes around it in fixed point (`unit`;
    /// indices clamped to the grid), per-axis trilinear tables, and `log2 r`.
    pub fn block(
        &self,
        lo: [i64; 3],
        dims: [usize; 3],
        unit: f32,
    ) -> (Vec<i32>, [usize; 3], [Axis; 3]) {
        let n = self.grid.n as i64;
        let r = self.r;
        let mut axes: [Axis; 3] = Default::default();
        let mut first = [0i64; 3];
        let mut cdims = [0usize; 3];
        for a in 0..3 {
            let u0 = lo[a] + self.pad * r;
            first[a] = u0.div_euclid(r);
            cdims[a] = ((u0 + dims[a] as i64 - 1).div_euclid(r) + 2 - first[a]) as usize;
            let ax = &mut axes[a];
            for p in 0..dims[a] as i64 {
                let u = u0 + p;
                ax.c0.push((u.div_euclid(r) - first[a]) as u32);
                ax.w0.push((r - u.rem_euclid(r)) as i32);
                ax.w1.push(u.rem_euclid(r) as i32);
            }
        }
        let at = |a: usize, j: usize| (first[a] + j as i64).clamp(0, n - 1) as usize;
        let mut raw = Vec::with_capacity(cdims.iter().product());
        for z in 0..cdims[2] {
            for y in 0..cdims[1] {
                for x in 0..cdims[0] {
                    let g = self.grid.n;
                    raw.push(self.values[(at(2, z) * g + at(1, y)) * g + at(0, x)]);
                }
            }
        }
        (quantise(&raw, unit), cdims, axes)
    }

    /// The largest magnitude of a coarse value.
    pub fn max_abs(&self) -> f64 {
        self.values.iter().fold(0f64, |m, v| m.max(v.abs() as f64))
    }

    /// Value at a world point.
    pub fn eval(&self, p: [f64; 3]) -> f64 {
        self.grid.eval(&self.values, p)
    }

    /// Minimum and maximum over the coarse nodes that influence fine nodes `lo..=hi`.
    pub fn range(&self, lo: [i64; 3], hi: [i64; 3]) -> (f32, f32) {
        let n = self.grid.n as i64;
        let c0 = lo.map(|v| ((v + self.pad * self.r).div_euclid(self.r)).clamp(0, n - 1));
        let c1 = hi.map(|v| ((v + self.pad * self.r).div_euclid(self.r) + 1).clamp(0, n - 1));
        let mut mn = f32::INFINITY;
        let mut mx = f32::NEG_INFINITY;
        for z in c0[2]..=c1[2] {
            for y in c0[1]..=c1[1] {
                for x in c0[0]..=c1[0] {
                    let v = self.values[((z * n + y) * n + x) as usize];
                    mn = mn.min(v);
                    mx = mx.max(v);
                }
            }
        }
        (mn, mx)
    }
}

/// First and second moments of the input points about an origin, to refuse point sets that
/// span no volume.
#[derive(Debug, Clone, Copy)]
pub struct Moments {
    origin: [f64; 3],
    /// Count, Σx, Σy, Σz, Σx², Σy², Σz², Σxy, Σxz, Σyz.
    m: [f64; 10],
}

impl Moments {
    /// No points yet; coordinates are taken relative to `origin` (for precision).
    pub fn new(origin: [f64; 3]) -> Moments {
        Moments {
            origin,
            m: [0.0; 10],
        }
    }

    /// Add point `p`.
    pub fn add(&mut self, p: [f64; 3]) {
        let c = self.origin;
        let q = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
        let m = &mut self.m;
        m[0] += 1.0;
        m[1] += q[0];
        m[2] += q[1];
        m[3] += q[2];
        m[4] += q[0] * q[0];
        m[5] += q[1] * q[1];
        m[6] += q[2] * q[2];
        m[7] += q[0] * q[1];
        m[8] += q[0] * q[2];
        m[9] += q[1] * q[2];
    }

    /// Refuse point sets that span no volume: a plane or a line has no inside. Errors name
    /// `dir` (the store).
    pub fn check_not_flat(&self, dir: &Path) -> Result<()> {
        let m = &self.m;
        let n = m[0];
        let mean = [m[1] / n, m[2] / n, m[3] / n];
        let cov = nalgebra::Matrix3::new(
            m[4] / n - mean[0] * mean[0],
            m[7] / n - mean[0] * mean[1],
            m[8] / n - mean[0] * mean[2],
            m[7] / n - mean[0] * mean[1],
            m[5] / n - mean[1] * mean[1],
            m[9] / n - mean[1] * mean[2],
            m[8] / n - mean[0] * mean[2],
            m[9] / n - mean[1] * mean[2],
            m[6] / n - mean[2] * mean[2],
        );
        let mut ev: Vec<f64> = cov.symmetric_eigen().eigenvalues.iter().copied().collect();
        ev.sort_by(|a, b| a.total_cmp(b));
        let top = ev[2].max(f64::MIN_POSITIVE);
        if ev[1] <= 1e-12 * top {
            return Err(Error::input(
                dir,
                "all points lie on a line: a surface needs points spread in three dimensions",
            ));
        }
        if ev[0] <= 1e-12 * top {
            return Err(Error::input(
                dir,
                "all points lie on a plane: a closed surface needs points spread in three dimensions",
            ));
        }
        Ok(())
    }
}
