//! Normals for points that have none: estimation and orientation, out of core.
//!
//! Runs inside `ingest`, on the store's cells before the manifest is written, in three passes
//! over the cells in Morton order:
//!
//! 1. **Fit and local orientation**, cell by cell on the worker pool. Each point's `k` nearest
//!    neighbours (kd-tree, [`estimate`]) give a plane fit (Hoppe et al. 1992 §3.2). Neighbours
//!    may lie in other cells: a point's k-th neighbour distance within its own cell, `d_k`, is
//!    an upper bound of the true one, so every true neighbour lies within `d_k` of it; the cell
//!    therefore loads a *halo*, the points of other cells within `h = max(d_k − b)` of its box
//!    (`b`: the point's distance to the box faces; `h` capped at one cell edge), and re-queries
//!    only the points whose ball leaves the box. The neighbour lists are exact, so a store gives
//!    the same normals whatever its cell sizes. Normals are then oriented along minimum spanning
//!    trees of the cell's neighbour graph (Hoppe §3.3, [`orient::orient_local`]), or by their
//!    scan's viewpoint where it is decisive; each connected part is a component. For each point
//!    whose neighbours reach into the halo, the pair with its nearest halo neighbour is kept.
//! 2. **Across cells**: every kept pair adds `nₐ·n_b` to the edge between the two components;
//!    a maximum spanning forest over those edges, viewpoint votes and hull extremes gives every
//!    component its sign ([`orient::orient_nodes`]).
//! 3. **Rewrite**: each cell file is rewritten with its oriented normals.
//!
//! Points whose neighbourhood spans no plane (fewer than three distinct points, or all on a
//! line) get a zero normal, which adds nothing to a Poisson solve; they are counted.
//!
//! Memory: a cell in flight holds about [`BYTES_PER_POINT`] per point (positions, tree,
//! neighbour lists, normals), admitted by the budget, plus a cache of decoded neighbour cells
//! bounded by a quarter of the budget.

pub mod estimate;
pub mod orient;

use std::collections::{HashMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use rayon::prelude::*;

use crate::error::{Error, IoContext, Result};
use crate::exec::Ctx;
use crate::store::cell_file::{RecordLayout, read_cell_file, write_cell_file};
use crate::store::manifest::{CellEntry, EstimatedNormals};
use crate::types::{Aabb, Cube, Viewpoint};
use orient::{Graph, Node};

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

/// Bytes held per point of a cell while its normals are estimated.
pub const BYTES_PER_POINT: u64 = 24 + 12 + 16 + 4 * ORIENT_K as u64 + 12 + 8 + 4 + 2;

/// Where normals come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NormalsMode {
    /// The inputs' normals when every input has them, else estimated.
    #[default]
    Auto,
    /// The inputs' normals; an input without them is an error.
    Use,
    /// Estimated, ignoring any normals in the inputs.
    Estimate,
}

impl std::str::FromStr for NormalsMode {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "auto" => Ok(NormalsMode::Auto),
            "use" => Ok(NormalsMode::Use),
            "estimate" => Ok(NormalsMode::Estimate),
            o => Err(Error::Usage(format!(
                "--normals \"{o}\": expected auto, use or estimate"
            ))),
        }
    }
}

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

/// A neighbour pair across two cells: point of component `comp` with normal `n`, and point
/// `to_idx` of cell `to_cell`.
#[derive(Debug, Clone, Copy)]
struct Cross {
    comp: u32,
    n: [f32; 3],
    to_cell: u32,
    to_idx: u32,
}

/// What pass 1 keeps of a cell.
struct CellResult {
    nodes: Vec<Node>,
    cross: Vec<Cross>,
    k: usize,
    by_view: u64,
    degenerate: u64,
}

/// Decoded positions (and scan ids) of cells, bounded in bytes, least recently used out.
struct PosCache<'a> {
    dir: &'a Path,
    cells: &'a [CellEntry],
    layout: RecordLayout,
    map: HashMap<usize, Arc<CellPts>>,
    lru: VecDeque<usize>,
    bytes: u64,
    cap: u64,
}

struct CellPts {
    pos: Vec<[f64; 3]>,
    source: Vec<u16>,
}

