//! `scanflow fit --tiles`: terrain larger than memory as one hierarchical spline over the
//! store's x–y extent, solved tile by tile and written as one surface per tile.
//!
//! The parameters are the points' `(x, y)`. The domain is cut into a grid of tiles of
//! [`TILE_CELLS`]² level-0 cells, sized from the point count alone (about `--tile-points`,
//! [`TILE_POINTS`] by default, a tile), so the result does not depend on `--mem` or `--threads`. One pass over the store
//! buckets every point into its tile's file in the work directory, and into the neighbouring
//! tiles' files when it lies within their halo (two level-0 cells: the reach of the supports
//! of the functions a tile owns). The coefficients form one vector for the whole domain; a
//! tile *owns* the functions whose support's centre lies in it. Each iteration sweeps the
//! tiles [`SWEEPS`] times in row order, solving each tile's block with the others held
//! ([`crate::spline::block`], block Gauss–Seidel), then measures every point's distance to
//! its tile's piece and refines the hierarchy where the tolerance is missed, as the single
//! fit does. Every tile's surface is a piece of the same spline
//! ([`crate::spline::hier::Hierarchy::to_tensor_rect`]), so neighbouring tiles meet with
//! C2 continuity; the report gives the largest gap measured along the seams.
//!
//! Memory: the coefficient vector and the hierarchy (tens of bytes per control point), plus
//! one tile's points and block system at a time, admitted by the budget.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;

use super::fit::{FitJob, FitStats, Surface};
use crate::error::{Error, IoContext, Result};
use crate::exec::Ctx;
use crate::exec::progress::Stage;
use crate::spline::block::solve_block;
use crate::spline::fit::{Fairness, Fit, FitReport, Missed, OMEGA_FLOOR, Refine};
use crate::spline::hier::{Hierarchy, Leaf};
use crate::spline::tensor;
use crate::store::Store;
use crate::types::{Aabb, TensorSurface};

/// Points a tile aims at.
pub const TILE_POINTS: u64 = 250_000;
/// Level-0 cells along a tile's side.
pub const TILE_CELLS: i64 = 4;
/// Gauss–Seidel sweeps over the tiles per iteration.
pub const SWEEPS: usize = 2;
/// Bytes a tile's point costs while its block is solved.
const BYTES_PER_TILE_POINT: u64 = 96;
/// Bytes a free coefficient costs in a block's system (entries, factor, right-hand sides).
const BYTES_PER_COEF: u64 = 4096;
/// Record of a bucketed point: x, y, z relative to the domain's centre, f64.
const RECORD: usize = 24;

/// The tile grid.
struct Tiling {
    tiles: [i64; 2],
    h0: f64,
    /// World (x, y) of the parameter origin.
    origin: [f64; 2],
    /// World position the coordinates are taken relative to.
    centre: [f64; 3],
}

impl Tiling {
    fn new(b: &Aabb, n: u64, per_tile: u64) -> Tiling {
        let w = (b.max[0] - b.min[0]).max(0.0);
        let hh = (b.max[1] - b.min[1]).max(0.0);
        let count = n.div_ceil(per_tile.max(1)).max(1) as f64;
        let tu = ((count * w / hh.max(1e-300)).sqrt().round() as i64).clamp(1, 1 << 12);
        let tv = ((count / tu as f64).ceil() as i64).max(1);
        let margin = 0.02 * w.max(hh);
        let h0 = ((w + 2.0 * margin) / tu as f64).max((hh + 2.0 * margin) / tv as f64)
            / TILE_CELLS as f64;
        let centre = [0, 1, 2].map(|x| 0.5 * (b.min[x] + b.max[x]));
        let origin = [
            centre[0] - 0.5 * (tu * TILE_CELLS) as f64 * h0,
            centre[1] - 0.5 * (tv * TILE_CELLS) as f64 * h0,
        ];
        Tiling {
            tiles: [tu, tv],
            h0,
            origin,
            centre,
        }
    }

    fn count(&self) -> usize {
        (self.tiles[0] * self.tiles[1]) as usize
    }

    fn side(&self) -> f64 {
        TILE_CELLS as f64 * self.h0
    }

    /// Parameters of a point given relative to the centre.
    fn uv(&self, p: [f64; 3]) -> [f64; 2] {
        [
            p[0] + self.centre[0] - self.origin[0],
            p[1] + self.centre[1] - self.origin[1],
        ]
    }

