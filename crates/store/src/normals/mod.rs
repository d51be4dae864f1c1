//! Normals for points that have none: estimation and orientation, out of core.
//!
//! Runs on a staged store ([`Staged`]: cells written, manifest not yet), between ingest's
//! passes and the store's commit (the pipeline chains them, ARCHITECTURE.md step 1), in three
//! passes over the cells in Morton order:
//!
//! 1. **Fit and local orientation**, cell by cell on the worker pool. Each point's `k` nearest
//!    neighbours ([`estimate::knn_all`]) give a plane fit: the normal is the eigenvector of the
//!    least eigenvalue of their covariance (principal component analysis, Hoppe et al. 1992
//!    §3.2, [`estimate::fit_normal`]). Neighbours may lie in other cells: a point's k-th
//!    neighbour distance within its own cell, `d_k`, is an upper bound of the true one, so
//!    every true neighbour lies within `d_k` of it; the cell therefore loads a *halo*, the
//!    points of other cells within `h = max(d_k − b)` of its box (`b`: the point's distance to
//!    the box faces; `h` capped at one cell edge), and re-queries only the points whose ball
//!    leaves the box ([`estimate::fit_own`], [`estimate::fit_boundary`]). The neighbour lists
//!    are exact, so a store gives the same normals whatever its cell sizes. Normals are then
//!    oriented along minimum spanning trees of the cell's neighbour graph (Hoppe §3.3,
//!    [`orient::orient_cell`]), or by their scan's viewpoint where it is decisive; each
//!    connected part is a component. For each point whose neighbours reach into the halo, the
//!    pair with its nearest halo neighbour is kept.
//! 2. **Across cells**: every kept pair adds `nₐ·n_b` to the edge between the two components;
//!    a maximum spanning forest over those edges, viewpoint votes and hull extremes gives every
//!    component its sign ([`orient::orient_nodes`]).
//! 3. **Rewrite**: each cell file is rewritten with its oriented normals.
//!
//! **Adaptive neighbour count.** With noise of spread `σ` across the surface, the angular error
//! of a plane fit to `k` neighbours falls about as `σ/(d_k √k)`; a cell whose median error at
//! `--neighbours` exceeds [`TARGET_ANGLE`] fits with `k` grown in proportion, up to
//! [`MAX_K_FACTOR`] times ([`estimate::cell_k`]).
//!
//! Points whose neighbourhood spans no plane (fewer than three distinct points, or all on a
//! line) get a zero normal, which adds nothing to a Poisson solve; they are counted.
//!
//! Memory: a cell in flight holds about [`BYTES_PER_POINT`] per point (positions, tree,
//! neighbour lists, normals), admitted by the budget in waves of at most
//! [`Share::NormalsWave`], plus a cache of decoded neighbour cells bounded by
//! [`Share::NormalsCellCache`] (at least [`MIN_CELL_CACHE_BYTES`]).

pub mod estimate;
pub mod orient;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use rayon::prelude::*;

use crate::Staged;
use crate::error::{Error, IoContext, Result, Setting};
use crate::exec::Ctx;
use crate::exec::budget::Share;
use crate::exec::cache::Lru;
use crate::exec::progress::Stage;
use crate::fs::atomic::{self, Durability};
use crate::fs::le::{LeReader, LeWriter};
use crate::manifest::{CellEntry, EstimatedNormals, next_wave};
use crate::types::{Aabb, Viewpoint};
use estimate::{Halo, OwnFit};
use orient::{Cross, Node};

pub use crate::NormalsMode;

/// Default neighbours per plane fit (the point itself included), as Open3D's and PCL's usual
/// choice.
pub const DEFAULT_K: usize = 20;

/// Angular error (radians) the neighbourhood size is chosen for: where noise makes a cell's
/// median `spread/√k` larger, its `k` grows in proportion (the error of a plane fit to noisy
/// points falls about as `1/k`: measured 4.3°, 2.1°, 1.2° at k = 20, 40, 80 on a noisy bumpy
/// sphere), up to [`MAX_K_FACTOR`] times `--neighbours`.
pub const TARGET_ANGLE: f64 = 0.025;

/// Largest growth of `k` for noise.
pub const MAX_K_FACTOR: usize = 8;

/// Neighbours per point linked in the orientation graph (the nearest ones of the `k`).
pub const ORIENT_K: usize = 6;