impl CellPts {
    fn bytes(&self) -> u64 {
        (self.pos.len() * 24 + self.source.len() * 2) as u64
    }
}

impl<'a> PosCache<'a> {
    fn load(&self, i: usize) -> Result<CellPts> {
        let e = &self.cells[i];
        let b = read_cell_file(&self.dir.join(&e.file), self.layout, e.count, e.crc32)?;
        Ok(CellPts {
            pos: b.pos,
            source: b.source,
        })
    }

    /// Make sure cells `ids` are cached (loading the missing ones in parallel).
    fn fill(&mut self, ids: &[usize], ctx: &Ctx) -> Result<()> {
        let missing: Vec<usize> = ids
            .iter()
            .copied()
            .filter(|i| !self.map.contains_key(i))
            .collect();
        let loaded: Vec<Result<CellPts>> = ctx
            .pool
            .install(|| missing.par_iter().map(|&i| self.load(i)).collect());
        for (i, c) in missing.into_iter().zip(loaded) {
            let c = Arc::new(c?);
            self.bytes += c.bytes();
            self.map.insert(i, c);
            self.lru.push_back(i);
        }
        Ok(())
    }

    fn get(&mut self, i: usize) -> Result<Arc<CellPts>> {
        if let Some(c) = self.map.get(&i) {
            let c = Arc::clone(c);
            if let Some(p) = self.lru.iter().position(|&j| j == i) {
                self.lru.remove(p);
            }
            self.lru.push_back(i);
            return Ok(c);
        }
        let c = Arc::new(self.load(i)?);
        self.bytes += c.bytes();
        self.map.insert(i, Arc::clone(&c));
        self.lru.push_back(i);
        Ok(c)
    }

    fn trim(&mut self) {
        while self.bytes > self.cap && self.lru.len() > 1 {
            if let Some(old) = self.lru.pop_front()
                && let Some(o) = self.map.remove(&old)
            {
                self.bytes -= o.bytes();
            }
        }
    }
}

fn side_path(dir: &Path, i: usize) -> PathBuf {
    dir.join(format!("{i}.nrm"))
}

