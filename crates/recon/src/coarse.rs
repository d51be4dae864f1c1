//! The coarse solution a level of leaves refines (step 1 of the two-level scheme, and the
//! levels above in the recursive scheme), the blend of a block's field from it and the leaf
//! details (step 3: [`tile_blend`], [`blend_block`]), and the check that the input spans a
//! volume. The field and the blend are one recursion: a level above the dense solve is read
//! through the blend of its own coarse field and details.

use std::borrow::Cow;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use super::blend::leaves_near;
use super::checkpoint::leaf_detail;
use super::grid::LocalGrid;
use super::plan::Plan;
use crate::error::{Error, Result};
use crate::exec::cache::Lru;
use crate::extract::field::BlendEval;
use crate::pou::{leaf_weights, quantise};
use crate::types::{Axis, Blend, CellKey, Detail, Leaf};

/// Coarse values on a grid: the dense global solve of the coarsest level, or a window of a
/// level above ([`CoarseField::local`]). Fine node `g` reads node `g/r + pad` (per axis).
#[derive(Clone)]
pub struct CoarseGrid {
    grid: LocalGrid,
    values: Vec<f32>,
    pad: [i64; 3],
}

impl CoarseGrid {
    /// The grid.
    pub fn grid(&self) -> &LocalGrid {
        &self.grid
    }

    /// Value at a world point (trilinear; a window answers within the fine nodes it was
    /// made for).
    pub fn eval(&self, p: [f64; 3]) -> f64 {
        self.grid.eval(&self.values, p)
    }

    /// Nodes `first .. first + dims` (indices clamped to the grid), x fastest.
    fn copy(&self, first: [i64; 3], dims: [usize; 3]) -> Vec<f32> {
        let g = self.grid.n;
        let at = |a: usize, j: usize| (first[a] + j as i64).clamp(0, g as i64 - 1) as usize;
        let mut raw = Vec::with_capacity(dims.iter().product());
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    raw.push(self.values[(at(2, z) * g + at(1, y)) * g + at(0, x)]);
                }
            }
        }
        raw
    }
}

/// The coarse solution a level of leaves refines: the dense global solve, or (the recursive
/// scheme, [`super::plan::levels`]) the blended field of the level above, read where it is
/// needed.
pub struct CoarseField {
    /// Fine voxels per coarse node (`r`).
    r: i64,
    kind: Kind,
}

enum Kind {
    Dense(CoarseGrid),
    Level(Box<Level>),
}

/// A level of the recursive scheme seen as the coarse field of the level below it: its
/// nodes are the coarse nodes below (its node `J` on fine node `rJ` there), its value there
/// the blend of its own coarse field and its leaves' details ([`blend_block`]),
/// exact in the run's fixed point.
pub struct Level {
    /// The level's grids (its fine spacing is the coarse spacing of the level below).
    plan: Plan,
    /// What the level refines.
    coarse: CoarseField,
    /// The level's refined leaves.
    refined: BTreeSet<CellKey>,
    /// Where their details are ([`crate::checkpoint::leaf_detail`]).
    dir: PathBuf,
    /// The run's fixed-point unit.
    unit: f32,
    /// The leaves' per-axis weights ([`crate::pou::leaf_weights`]).
    own: Vec<i32>,
    /// Details read lately: the leaves below read the same few as they go in Morton order.
    cache: Mutex<Lru<CellKey, Arc<Detail>>>,
}

impl Level {
    /// A level: `plan`'s leaves `refined` (their details in `dir`, fixed point `unit`)
    /// over `coarse`, keeping up to `cache_bytes` of decoded details.
    pub fn new(
        plan: Plan,
        coarse: CoarseField,
        refined: BTreeSet<CellKey>,
        dir: PathBuf,
        unit: f32,
        cache_bytes: u64,
    ) -> Level {
        Level {
            own: leaf_weights(plan.leaf_voxels as i64, plan.overlap_voxels as i64),
            plan,
            coarse,
            refined,
            dir,
            unit,
            cache: Mutex::new(Lru::new(cache_bytes)),
        }
    }

    /// The detail of refined leaf `k`, from the cache or its checkpoint.
    fn detail(&self, k: CellKey) -> Result<Arc<Detail>> {
        let hit = self.cache.lock().ok().and_then(|mut c| c.get(&k).cloned());
        if let Some(d) = hit {
            return Ok(d);
        }
        let d = Arc::new(leaf_detail(&self.dir, k, self.plan.detail_n())?);
        if let Ok(mut c) = self.cache.lock() {
            c.insert(k, Arc::clone(&d), 2 * d.values.len() as u64);
        }
        Ok(d)
    }