/// Bytes held per point of a cell while its normals are estimated: position (f64 ×3), relative
/// position (f32 ×3), fitted normal (an `Option<[f32; 3]>`, 16), orientation neighbours (u32
/// each), oriented normal (f32 ×3), the neighbour search's voxel key and index (u64 + u32) and
/// the scan (u16).
pub const BYTES_PER_POINT: u64 = 24 + 12 + 16 + 4 * ORIENT_K as u64 + 12 + 8 + 4 + 2;

/// Least capacity of the neighbour cell cache, for budgets so small that their slice would
/// not hold a few cells.
pub const MIN_CELL_CACHE_BYTES: u64 = 16 << 20;

/// Cells estimated at once per worker thread (fewer when they would not fit the wave's slice).
const CELLS_PER_THREAD: usize = 2;

/// Bytes per point of a cell being rewritten, besides its raw and compressed records (twice
/// the stride): the decoded batch and the side record read back.
const REWRITE_BYTES_PER_POINT: u64 = 64;

/// Bytes per point of a side file: the normal (f32 ×3) and the component (u32).
const SIDE_RECORD_BYTES: usize = 16;

/// Directory of the side files inside the staged store, removed when the rewrite is done.
const SIDE_DIR: &str = "normals";

/// Options of the estimation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormalParams {
    /// Neighbours per plane fit, the point included.
    pub k: usize,
    /// Re-fit once with robust (Cauchy) weights.
    pub robust: bool,
    /// Grow `k` per cell where noise dominates (see [`TARGET_ANGLE`]).
    pub adaptive: bool,
}

impl Default for NormalParams {
    fn default() -> Self {
        NormalParams {
            k: DEFAULT_K,
            robust: false,
            adaptive: true,
        }
    }
}

/// What pass 1 keeps of a cell: its components' orientation data, the pairs reaching into
/// other cells, the `k` it fitted with and its counts.
#[derive(Debug, Clone)]
pub struct CellResult {
    nodes: Vec<Node>,
    cross: Vec<Cross>,
    k: usize,
    by_view: u64,
    degenerate: u64,
}

/// The first bytes of a file of pass-1 results.
const RESULTS_MAGIC: &[u8; 8] = b"SFNORM01";

/// Pass-1 results of consecutive cells as bytes ([`LeWriter`]), for the checkpoints of a
/// split ingest.
pub fn encode_results(results: &[CellResult]) -> Vec<u8> {
    let mut w = LeWriter::new(RESULTS_MAGIC);
    w.u64(results.len() as u64);
    for r in results {
        w.u64(r.k as u64);
        w.u64(r.by_view);
        w.u64(r.degenerate);
        w.u64(r.nodes.len() as u64);
        for n in &r.nodes {
            w.f64(n.vote);
            for &(e, c) in &n.ext {
                w.f64(e);
                w.f32(c);
            }
        }
        w.u64(r.cross.len() as u64);
        for x in &r.cross {
            w.u32(x.comp);
            x.n.iter().for_each(|&v| w.f32(v));
            w.u32(x.to_cell);
            w.u32(x.to_idx);
        }
    }
    w.finish()
}

/// Read what [`encode_results`] wrote to `path` (named in errors).
pub fn decode_results(bytes: &[u8], path: &Path) -> Result<Vec<CellResult>> {
    let bad = || Error::input(path, "damaged normals checkpoint");
    let mut r = LeReader::open(bytes, RESULTS_MAGIC).ok_or_else(bad)?;
    let decoded = (|| {
        let mut out = Vec::new();
        for _ in 0..r.u64()? {
            let (k, by_view, degenerate) = (r.u64()? as usize, r.u64()?, r.u64()?);
            let mut nodes = Vec::new();
            for _ in 0..r.u64()? {
                let mut n = Node::EMPTY;
                n.vote = r.f64()?;
                for e in &mut n.ext {
                    *e = (r.f64()?, r.f32()?);
                }
                nodes.push(n);
            }
            let mut cross = Vec::new();
            for _ in 0..r.u64()? {
                cross.push(Cross {
                    comp: r.u32()?,
                    n: [r.f32()?, r.f32()?, r.f32()?],
                    to_cell: r.u32()?,
                    to_idx: r.u32()?,
                });
            }
            out.push(CellResult {
                nodes,
                cross,
                k,
                by_view,
                degenerate,
            });
        }
        r.at_end().then_some(out)
    })();
    decoded.ok_or_else(bad)
}