/// Estimate and orient normals for every cell of a store being built in `store_dir`,
/// rewriting the cell files from `layout_in` (no normals) to `layout_out` (with normals) and
/// updating `cells` (sizes and checksums). `viewpoints[s]` is scan `s`'s viewpoint.
#[allow(clippy::too_many_arguments)]
pub fn estimate_cells(
    store_dir: &Path,
    cells: &mut [CellEntry],
    cube: &Cube,
    layout_in: RecordLayout,
    layout_out: RecordLayout,
    viewpoints: &[Option<Viewpoint>],
    params: &NormalParams,
    zstd_level: i32,
    ctx: &Ctx,
) -> Result<(EstimatedNormals, f64)> {
    let t0 = Instant::now();
    if params.k < 3 {
        return Err(Error::Usage(format!(
            "--neighbours {}: a plane fit needs at least 3",
            params.k
        )));
    }
    let cells_dir = store_dir.join("cells");
    let side_dir = store_dir.join("normals");
    std::fs::create_dir_all(&side_dir).with_path(&side_dir)?;
    let total: u64 = cells.iter().map(|c| c.count).sum();
    let use_view = layout_in.attrs.source && viewpoints.iter().any(|v| v.is_some());
    let cell_boxes: Vec<Aabb> = cells.iter().map(|c| cube.cell_box(c.key)).collect();

    // Pass 1.
    let cache_cap = (ctx.budget.total() / 4).max(16 << 20);
    let _cache_permit = ctx
        .budget
        .acquire(cache_cap, "the neighbour cell cache of normal estimation")?;
    let mut cache = PosCache {
        dir: &cells_dir,
        cells,
        layout: layout_in,
        map: HashMap::new(),
        lru: VecDeque::new(),
        bytes: 0,
        cap: cache_cap,
    };
    let stage = ctx.progress.stage("normals", Some(total), "points");
    let share = ctx.budget.total() / 3;
    let mut results: Vec<CellResult> = Vec::with_capacity(cells.len());
    let mut i = 0;
    while i < cells.len() {
        // A wave of cells whose working memory fits a third of the budget.
        let mut j = i;
        let mut bytes = 0u64;
        while j < cells.len() && j - i < 2 * ctx.threads() {
            let b = cells[j].count * BYTES_PER_POINT;
            if j > i && bytes + b > share {
                break;
            }
            bytes += b;
            j += 1;
        }
        let ids: Vec<usize> = (i..j).collect();
        let _permit = ctx
            .budget
            .acquire(bytes, "a wave of normal estimation cells")?;
        cache.fill(&ids, ctx)?;
        let own: Vec<Arc<CellPts>> = ids.iter().map(|&c| cache.get(c)).collect::<Result<_>>()?;
        // a) fits within each cell alone.
        let firsts: Vec<First> = ctx.pool.install(|| {
            ids.par_iter()
                .zip(&own)
                .map(|(&c, pts)| first_pass(pts, &cell_boxes[c], params))
                .collect()
        });
        // b) halos.
        let mut halos = Vec::with_capacity(ids.len());
        for (&c, f) in ids.iter().zip(&firsts) {
            let mut halo = Halo::default();
            if f.h > 0.0 {
                let reach = cell_boxes[c].grown(f.h);
                for (o, e) in cells.iter().enumerate() {
                    if o == c || !reach.meets(&e.bounds) {
                        continue;
                    }
                    let other = cache.get(o)?;
                    let centre = f.centre;
                    for (k, p) in other.pos.iter().enumerate() {
                        if reach.contains(*p) {
                            halo.pos.push(rel(*p, centre));
                            halo.origin.push((o as u32, k as u32));
                        }
                    }
                }
            }
            halos.push(halo);
        }
        cache.trim();
        // c) boundary points with the halo, orientation, side files.
        let res: Vec<Result<CellResult>> = ctx.pool.install(|| {
            ids.par_iter()
                .zip(own.par_iter())
                .zip(firsts.into_par_iter().zip(halos.into_par_iter()))
                .map(|((&c, pts), (f, halo))| {
                    let view = |p: [f64; 3], s: u16| -> [f32; 3] {
                        match viewpoints.get(s as usize).copied().flatten() {
                            Some(v) => v.toward(p).map(|x| x as f32),
                            None => [0.0; 3],
                        }
                    };
                    let r = second_pass(pts, f, &halo, params, use_view.then_some(&view));
                    let (normals, comp, result) = r;
                    write_side(&side_path(&side_dir, c), &normals, &comp)?;
                    Ok(result)
                })
                .collect()
        });
        for r in res {
            results.push(r?);
        }
        stage.inc(cells[i..j].iter().map(|c| c.count).sum());
        i = j;
    }
    drop(cache);
    stage.finish(None);

    // Pass 2: the component graph across cells.
    let mut offsets = Vec::with_capacity(cells.len() + 1);
    offsets.push(0u32);
    for r in &results {
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
                let path = side_path(&side_dir, t);
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

    // Pass 3: rewrite the cells.
    let stage = ctx
        .progress
        .stage("orient", Some(cells.len() as u64), "cells");
    let mut i = 0;
    while i < cells.len() {
        let j = (i + 2 * ctx.threads()).min(cells.len());
        let bytes: u64 = cells[i..j]
            .iter()
            .map(|c| c.count * (2 * layout_out.stride as u64 + 64))
            .sum();
        let _permit = ctx.budget.acquire(bytes, "a wave of cells to rewrite")?;
        let done: Vec<Result<(u64, u32)>> = ctx.pool.install(|| {
            (i..j)
                .into_par_iter()
                .map(|c| {
                    let e = &cells[c];
                    let path = cells_dir.join(&e.file);
                    let mut b = read_cell_file(&path, layout_in, e.count, e.crc32)?;
                    let side = side_path(&side_dir, c);
                    let (normals, comp) = read_side(&side, e.count as usize)?;
                    b.normal = normals
                        .iter()
                        .zip(&comp)
                        .map(|(n, &k)| {
                            if flip[(offsets[c] + k) as usize] {
                                n.map(|v| -v)
                            } else {
                                *n
                            }
                        })
                        .collect();
                    let r = write_cell_file(&path, layout_out, &b, zstd_level)?;
                    std::fs::remove_file(&side).with_path(&side)?;
                    Ok(r)
                })
                .collect()
        });
        for (c, d) in (i..j).zip(done) {
            let (bytes, crc) = d?;
            cells[c].bytes = bytes;
            cells[c].crc32 = crc;
        }
        stage.inc((j - i) as u64);
        i = j;
    }
    stage.finish(None);
    std::fs::remove_dir(&side_dir).with_path(&side_dir)?;
    let by_view: u64 = results.iter().map(|r| r.by_view).sum();
    let degenerate: u64 = results.iter().map(|r| r.degenerate).sum();
    if degenerate > 0 {
        log::warn!(
            "{degenerate} points have no plane among their {} nearest neighbours (duplicates or a line); their normals are zero",
            params.k
        );
    }
    Ok((
        EstimatedNormals {
            k: params.k,
            k_max: results.iter().map(|r| r.k).max().unwrap_or(params.k),
            robust: params.robust,
            by_viewpoint: by_view,
            by_propagation: total - by_view - degenerate,
            degenerate,
            components: trees as u64,
        },
        t0.elapsed().as_secs_f64(),
    ))
}

#[inline]
fn rel(p: [f64; 3], c: [f64; 3]) -> [f32; 3] {
    [
        (p[0] - c[0]) as f32,
        (p[1] - c[1]) as f32,
        (p[2] - c[2]) as f32,
    ]
}

/// Points of other cells near a cell's box.
#[derive(Default)]
struct Halo {
    pos: Vec<[f32; 3]>,
    origin: Vec<(u32, u32)>,
}

/// A cell after fitting with its own points only.
struct First {
    /// Neighbours per fit in this cell.
    k: usize,
    /// Typical k-th neighbour distance in the cell.
    typical: f32,
    centre: [f64; 3],
    rel: Vec<[f32; 3]>,
    normals: Vec<Option<[f32; 3]>>,
    nbrs: Vec<u32>,
    /// Points whose neighbour ball leaves the box (fit again with the halo).
    boundary: Vec<u32>,
    h: f64,
}

/// The cell's neighbourhood size: `k`, grown where noise dominates the fits (measured on a
/// sample of up to 1024 of its points; see [`TARGET_ANGLE`]).
fn cell_k(rel: &[[f32; 3]], k: usize) -> usize {
    let n = rel.len();
    if n <= k {
        return k;
    }
    let sample: Vec<u32> = (0..n as u32).step_by((n / 1024).max(1)).collect();
    let mut spreads = Vec::with_capacity(sample.len());
    estimate::knn_all(rel, &sample, k, None, |_, nb| {
        if let Some(s) = estimate::spread(rel, nb) {
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

fn first_pass(pts: &CellPts, bx: &Aabb, params: &NormalParams) -> First {
    let centre = [0, 1, 2].map(|a| 0.5 * (bx.min[a] + bx.max[a]));
    let edge = bx.max[0] - bx.min[0];
    let n = pts.pos.len();
    let rel: Vec<[f32; 3]> = pts.pos.iter().map(|p| rel(*p, centre)).collect();
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
    let typical = estimate::knn_all(&rel, &all, params.k, None, |i, nb| {
        let i = i as usize;
        let p = pts.pos[i];
        let b = (0..3)
            .map(|a| (p[a] - bx.min[a]).min(bx.max[a] - p[a]))
            .fold(f64::INFINITY, f64::min);
        let dk = if nb.len() < params.k {
            f64::INFINITY
        } else {
            (nb[nb.len() - 1].0 as f64).sqrt() * (1.0 + 1e-6)
        };
        if dk > b {
            boundary.push(i as u32);
            h = h.max(dk - b);
            return;
        }
        normals[i] = estimate::fit_normal(&rel, nb, params.robust);
        keep_nbrs(&mut nbrs[i * ORIENT_K..(i + 1) * ORIENT_K], i as u32, nb, n);
    });
    First {
        k: params.k,
        typical,
        centre,
        rel,
        normals,
        nbrs,
        boundary,
        h: h.min(edge),
    }
}

/// The first `ORIENT_K` neighbours other than `i` itself among the cell's own points.
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

type ViewFn<'a> = &'a (dyn Fn([f64; 3], u16) -> [f32; 3] + Sync);

fn second_pass(
    pts: &CellPts,
    mut f: First,
    halo: &Halo,
    params: &NormalParams,
    view: Option<ViewFn>,
) -> (Vec<[f32; 3]>, Vec<u32>, CellResult) {
    let n = pts.pos.len();
    let params = &NormalParams { k: f.k, ..*params };
    let mut cross_of: Vec<(u32, u32)> = Vec::new(); // (own point, index into halo)
    if !f.boundary.is_empty() {
        let mut all = f.rel.clone();
        all.extend_from_slice(&halo.pos);
        let (normals, nbrs) = (&mut f.normals, &mut f.nbrs);
        estimate::knn_all(&all, &f.boundary, params.k, Some(f.typical), |i, nb| {
            let iu = i as usize;
            normals[iu] = estimate::fit_normal(&all, nb, params.robust);
            keep_nbrs(&mut nbrs[iu * ORIENT_K..(iu + 1) * ORIENT_K], i, nb, n);
            if let Some(&(_, j)) = nb.iter().find(|&&(_, j)| j as usize >= n) {
                cross_of.push((i, j - n as u32));
            }
        });
    }
    let mut degenerate = 0u64;
    let mut normals: Vec<[f32; 3]> = f
        .normals
        .iter()
        .map(|x| {
            x.unwrap_or_else(|| {
                degenerate += 1;
                [0.0; 3]
            })
        })
        .collect();
    let mut edges = Vec::with_capacity(n * ORIENT_K);
    for i in 0..n {
        if normals[i] == [0.0; 3] {
            continue;
        }
        for &j in &f.nbrs[i * ORIENT_K..(i + 1) * ORIENT_K] {
            if j != u32::MAX && normals[j as usize] != [0.0; 3] {
                edges.push((i as u32, j));
            }
        }
    }
    let g = Graph::symmetric(n, &edges);
    drop(edges);
    let dirs: Vec<[f32; 3]> = match view {
        Some(v) => (0..n)
            .map(|i| v(pts.pos[i], pts.source.get(i).copied().unwrap_or(0)))
            .collect(),
        None => Vec::new(),
    };
    let local = orient::orient_local(&mut normals, &g, &dirs);
    let mut nodes = vec![Node::EMPTY; local.components];
    for i in 0..n {
        let vote = if dirs.is_empty() {
            0.0
        } else {
            let d = dirs[i];
            normals[i][0] * d[0] + normals[i][1] * d[1] + normals[i][2] * d[2]
        };
        nodes[local.comp[i] as usize].add(pts.pos[i], normals[i], vote);
    }
    let cross = cross_of
        .iter()
        .filter(|(i, _)| normals[*i as usize] != [0.0; 3])
        .map(|&(i, h)| {
            let (to_cell, to_idx) = halo.origin[h as usize];
            Cross {
                comp: local.comp[i as usize],
                n: normals[i as usize],
                to_cell,
                to_idx,
            }
        })
        .collect();
    (
        normals,
        local.comp,
        CellResult {
            nodes,
            cross,
            k: params.k,
            by_view: local.by_view,
            degenerate,
        },
    )
}

fn write_side(path: &Path, normals: &[[f32; 3]], comp: &[u32]) -> Result<()> {
    let mut raw = Vec::with_capacity(normals.len() * 16);
    for (n, c) in normals.iter().zip(comp) {
        for v in n {
            raw.extend_from_slice(&v.to_le_bytes());
        }
        raw.extend_from_slice(&c.to_le_bytes());
    }
    // Uncompressed: read once more shortly after, and 16 bytes a point.
    std::fs::write(path, raw).with_path(path)
}

fn read_side(path: &Path, count: usize) -> Result<(Vec<[f32; 3]>, Vec<u32>)> {
    let raw = std::fs::read(path).with_path(path)?;
    if raw.len() != count * 16 {
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
    for r in raw.chunks_exact(16) {
        normals.push([f(r, 0), f(r, 4), f(r, 8)]);
        comp.push(u32::from_le_bytes([r[12], r[13], r[14], r[15]]));
    }
    Ok((normals, comp))
}