    fn tile_of(&self, uv: [f64; 2]) -> [i64; 2] {
        let s = self.side();
        [
            ((uv[0] / s).floor() as i64).clamp(0, self.tiles[0] - 1),
            ((uv[1] / s).floor() as i64).clamp(0, self.tiles[1] - 1),
        ]
    }

    fn index(&self, t: [i64; 2]) -> usize {
        (t[0] + self.tiles[0] * t[1]) as usize
    }

    /// The tile's parameter box grown by `grow`.
    fn rect(&self, t: [i64; 2], grow: f64) -> [[f64; 2]; 2] {
        let s = self.side();
        [
            [t[0] as f64 * s - grow, t[1] as f64 * s - grow],
            [(t[0] + 1) as f64 * s + grow, (t[1] + 1) as f64 * s + grow],
        ]
    }

    fn halo(&self) -> f64 {
        2.0 * self.h0
    }
}

fn tile_path(dir: &Path, t: usize, own: bool) -> PathBuf {
    dir.join(format!("tile-{t}.{}", if own { "own" } else { "halo" }))
}

/// One pass over the store: every point into its tile's file and its neighbours' halos.
fn bucket(store: &Store, tl: &Tiling, dir: &Path, ctx: &Ctx) -> Result<Vec<[u64; 2]>> {
    std::fs::create_dir_all(dir).with_path(dir)?;
    let nt = tl.count();
    let buf = (ctx.budget.total() / 8 / (2 * nt as u64).max(1)).clamp(4096, 1 << 16) as usize;
    let _permit = ctx
        .budget
        .acquire(buf as u64 * 2 * nt as u64, "the tile buckets' buffers")?;
    let mut writers: Vec<BufWriter<File>> = Vec::with_capacity(2 * nt);
    for t in 0..nt {
        for own in [true, false] {
            let p = tile_path(dir, t, own);
            writers.push(BufWriter::with_capacity(
                buf,
                File::create(&p).with_path(&p)?,
            ));
        }
    }
    let mut counts = vec![[0u64; 2]; nt];
    let stage = ctx
        .progress
        .stage("bucket", Some(store.manifest.cells.len() as u64), "cells");
    for i in 0..store.manifest.cells.len() {
        let batch = store.read_cell(i)?;
        for p in &batch.pos {
            let q = [
                p[0] - tl.centre[0],
                p[1] - tl.centre[1],
                p[2] - tl.centre[2],
            ];
            let uv = tl.uv(q);
            let own = tl.tile_of(uv);
            let mut bytes = [0u8; RECORD];
            for x in 0..3 {
                bytes[8 * x..8 * x + 8].copy_from_slice(&q[x].to_le_bytes());
            }
            for dv in -1..=1 {
                for du in -1..=1 {
                    let t = [own[0] + du, own[1] + dv];
                    if t[0] < 0 || t[1] < 0 || t[0] >= tl.tiles[0] || t[1] >= tl.tiles[1] {
                        continue;
                    }
                    let is_own = du == 0 && dv == 0;
                    let r = tl.rect(t, tl.halo());
                    let inside =
                        uv[0] >= r[0][0] && uv[0] < r[1][0] && uv[1] >= r[0][1] && uv[1] < r[1][1];
                    if !is_own && !inside {
                        continue;
                    }
                    let k = tl.index(t);
                    let w = &mut writers[2 * k + usize::from(!is_own)];
                    let p = tile_path(dir, k, is_own);
                    w.write_all(&bytes).with_path(&p)?;
                    counts[k][usize::from(!is_own)] += 1;
                }
            }
        }
        stage.inc(1);
    }
    for (k, w) in writers.into_iter().enumerate() {
        let p = tile_path(dir, k / 2, k % 2 == 0);
        w.into_inner()
            .map_err(|e| Error::io(&p, e.into_error()))?
            .sync_all()
            .with_path(&p)?;
    }
    stage.finish(None);
    Ok(counts)
}

/// A tile's points (its own first, then its halo's when `halo`).
fn read_tile(dir: &Path, t: usize, halo: bool) -> Result<Vec<[f64; 3]>> {
    let mut out = Vec::new();
    for own in [true, false] {
        if !own && !halo {
            break;
        }
        let p = tile_path(dir, t, own);
        let mut r = BufReader::new(File::open(&p).with_path(&p)?);
        let mut bytes = Vec::new();
        r.read_to_end(&mut bytes).with_path(&p)?;
        if bytes.len() % RECORD != 0 {
            return Err(Error::input(&p, "a tile bucket was cut short; run again"));
        }
        out.extend(bytes.chunks_exact(RECORD).map(|c| {
            std::array::from_fn(|x| {
                f64::from_le_bytes(c[8 * x..8 * x + 8].try_into().unwrap_or([0; 8]))
            })
        }));
    }
    Ok(out)
}