/// A cell's positions and scan ids, decoded.
struct CellPts {
    pos: Vec<[f64; 3]>,
    source: Vec<u16>,
}

impl CellPts {
    fn bytes(&self) -> u64 {
        (self.pos.len() * 24 + self.source.len() * 2) as u64
    }
}

/// Decoded cells of a staged store, bounded in bytes, least recently used out.
struct CellCache<'a> {
    store: &'a Staged,
    lru: Lru<usize, Arc<CellPts>>,
}

impl CellCache<'_> {
    fn load(&self, i: usize) -> Result<CellPts> {
        let b = self.store.read_cell(i)?;
        Ok(CellPts {
            pos: b.pos,
            source: b.source,
        })
    }

    /// Cells `ids`, the missing ones loaded in parallel.
    fn fill(&mut self, ids: &[usize], ctx: &Ctx) -> Result<Vec<Arc<CellPts>>> {
        let missing: Vec<usize> = ids
            .iter()
            .copied()
            .filter(|i| !self.lru.contains(i))
            .collect();
        let loaded: Vec<Result<CellPts>> = ctx
            .pool
            .install(|| missing.par_iter().map(|&i| self.load(i)).collect());
        let mut out: Vec<Option<Arc<CellPts>>> =
            ids.iter().map(|i| self.lru.get(i).cloned()).collect();
        for (i, c) in missing.into_iter().zip(loaded) {
            let c = Arc::new(c?);
            let bytes = c.bytes();
            if let Some(k) = ids.iter().position(|&x| x == i) {
                out[k] = Some(Arc::clone(&c));
            }
            self.lru.insert(i, c, bytes);
        }
        out.into_iter()
            .map(|c| c.ok_or_else(|| Error::Internal("a cell was not loaded".into())))
            .collect()
    }

    fn get(&mut self, i: usize) -> Result<Arc<CellPts>> {
        if let Some(c) = self.lru.get(&i) {
            return Ok(Arc::clone(c));
        }
        let c = Arc::new(self.load(i)?);
        let bytes = c.bytes();
        self.lru.insert(i, Arc::clone(&c), bytes);
        Ok(c)
    }
}

/// Estimate and orient normals for every cell of the staged `store`, rewriting its cell files
/// with them (see the [module docs](self)). Returns what was done and the wall time in seconds.
pub fn estimate_cells(
    store: &mut Staged,
    params: &NormalParams,
    ctx: &Ctx,
) -> Result<(EstimatedNormals, f64)> {
    let t0 = Instant::now();
    check_k(params)?;
    let side_dir = store.dir().join(SIDE_DIR);
    std::fs::create_dir_all(&side_dir).with_path(&side_dir)?;
    let total: u64 = store.cells().iter().map(|c| c.count).sum();
    let stage = ctx.progress.stage("normals", Some(total), "points");
    let results = fit_cells(
        store,
        &side_dir,
        params,
        0..store.cells().len(),
        &stage,
        ctx,
    )?;
    stage.finish(None);
    let signs = component_signs(&results, store.cells(), &side_dir, ctx)?;
    rewrite_cells(store, &side_dir, &signs, ctx)?;
    std::fs::remove_dir(&side_dir).with_path(&side_dir)?;
    Ok((
        summary(&results, &signs, params, total),
        t0.elapsed().as_secs_f64(),
    ))
}

/// What the estimation did, from every cell's pass-1 results and pass 2's signs.
pub fn summary(
    results: &[CellResult],
    signs: &Signs,
    params: &NormalParams,
    total: u64,
) -> EstimatedNormals {
    let by_view: u64 = results.iter().map(|r| r.by_view).sum();
    let degenerate: u64 = results.iter().map(|r| r.degenerate).sum();
    if degenerate > 0 {
        log::warn!(
            "{degenerate} points have no plane among their {} nearest neighbours (duplicates or a line); their normals are zero",
            params.k
        );
    }
    EstimatedNormals {
        k: params.k,
        k_max: results.iter().map(|r| r.k).max().unwrap_or(params.k),
        robust: params.robust,
        by_viewpoint: by_view,
        by_propagation: total - by_view - degenerate,
        degenerate,
        components: signs.trees as u64,
    }
}