    /// The level's field on its nodes `lo .. lo + dims` (x fastest): every value a whole
    /// number of units, so that quantising it again gives the same integers.
    fn values(&self, lo: [i64; 3], dims: [usize; 3]) -> Result<Vec<f32>> {
        let hi = [0, 1, 2].map(|a| lo[a] + dims[a] as i64 - 1);
        let details = leaves_near(&self.plan, &self.refined, lo, hi)
            .into_iter()
            .map(|k| Ok((k, self.detail(k)?)))
            .collect::<Result<Vec<_>>>()?;
        blend_block(
            &self.plan,
            &self.own,
            &self.coarse,
            self.unit,
            lo,
            dims,
            &details,
        )?
        .try_eval()
    }
}

impl CoarseField {
    /// The solution `values` on `plan`'s coarse grid.
    pub fn new(plan: &Plan, values: Vec<f32>) -> CoarseField {
        CoarseField {
            r: plan.coarse_ratio as i64,
            kind: Kind::Dense(CoarseGrid {
                grid: plan.coarse_grid(),
                values,
                pad: [plan.coarse_pad as i64; 3],
            }),
        }
    }

    /// The field of `level` as the coarse field of the level below, whose coarse ratio is
    /// `r`.
    pub fn level(level: Level, r: u64) -> CoarseField {
        CoarseField {
            r: r as i64,
            kind: Kind::Level(Box::new(level)),
        }
    }

    /// Levels of leaves between this field and the dense solve (0: it is the dense solve).
    pub fn levels(&self) -> usize {
        match &self.kind {
            Kind::Dense(_) => 0,
            Kind::Level(l) => 1 + l.coarse.levels(),
        }
    }

    /// The first coarse node, node count and trilinear tables of a block of `dims` fine
    /// nodes from node `lo`.
    fn tables(&self, lo: [i64; 3], dims: [usize; 3]) -> ([i64; 3], [usize; 3], [Axis; 3]) {
        let r = self.r;
        let pad = match &self.kind {
            Kind::Dense(d) => d.pad,
            Kind::Level(_) => [0; 3],
        };
        let mut axes: [Axis; 3] = Default::default();
        let mut first = [0i64; 3];
        let mut cdims = [0usize; 3];
        for a in 0..3 {
            let u0 = lo[a] + pad[a] * r;
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
        (first, cdims, axes)
    }

    /// What a block of `dims` fine nodes from node `lo` reads of the coarse solution, for
    /// [`crate::types::Blend`]: the coarse nodes around it in fixed point (`unit`;
    /// indices clamped to a dense grid), per-axis trilinear tables, and `log2 r`.
    pub fn block(
        &self,
        lo: [i64; 3],
        dims: [usize; 3],
        unit: f32,
    ) -> Result<(Vec<i32>, [usize; 3], [Axis; 3])> {
        let (first, cdims, axes) = self.tables(lo, dims);
        let raw = match &self.kind {
            Kind::Dense(d) => d.copy(first, cdims),
            Kind::Level(l) => l.values(first, cdims)?,
        };
        Ok((quantise(&raw, unit), cdims, axes))
    }

    /// The coarse values around fine nodes `lo..=hi` (and a coarse node beyond) as a grid
    /// that [`CoarseGrid::eval`] reads there: the dense solve itself, or a window of the
    /// level above.
    pub fn local(&self, lo: [i64; 3], hi: [i64; 3]) -> Result<Cow<'_, CoarseGrid>> {
        let l = match &self.kind {
            Kind::Dense(d) => return Ok(Cow::Borrowed(d)),
            Kind::Level(l) => l,
        };
        let c0 = lo.map(|v| v.div_euclid(self.r) - 1);
        let c1 = hi.map(|v| v.div_euclid(self.r) + 2);
        let n = (0..3)
            .map(|a| (c1[a] - c0[a] + 1) as usize)
            .max()
            .unwrap_or(1);
        Ok(Cow::Owned(CoarseGrid {
            grid: LocalGrid {
                n,
                h: l.plan.spacing,
                origin: l.plan.node_pos(c0),
                unit: l.plan.cube.size,
            },
            values: l.values(c0, [n; 3])?,
            pad: c0.map(|v| -v),
        }))
    }

    /// The dense solve's node values (none for a level's field).
    pub fn dense_values(&self) -> Option<&[f32]> {
        match &self.kind {
            Kind::Dense(d) => Some(&d.values),
            Kind::Level(_) => None,
        }
    }