/// The functions each tile owns (sorted global indices).
fn owners(h: &Hierarchy, tl: &Tiling) -> Vec<Vec<u32>> {
    let mut out = vec![Vec::new(); tl.count()];
    for (idx, l, f) in h.functions() {
        let hl = h.spacing(l);
        let centre = [(f[0] as f64 + 2.0) * hl, (f[1] as f64 + 2.0) * hl];
        out[tl.index(tl.tile_of(centre))].push(idx);
    }
    out
}

/// What every pass over the tiles of a terrain fit shares.
struct TileFit<'a> {
    store: &'a Store,
    tl: &'a Tiling,
    /// The tiles' bucketed points.
    dir: &'a Path,
    /// Each tile's points: own and halo.
    counts: &'a [[u64; 2]],
    ctx: &'a Ctx,
}

impl TileFit<'_> {
    /// [`SWEEPS`] sweeps of block Gauss–Seidel over the tiles: each tile's own coefficients
    /// solved against its points and halo, the others held (`rpiece_of`: the reference piece
    /// of data-dependent fairness, for a tile).
    fn sweeps(
        &self,
        h: &Hierarchy,
        coef: &mut [[f64; 3]],
        omega: f64,
        rpiece_of: impl Fn([i64; 2]) -> Option<TensorSurface>,
        stage: &Stage,
    ) -> Result<()> {
        let own = owners(h, self.tl);
        let mut local = vec![u32::MAX; h.len()];
        for _ in 0..SWEEPS {
            for t in 0..self.tl.count() {
                let ti = [t as i64 % self.tl.tiles[0], t as i64 / self.tl.tiles[0]];
                let m = self.counts[t][0] + self.counts[t][1];
                let _permit = self.ctx.budget.acquire(
                    m * BYTES_PER_TILE_POINT + own[t].len() as u64 * BYTES_PER_COEF,
                    "one tile's points and block system",
                )?;
                let pts = read_tile(self.dir, t, true)?;
                let uv: Vec<[f64; 2]> = pts.iter().map(|&p| self.tl.uv(p)).collect();
                let rect = self.tl.rect(ti, self.tl.halo());
                let rpiece = rpiece_of(ti);
                self.ctx
                    .pool
                    .install(|| {
                        solve_block(
                            h,
                            coef,
                            &own[t],
                            &mut local,
                            &pts,
                            &uv,
                            rect,
                            omega,
                            rpiece.as_ref(),
                        )
                    })
                    .map_err(|e| Error::input(&self.store.dir, e.to_string()))?;
                stage.inc(1);
            }
        }
        Ok(())
    }

    /// Distances of every tile's own points to its piece, and the leaves that miss
    /// `tolerance`: `(missing leaves, per tile (max, sum of squares, points), per tile the
    /// misses)`.
    #[allow(clippy::type_complexity)]
    fn measure(
        &self,
        h: &Hierarchy,
        coef: &[[f64; 3]],
        tolerance: f64,
    ) -> Result<(Vec<Leaf>, Vec<(f64, f64, u64)>, Vec<Vec<Missed>>)> {
        let nt = self.tl.count();
        // Distances of every tile's own points to its piece, and the leaves that miss.
        let mut bad: Vec<Leaf> = Vec::new();
        let mut dist: Vec<(f64, f64, u64)> = Vec::with_capacity(nt);
        let mut missed: Vec<Vec<Missed>> = Vec::with_capacity(nt);
        for t in 0..nt {
            let ti = [t as i64 % self.tl.tiles[0], t as i64 / self.tl.tiles[0]];
            let pts = read_tile(self.dir, t, false)?;
            let s = piece(h, coef, self.tl, ti, 0);
            let d: Vec<([f64; 2], f64)> = self.ctx.pool.install(|| {
                pts.par_iter()
                    .map(|&p| tensor::project(&s, p, self.tl.uv(p)))
                    .collect()
            });
            let mut m = BTreeMap::new();
            let (mut max, mut sq) = (0.0f64, 0.0f64);
            for ((q, dd), p) in d.iter().zip(&pts) {
                max = max.max(*dd);
                sq += dd * dd;
                if *dd > tolerance {
                    let leaf = h.leaf_of(*q);
                    bad.push(leaf);
                    note_missed(&mut m, h, leaf, *p, *dd, self.tl);
                }
            }
            dist.push((max, sq, pts.len() as u64));
            missed.push(m.into_values().collect());
        }
        Ok((bad, dist, missed))
    }

    /// Each tile's exported piece with its report; `run` is `(iterations, omega, tolerance)`.
    fn surfaces(
        &self,
        h: &Hierarchy,
        coef: &[[f64; 3]],
        dist: &[(f64, f64, u64)],
        missed: &[Vec<Missed>],
        run: (usize, f64, f64),
    ) -> Vec<Surface> {
        let (iterations, omega, tolerance) = run;
        let nt = self.tl.count();
        let own = owners(h, self.tl);
        let mut surfaces = Vec::with_capacity(nt);
        for t in 0..nt {
            let ti = [t as i64 % self.tl.tiles[0], t as i64 / self.tl.tiles[0]];
            let mut s = piece(h, coef, self.tl, ti, 0);
            for c in &mut s.ctrl {
                for x in 0..3 {
                    c[x] += self.tl.centre[x];
                }
            }
            let mut per_level = vec![0usize; h.levels()];
            for &f in &own[t] {
                per_level[level_of(h, f)] += 1;
            }
            let (max, sq, m) = dist[t];
            let report = FitReport {
                control_points: own[t].len(),
                per_level,
                tensor_control_points: s.ctrl.len(),
                max_deviation: max,
                rms_deviation: (sq / m.max(1) as f64).sqrt(),
                max_residual: f64::NAN,
                fairness_energy: f64::NAN,
                iterations,
                omega,
                met: max <= tolerance,
                missed: missed[t].clone(),
            };
            surfaces.push(Surface {
                fit: Fit {
                    surface: s,
                    report,
                    foot: Vec::new(),
                    distance: Vec::new(),
                },
                points: m as usize,
                from_triangles: false,
                flips: 0,
                secs: [0.0, 0.0],
            });
        }
        surfaces
    }
}