/// Pass 1 for the cells `range`: fit and orient each cell locally, wave by wave; each cell's
/// normals and components go to its side file in `side_dir` (written under a temporary name
/// and renamed: tasks of a split ingest may write the same one).
pub fn fit_cells(
    store: &Staged,
    side_dir: &Path,
    params: &NormalParams,
    range: std::ops::Range<usize>,
    stage: &Stage,
    ctx: &Ctx,
) -> Result<Vec<CellResult>> {
    check_k(params)?;
    let cells = store.cells();
    let cell_boxes: Vec<Aabb> = cells.iter().map(|c| store.cube().cell_box(c.key)).collect();
    let viewpoints = store.viewpoints();
    let use_view = store.layout().attrs.source && viewpoints.iter().any(|v| v.is_some());
    let cache_cap = ctx
        .budget
        .share(Share::NormalsCellCache)
        .max(MIN_CELL_CACHE_BYTES);
    let _cache_permit = ctx
        .budget
        .acquire(cache_cap, "the neighbour cell cache of normal estimation")?;
    let mut cache = CellCache {
        store,
        lru: Lru::new(cache_cap),
    };
    let share = ctx.budget.share(Share::NormalsWave);
    let mut results: Vec<CellResult> = Vec::with_capacity(range.len());
    let mut i = range.start;
    while i < range.end {
        let (j, bytes) = next_wave(
            &cells[..range.end],
            i,
            CELLS_PER_THREAD * ctx.threads(),
            share,
            BYTES_PER_POINT,
        );
        let ids: Vec<usize> = (i..j).collect();
        let _permit = ctx
            .budget
            .acquire(bytes, "a wave of normal estimation cells")?;
        let own = cache.fill(&ids, ctx)?;
        // a) fits within each cell alone.
        let firsts: Vec<OwnFit> = ctx.pool.install(|| {
            ids.par_iter()
                .zip(&own)
                .map(|(&c, pts)| estimate::fit_own(&pts.pos, &cell_boxes[c], params, stage))
                .collect()
        });
        // b) halos.
        let mut halos = Vec::with_capacity(ids.len());
        for (&c, f) in ids.iter().zip(&firsts) {
            halos.push(gather_halo(&mut cache, c, f, &cell_boxes[c])?);
        }
        // c) boundary points with the halo, orientation, side files.
        let view = ViewDirs {
            viewpoints: &viewpoints,
            on: use_view,
        };
        let res: Vec<Result<CellResult>> = ctx.pool.install(|| {
            ids.par_iter()
                .zip(own.par_iter())
                .zip(firsts.into_par_iter().zip(halos.into_par_iter()))
                .map(|((&c, pts), (f, halo))| {
                    finish_cell(pts, f, &halo, params, &view, &side_path(side_dir, c))
                })
                .collect()
        });
        for r in res {
            results.push(r?);
        }
        i = j;
    }
    Ok(results)
}

/// A plane fit needs three points.
fn check_k(params: &NormalParams) -> Result<()> {
    if params.k < 3 {
        return Err(Error::Usage(format!(
            "{} {}: a plane fit needs at least 3",
            Setting::Neighbours,
            params.k
        )));
    }
    Ok(())
}

/// The points of other cells within `f.h` of cell `c`'s box `bx`.
fn gather_halo(cache: &mut CellCache, c: usize, f: &OwnFit, bx: &Aabb) -> Result<Halo> {
    let mut halo = Halo::default();
    if f.h <= 0.0 {
        return Ok(halo);
    }
    let reach = bx.grown(f.h);
    for (o, e) in cache.store.cells().iter().enumerate() {
        if o == c || !reach.meets(&e.bounds) {
            continue;
        }
        let other = cache.get(o)?;
        for (k, p) in other.pos.iter().enumerate() {
            if reach.contains(*p) {
                halo.pos.push(estimate::rel(*p, f.centre, f.inv));
                halo.origin.push((o as u32, k as u32));
            }
        }
    }
    Ok(halo)
}

/// Where each scan was seen from, when the records carry scans and any viewpoint is known.
struct ViewDirs<'a> {
    viewpoints: &'a [Option<Viewpoint>],
    on: bool,
}

impl ViewDirs<'_> {
    /// Each point's direction toward its scan's viewpoint (zero without one); empty when off.
    fn of(&self, pts: &CellPts) -> Vec<[f32; 3]> {
        if !self.on {
            return Vec::new();
        }
        (0..pts.pos.len())
            .map(|i| {
                let s = pts.source.get(i).copied().unwrap_or(0);
                match self.viewpoints.get(s as usize).copied().flatten() {
                    Some(v) => v.toward(pts.pos[i]).map(|x| x as f32),
                    None => [0.0; 3],
                }
            })
            .collect()
    }
}