    /// The largest magnitude of a value of the dense solve (every level above shares its
    /// fixed-point unit).
    pub fn max_abs(&self) -> f64 {
        match &self.kind {
            Kind::Dense(d) => d.values.iter().fold(0f64, |m, v| m.max(v.abs() as f64)),
            Kind::Level(l) => l.coarse.max_abs(),
        }
    }

    /// Minimum and maximum over the coarse nodes that influence fine nodes `lo..=hi`. Above
    /// the dense solve, where no leaf of the level reaches them, it is the range of the
    /// level's own coarse nodes there (which bound its values); otherwise the level's
    /// values are blended.
    pub fn range(&self, lo: [i64; 3], hi: [i64; 3]) -> Result<(f32, f32)> {
        let r = self.r;
        match &self.kind {
            Kind::Dense(d) => {
                let n = d.grid.n as i64;
                let c0 = [0, 1, 2].map(|a| ((lo[a] + d.pad[a] * r).div_euclid(r)).clamp(0, n - 1));
                let c1 =
                    [0, 1, 2].map(|a| ((hi[a] + d.pad[a] * r).div_euclid(r) + 1).clamp(0, n - 1));
                let dims = [0, 1, 2].map(|a| (c1[a] - c0[a] + 1) as usize);
                Ok(min_max(&d.copy(c0, dims)))
            }
            Kind::Level(l) => {
                let c0 = lo.map(|v| v.div_euclid(r));
                let c1 = hi.map(|v| v.div_euclid(r) + 1);
                if leaves_near(&l.plan, &l.refined, c0, c1).is_empty() {
                    return l.coarse.range(c0, c1);
                }
                let dims = [0, 1, 2].map(|a| (c1[a] - c0[a] + 1) as usize);
                Ok(min_max(&l.values(c0, dims)?))
            }
        }
    }
}

/// The least and the largest of `v`.
fn min_max(v: &[f32]) -> (f32, f32) {
    v.iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        })
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

    /// The sums: count, Σx, Σy, Σz, Σx², Σy², Σz², Σxy, Σxz, Σyz (for a checkpoint).
    pub fn sums(&self) -> [f64; 10] {
        self.m
    }

    /// The moments about `origin` whose sums are `m` ([`Moments::sums`]).
    pub fn with_sums(origin: [f64; 3], m: [f64; 10]) -> Moments {
        Moments { origin, m }
    }

    /// Add the points `other` holds (taken relative to the same origin).
    pub fn merge(&mut self, other: &Moments) {
        for (a, b) in self.m.iter_mut().zip(&other.m) {
            *a += b;
        }
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

/// A tile's `(T+1)³` nodes from fine node `lo` as a blend ([`Blend`]) of the coarse solution
/// and the leaf details `details` (fixed point in `unit`), with per-axis leaf weights `own`
/// ([`super::pou::leaf_weights`]). The extraction stage evaluates it (on the CPU or the GPU).
pub fn tile_blend<'a>(
    plan: &Plan,
    own: &[i32],
    coarse: &CoarseField,
    unit: f32,
    lo: [i64; 3],
    details: &'a [(CellKey, Arc<Detail>)],
) -> Result<Blend<'a>> {
    let dims = [(plan.tile + 1) as usize; 3];
    blend_block(plan, own, coarse, unit, lo, dims, details)
}

/// [`tile_blend`] for any block of `dims` nodes from fine node `lo` (a level of the recursive
/// scheme blends the windows the level below reads, [`CoarseField::local`]). Reading the
/// coarse values of a level above fails only on its leaves' checkpoints.
pub fn blend_block<'a>(
    plan: &Plan,
    own: &[i32],
    coarse: &CoarseField,
    unit: f32,
    lo: [i64; 3],
    dims: [usize; 3],
    details: &'a [(CellKey, Arc<Detail>)],
) -> Result<Blend<'a>> {
    let (cvals, coarse_dims, axes) = coarse.block(lo, dims, unit)?;
    Ok(Blend {
        lo,
        dims,
        axes,
        coarse: cvals,
        coarse_dims,
        coarse_bits: plan.coarse_ratio.trailing_zeros(),
        e: plan.leaf_voxels as i64,
        ov: plan.overlap_voxels as i64,
        own: own.to_vec(),
        unit,
        leaves: details
            .iter()
            .map(|(k, d)| Leaf {
                cell: k.decode().1.map(|v| v as i64),
                id: k.0,
                detail: &d.values,
                shift: d.shift,
            })
            .collect(),
    })
}