/// Fits the store as terrain, tile by tile; writes nothing (the caller writes the outputs).
pub fn fit_tiles(store: &Store, work: &Path, job: &FitJob, ctx: &Ctx) -> Result<FitStats> {
    let t0 = Instant::now();
    let mut b = Aabb::EMPTY;
    let mut n = 0u64;
    for c in &store.manifest.cells {
        b = b.union(&c.bounds);
        n += c.count;
    }
    if n < 3 {
        return Err(Error::input(
            &store.dir,
            format!("{n} points: a surface needs at least 3"),
        ));
    }
    if !(b.max[0] > b.min[0] && b.max[1] > b.min[1]) {
        return Err(Error::input(
            &store.dir,
            "the points span no area in x and y: terrain tiles are parameterised by x and y",
        ));
    }
    let diag = b.diagonal();
    let tolerance = job.tolerance.resolve(diag);
    let tl = Tiling::new(&b, n, job.tile_points);
    let dir = work.join("tiles");
    let counts = bucket(store, &tl, &dir, ctx)?;
    let secs_read = t0.elapsed().as_secs_f64();
    let cells0 = [tl.tiles[0] * TILE_CELLS, tl.tiles[1] * TILE_CELLS];
    let mut h = Hierarchy::new(tl.h0, cells0);
    // Start from the plane z = 0 (in coordinates about the centre): x and y are linear in the
    // parameters, reproduced exactly by coefficients at the functions' Greville points.
    let shift = [tl.centre[0] - tl.origin[0], tl.centre[1] - tl.origin[1]];
    let mut coef: Vec<[f64; 3]> = h
        .functions()
        .map(|(_, l, f)| {
            let hl = h.spacing(l);
            [
                (f[0] as f64 + 2.0) * hl - shift[0],
                (f[1] as f64 + 2.0) * hl - shift[1],
                0.0,
            ]
        })
        .collect();
    let mut omega = job.fit.omega;
    let max_iter = 3 * (job.fit.max_level + 1) + 6;
    let mut iterations = 0;
    let mut reference: Option<Hierarchy> = None;
    let mut ref_coef: Vec<[f64; 3]> = Vec::new();
    let stage = ctx.progress.stage("fit", None, "tile solves");
    let fit = TileFit {
        store,
        tl: &tl,
        dir: &dir,
        counts: &counts,
        ctx,
    };
    let (dist, missed) = loop {
        iterations += 1;
        let rpiece_of = |ti| match (job.fit.fairness, &reference) {
            (Fairness::Data, Some(r)) => Some(piece(r, &ref_coef, &tl, ti, 2)),
            _ => None,
        };
        fit.sweeps(&h, &mut coef, omega, rpiece_of, &stage)?;
        let (mut bad, dist, missed) = fit.measure(&h, &coef, tolerance)?;
        bad.sort_unstable();
        bad.dedup();
        if bad.is_empty() || iterations >= max_iter {
            break (dist, missed);
        }
        if job.fit.fairness == Fairness::Data {
            reference = Some(h.clone());
            ref_coef = coef.clone();
        }
        let bad = match job.fit.refine {
            Refine::Local => bad,
            Refine::Global => h.leaves(),
        };
        let old = h.clone();
        let (_, changed) = h.refine(&bad, job.fit.max_level);
        omega = (omega * 0.1).max(OMEGA_FLOOR);
        if !changed {
            break (dist, missed);
        }
        coef = old.prolong(&coef, &h);
    };
    stage.finish(None);
    let surfaces = fit.surfaces(&h, &coef, &dist, &missed, (iterations, omega, tolerance));
    let seam = seam_gap(&surfaces, &tl);
    Ok(FitStats {
        surfaces,
        input_points: n as usize,
        diagonal: diag,
        tolerance,
        secs_read,
        secs: t0.elapsed().as_secs_f64(),
        seam_gap: Some(seam),
        gaps: Vec::new(),
        point_deviation: None,
    })
}