/// Fit a cell's boundary points with its halo, orient the cell and write its side file.
fn finish_cell(
    pts: &CellPts,
    mut f: OwnFit,
    halo: &Halo,
    params: &NormalParams,
    view: &ViewDirs,
    side: &Path,
) -> Result<CellResult> {
    let cross_of = estimate::fit_boundary(&mut f, halo, params);
    let dirs = view.of(pts);
    let o = orient::orient_cell(
        &pts.pos,
        &f.normals,
        &f.nbrs,
        &dirs,
        &cross_of,
        &halo.origin,
    );
    write_side(side, &o.normals, &o.comp)?;
    Ok(CellResult {
        nodes: o.nodes,
        cross: o.cross,
        k: f.k,
        by_view: o.by_view,
        degenerate: o.degenerate,
    })
}

/// The outcome of pass 2.
pub struct Signs {
    /// Per node (component of a cell): flip its normals.
    flip: Vec<bool>,
    /// Index of each cell's first node; one more entry at the end.
    offsets: Vec<u32>,
    /// Trees of the spanning forest (orientation components).
    trees: usize,
}

/// The first bytes of a file of pass-2 signs.
const SIGNS_MAGIC: &[u8; 8] = b"SFSIGN01";

impl Signs {
    /// As bytes ([`LeWriter`]), for the checkpoint a split ingest's tasks share.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = LeWriter::new(SIGNS_MAGIC);
        w.u64(self.trees as u64);
        w.u64(self.offsets.len() as u64);
        self.offsets.iter().for_each(|&o| w.u32(o));
        w.u64(self.flip.len() as u64);
        self.flip.iter().for_each(|&f| w.u32(f as u32));
        w.finish()
    }

    /// Read what [`Signs::encode`] wrote to `path` (named in errors).
    pub fn decode(bytes: &[u8], path: &Path) -> Result<Signs> {
        let bad = || Error::input(path, "damaged normals checkpoint");
        let mut r = LeReader::open(bytes, SIGNS_MAGIC).ok_or_else(bad)?;
        let s = (|| {
            let trees = r.u64()? as usize;
            let offsets = (0..r.u64()?)
                .map(|_| r.u32())
                .collect::<Option<Vec<u32>>>()?;
            let flip = (0..r.u64()?)
                .map(|_| r.u32().map(|f| f != 0))
                .collect::<Option<Vec<bool>>>()?;
            r.at_end().then_some(Signs {
                flip,
                offsets,
                trees,
            })
        })();
        s.ok_or_else(bad)
    }
}

/// Pass 2: sum the cross-cell pairs into edges between components and orient the components.
pub fn component_signs(
    results: &[CellResult],
    cells: &[CellEntry],
    side_dir: &Path,
    ctx: &Ctx,
) -> Result<Signs> {
    let mut offsets = Vec::with_capacity(cells.len() + 1);
    offsets.push(0u32);
    for r in results {
        offsets.push(offsets.last().copied().unwrap_or(0) + r.nodes.len() as u32);
    }
    let nodes: Vec<Node> = results.iter().flat_map(|r| r.nodes.clone()).collect();
    let mut by_target: Vec<Vec<(u32, Cross)>> = vec![Vec::new(); cells.len()];
    for (c, r) in results.iter().enumerate() {
        for x in &r.cross {
            by_target[x.to_cell as usize].push((offsets[c] + x.comp, *x));
        }
    }
    let pairs: Vec<Result<Vec<(u32, u32, f64)>>> = ctx.pool.install(|| {
        by_target
            .par_iter()
            .enumerate()
            .filter(|(_, v)| !v.is_empty())
            .map(|(t, v)| {
                let path = side_path(side_dir, t);
                let (normals, comp) = read_side(&path, cells[t].count as usize)?;
                Ok(v.iter()
                    .map(|(a, x)| {
                        let q = x.to_idx as usize;
                        let b = offsets[t] + comp[q];
                        let n = normals[q];
                        let w = x.n[0] * n[0] + x.n[1] * n[1] + x.n[2] * n[2];
                        ((*a).min(b), (*a).max(b), w as f64)
                    })
                    .collect())
            })
            .collect()
    });
    let mut all = Vec::new();
    for p in pairs {
        all.extend(p?);
    }
    all.sort_by_key(|&(a, b, _)| (a, b));
    let mut edges: Vec<(u32, u32, f64)> = Vec::new();
    for (a, b, w) in all {
        match edges.last_mut() {
            Some(e) if e.0 == a && e.1 == b => e.2 += w,
            _ => edges.push((a, b, w)),
        }
    }
    let (flip, trees) = orient::orient_nodes(&nodes, &edges);
    Ok(Signs {
        flip,
        offsets,
        trees,
    })
}

/// Pass 3: rewrite every cell with its normals, flipped by its component's sign, wave by wave.
fn rewrite_cells(store: &mut Staged, side_dir: &Path, signs: &Signs, ctx: &Ctx) -> Result<()> {
    let n_cells = store.cells().len();
    let stride_out = store.layout().with_normals().stride as u64;
    let stage = ctx.progress.stage("orient", Some(n_cells as u64), "cells");
    let mut i = 0;
    while i < n_cells {
        let j = (i + CELLS_PER_THREAD * ctx.threads()).min(n_cells);
        let bytes: u64 = store.cells()[i..j]
            .iter()
            .map(|c| c.count * (2 * stride_out + REWRITE_BYTES_PER_POINT))
            .sum();
        let _permit = ctx.budget.acquire(bytes, "a wave of cells to rewrite")?;
        let st: &Staged = store;
        let done: Vec<Result<(u64, u32)>> = ctx.pool.install(|| {
            (i..j)
                .into_par_iter()
                .map(|c| {
                    let r = rewrite_cell(st, c, side_dir, signs, &st.cell_path(c)).and_then(|r| {
                        let side = side_path(side_dir, c);
                        std::fs::remove_file(&side).with_path(&side)?;
                        Ok(r)
                    });
                    stage.inc(1);
                    r
                })
                .collect()
        });
        for (c, d) in (i..j).zip(done) {
            let (bytes, crc) = d?;
            store.set_cell_file(c, bytes, crc);
        }
        i = j;
    }
    stage.finish(None);
    Ok(())
}

/// Pass 3 for cell `c`: write it to `dest` with its oriented normals; returns the file's size
/// and CRC-32.
pub fn rewrite_cell(
    store: &Staged,
    c: usize,
    side_dir: &Path,
    signs: &Signs,
    dest: &Path,
) -> Result<(u64, u32)> {
    let mut b = store.read_cell(c)?;
    let side = side_path(side_dir, c);
    let (normals, comp) = read_side(&side, store.cells()[c].count as usize)?;
    let first = signs.offsets[c];
    b.normal = normals
        .iter()
        .zip(&comp)
        .map(|(n, &k)| {
            if signs.flip[(first + k) as usize] {
                n.map(|v| -v)
            } else {
                *n
            }
        })
        .collect();
    store.write_with_normals(dest, &b)
}

/// The side file of cell `i` in `dir`.
fn side_path(dir: &Path, i: usize) -> PathBuf {
    dir.join(format!("{i}.nrm"))
}

/// Write a cell's side file: per point its normal and component, little-endian, uncompressed
/// (read once more shortly after).
fn write_side(path: &Path, normals: &[[f32; 3]], comp: &[u32]) -> Result<()> {
    let mut raw = Vec::with_capacity(normals.len() * SIDE_RECORD_BYTES);
    for (n, c) in normals.iter().zip(comp) {
        for v in n {
            raw.extend_from_slice(&v.to_le_bytes());
        }
        raw.extend_from_slice(&c.to_le_bytes());
    }
    atomic::write(path, &raw, Durability::Renamed)
}

fn read_side(path: &Path, count: usize) -> Result<(Vec<[f32; 3]>, Vec<u32>)> {
    let raw = std::fs::read(path).with_path(path)?;
    if raw.len() != count * SIDE_RECORD_BYTES {
        return Err(Error::input(
            path,
            format!(
                "corrupt normals side file: {} bytes for {count} points",
                raw.len()
            ),
        ));
    }
    let f = |r: &[u8], o: usize| f32::from_le_bytes([r[o], r[o + 1], r[o + 2], r[o + 3]]);
    let mut normals = Vec::with_capacity(count);
    let mut comp = Vec::with_capacity(count);
    for r in raw.chunks_exact(SIDE_RECORD_BYTES) {
        normals.push([f(r, 0), f(r, 4), f(r, 8)]);
        comp.push(u32::from_le_bytes([r[12], r[13], r[14], r[15]]));
    }
    Ok((normals, comp))
}