fn level_of(h: &Hierarchy, f: u32) -> usize {
    let per = h.per_level();
    let mut acc = 0usize;
    for (l, c) in per.iter().enumerate() {
        acc += c;
        if (f as usize) < acc {
            return l;
        }
    }
    per.len() - 1
}

/// The tile's piece (its level-0 cells, grown by `grow` cells within the domain).
fn piece(h: &Hierarchy, coef: &[[f64; 3]], tl: &Tiling, t: [i64; 2], grow: i64) -> TensorSurface {
    let lo = [0, 1].map(|d| (t[d] * TILE_CELLS - grow).max(0));
    let hi = [0, 1].map(|d| ((t[d] + 1) * TILE_CELLS + grow).min(tl.tiles[d] * TILE_CELLS));
    h.to_tensor_rect(coef, [0.0; 3], lo, hi)
}

fn note_missed(
    m: &mut BTreeMap<Leaf, Missed>,
    h: &Hierarchy,
    leaf: Leaf,
    p: [f64; 3],
    d: f64,
    tl: &Tiling,
) {
    let w = [
        p[0] + tl.centre[0],
        p[1] + tl.centre[1],
        p[2] + tl.centre[2],
    ];
    let e = m.entry(leaf).or_insert_with(|| {
        let s = h.spacing(leaf.level as usize);
        let lo = [leaf.cell[0] as f64 * s, leaf.cell[1] as f64 * s];
        Missed {
            rect: [lo, [lo[0] + s, lo[1] + s]],
            bounds: [w, w],
            points: 0,
            max_deviation: 0.0,
        }
    });
    e.points += 1;
    e.max_deviation = e.max_deviation.max(d);
    for x in 0..3 {
        e.bounds[0][x] = e.bounds[0][x].min(w[x]);
        e.bounds[1][x] = e.bounds[1][x].max(w[x]);
    }
}

/// Largest distance between neighbouring tiles' surfaces, sampled along their shared edges.
fn seam_gap(surfaces: &[Surface], tl: &Tiling) -> f64 {
    let mut gap = 0.0f64;
    let s = tl.side();
    for tv in 0..tl.tiles[1] {
        for tu in 0..tl.tiles[0] {
            let a = &surfaces[tl.index([tu, tv])].fit.surface;
            for (d, nb) in [(0usize, [tu + 1, tv]), (1, [tu, tv + 1])] {
                if nb[0] >= tl.tiles[0] || nb[1] >= tl.tiles[1] {
                    continue;
                }
                let b = &surfaces[tl.index(nb)].fit.surface;
                for k in 0..=64 {
                    let along = (k as f64 / 64.0) * s;
                    let q = if d == 0 {
                        [(tu + 1) as f64 * s, tv as f64 * s + along]
                    } else {
                        [tu as f64 * s + along, (tv + 1) as f64 * s]
                    };
                    let (pa, pb) = (tensor::eval(a, q)[0], tensor::eval(b, q)[0]);
                    let g = ((pa[0] - pb[0]).powi(2)
                        + (pa[1] - pb[1]).powi(2)
                        + (pa[2] - pb[2]).powi(2))
                    .sqrt();
                    gap = gap.max(g);
                }
            }
        }
    }
    gap
}
