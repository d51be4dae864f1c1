//! Adaptive FFT surface reconstruction, streamed tile by tile (DESIGN.md steps 3–5).
//!
//! Sources: Kazhdan, "Reconstruction of solid models from oriented point sets" (2005) for the
//! FFT Poisson solve ([`fft_solve`]); Schall, Belyaev, Seidel, "Adaptive Fourier-based surface
//! reconstruction" (2006) for local solves on octree cells blended by a partition of unity
//! ([`pou`]). The blending follows the **two-level scheme** measured in `notes/adfft.md`,
//! which matches one global solve where the paper's plain per-leaf blend loses ~8× accuracy:
//!
//! 1. A **coarse global solve** on `(N/r)³` nodes (σ = 1 coarse voxel) over the whole cube,
//!    padded by `N/(8r)` coarse voxels on each side so that the periodic solve never wraps the
//!    surface. Coarse node `J` coincides with fine node `rJ`; it is upsampled trilinearly.
//! 2. Each **leaf** (an occupied octree cell of `E = 8r` fine voxels, so the coarse voxel is
//!    `E/8` as the notes require) solves its points — those of the cell scaled by 1.8 about its
//!    centre — on a periodic fine grid of `(2E)³` nodes (the cell embedded in a cube twice its
//!    size), and on the coarse grid of the same domain, aligned to the global coarse grid. Its
//!    **detail** is the difference, kept on the cell plus an overlap of `E/4` voxels. Details
//!    are spilled to the work directory (zstd) and are the checkpoint a resumed run reuses.
//! 3. The field at a fine node is the upsampled coarse solution plus the details blended by
//!    partition of unity ([`pou`]). Regions no leaf covers (holes, the unseen bottom of a scan)
//!    take the coarse solution, which closes them. The blend is exact fixed-point arithmetic
//!    ([`crate::extract::field`]), done on the CPU or, with `--gpu`, on the device from the
//!    leaf grids; both give the same bits.
//! 4. The iso-value is the mean of the field at the input samples (each leaf sums its own
//!    cell's samples). With outward normals the field is lower inside.
//!
//! **Grid conventions** (written once, here). The cube is the store's root cube (the bounding
//! box enlarged 10%, PoissonRecon's `--scale 1.1`). Depth `D` gives `N = 2^D` cells per edge and
//! spacing `h = size/N`; fine node `g = (i, j, k)`, `0 <= g <= N`, sits at `origin + h·g`. Every
//! local grid's origin is a global node, so blending never resamples. Tiles are octree cells
//! of `T` fine voxels (a multiple of `E`) visited in Morton order; marching cubes runs on each
//! tile's `(T+1)³` nodes, a vertex is keyed by the global grid edge it lies on, and tiles share
//! the vertices of their common faces through the welder's frontier.

pub mod fft_solve;
pub mod pou;

use std::collections::{BTreeSet, HashMap, VecDeque};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{Error, IoContext, Result};
use crate::exec::Ctx;
use crate::extract::cpu::marching_cubes;
use crate::extract::field::BlendEval;
use crate::extract::weld::Welder;
use crate::io::mesh_write::MeshPlyWriter;
use crate::store::Store;
use crate::types::{Aabb, CellKey, Cube, PointBatch, morton3};
use crate::types::{Axis, Blend, Detail, GridGeom, Leaf, MAX_SHIFT, TileMesh};
use fft_solve::{LocalGrid, Solver};
use pou::{quantise, quantise_detail, unit_for};

/// Peak bytes per node of a solve: the splatted normals (12) and the divergence (4).
const COARSE_BYTES_PER_NODE: u64 = 16;

/// The smallest `m >= n` whose only prime factors are 2, 3 and 5.
fn smooth_size(n: u64) -> u64 {
    let mut m = n.max(1);
    loop {
        let mut k = m;
        for p in [2, 3, 5] {
            while k.is_multiple_of(p) {
                k /= p;
            }
        }
        if k == 1 {
            return m;
        }
        m += 1;
    }
}

/// Depths `reconstruct` supports.
pub const DEPTHS: std::ops::RangeInclusive<u32> = 5..=13;

/// Options of `reconstruct`.
#[derive(Debug, Clone)]
pub struct ReconParams {
    /// Octree depth: `2^depth` cells per edge of the cube (as PoissonRecon's `--depth`).
    pub depth: u32,
    /// Gaussian smoothing width, in voxels of each grid.
    pub sigma_vox: f64,
    /// Tile edge in fine voxels (`None`: 64, at least one leaf, at most the cube).
    pub tile_voxels: Option<u64>,
    /// Work directory (leaf checkpoints, run description).
    pub work_dir: PathBuf,
    /// Reuse the leaves a previous run with the same inputs and options left in `work_dir`.
    pub resume: bool,
    /// Error tolerance relative to the bounding-box diagonal: a leaf whose samples lie
    /// within this mean distance of the coarse solution's surface is not refined.
    pub error: f64,
    /// Leaves with fewer points in their cell are not refined.
    pub min_points: u64,
    /// Leave the surface open where no input point is within two coarse voxels.
    pub trim: bool,
    /// Tile fields and marching cubes on the GPU: auto (a real GPU when there is one), on,
    /// off (the default: the GPU path is not yet measured faster end to end, see
    /// `extract::gpu`).
    pub gpu: crate::extract::gpu::GpuMode,
    /// Move each vertex onto the plane of its nearest input points (see [`FIT_NEIGHBOURS`]).
    pub fit: bool,
}

impl ReconParams {
    /// Defaults for `depth` with work directory `work_dir`.
    pub fn new(depth: u32, work_dir: PathBuf) -> ReconParams {
        ReconParams {
            depth,
            sigma_vox: 1.0,
            fit: true,
            tile_voxels: None,
            work_dir,
            resume: false,
            error: DEFAULT_ERROR,
            min_points: DEFAULT_MIN_POINTS,
            trim: false,
            gpu: crate::extract::gpu::GpuMode::Off,
        }
    }
}

/// Default `--error`: 2·10⁻⁵ of the diagonal, about a fiftieth of a voxel at depth 10: below
/// the noise of real scans (which are then refined everywhere, as a global solve would be),
/// above the error of the coarse solve on smooth, clean surfaces (which are then left coarse).
pub const DEFAULT_ERROR: f64 = 2e-5;

/// Default `--min-points`: a leaf needs this many samples in its cell to be refined. A fixed
/// count, not a share of the input (the paper's 0.5% suits 10⁵ points, not 10⁹): the detail
/// of a leaf is defined by its own samples, whatever the size of the scan.
pub const DEFAULT_MIN_POINTS: u64 = 8;

/// What `reconstruct` did.
#[derive(Debug, Clone, Serialize)]
pub struct ReconStats {
    /// Output vertices.
    pub vertices: u64,
    /// Output triangles.
    pub faces: u64,
    /// Occupied leaves (solved or reused).
    pub leaves: usize,
    /// Leaves refined by a fine solve (the others were within `--error` of the coarse solve).
    pub leaves_refined: usize,
    /// Leaves reused from the work directory.
    pub leaves_reused: usize,
    /// Tiles extracted (tiles with no surface are skipped).
    pub tiles: usize,
    /// Iso-value.
    pub iso: f64,
    /// Leaf edge in fine voxels.
    pub leaf_voxels: u64,
    /// Fine voxels per coarse voxel.
    pub coarse_ratio: u64,
    /// Tile edge in fine voxels.
    pub tile_voxels: u64,
    /// Most vertices held in the welder's frontier at once.
    pub peak_frontier: usize,
    /// Wall time in seconds.
    pub secs: f64,
}

/// The grids of one run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// The cube.
    pub cube: Cube,
    /// Depth.
    pub depth: u32,
    /// Fine cells per edge.
    pub n: u64,
    /// Fine spacing.
    pub h: f64,
    /// Fine voxels per coarse voxel.
    pub r: u64,
    /// Leaf edge in fine voxels.
    pub e: u64,
    /// Detail overlap in fine voxels.
    pub ov: u64,
    /// Octree level of leaves.
    pub leaf_level: u32,
    /// Coarse padding below the cube, in coarse voxels (at least 4 on each side).
    pub pad: u64,
    /// Coarse nodes per axis: the smallest 5-smooth size (fast for the FFT) holding the cube
    /// and 4 coarse voxels of padding on each side.
    pub coarse_nodes: u64,
    /// Tile edge in fine voxels.
    pub tile: u64,
    /// Octree level of tiles.
    pub tile_level: u32,
    /// Smoothing width in voxels.
    pub sigma_vox: f64,
}

impl Plan {
    /// Choose grids for `depth` on `cube` within `budget_bytes`: the smallest coarse ratio
    /// `r >= 4` whose coarse solve fits a third of the budget.
    pub fn new(
        cube: Cube,
        depth: u32,
        sigma_vox: f64,
        tile: Option<u64>,
        budget_bytes: u64,
    ) -> Result<Plan> {
        if !DEPTHS.contains(&depth) {
            return Err(Error::Usage(format!(
                "--depth {depth} is out of range: supported depths are {}..={}",
                DEPTHS.start(),
                DEPTHS.end()
            )));
        }
        let n = 1u64 << depth;
        let mut r = 4u64;
        loop {
            let e = 8 * r;
            let nc = smooth_size(n / r + 8);
            let coarse_bytes = nc * nc * nc * COARSE_BYTES_PER_NODE;
            if e >= n || coarse_bytes <= budget_bytes / 3 {
                break;
            }
            r *= 2;
        }
        let e = (8 * r).min(n);
        let r = (e / 8).max(1);
        let ov = e / 4;
        let coarse_nodes = smooth_size(n / r + 8);
        let pad = (coarse_nodes - n / r) / 2;
        let tile = tile.unwrap_or(64).clamp(e, n);
        let tile = tile.next_power_of_two().min(n);
        Ok(Plan {
            cube,
            depth,
            n,
            h: cube.size / n as f64,
            r,
            e,
            ov,
            leaf_level: depth - e.trailing_zeros(),
            pad,
            coarse_nodes,
            tile,
            tile_level: depth - tile.trailing_zeros(),
            sigma_vox,
        })
    }

    /// Coarse nodes per axis (periodic FFT size).
    pub fn coarse_n(&self) -> usize {
        self.coarse_nodes as usize
    }

    /// The coarse global grid.
    pub fn coarse_grid(&self) -> LocalGrid {
        let hc = self.h * self.r as f64;
        let o = self.pad as f64 * hc;
        LocalGrid {
            n: self.coarse_n(),
            h: hc,
            origin: [
                self.cube.origin[0] - o,
                self.cube.origin[1] - o,
                self.cube.origin[2] - o,
            ],
        }
    }

    /// Global fine node of the lower corner of leaf cell `key`.
    pub fn leaf_node(&self, key: CellKey) -> [i64; 3] {
        let (_, c) = key.decode();
        c.map(|v| v as i64 * self.e as i64)
    }

    /// The fine local grid of a leaf: the cell embedded in a cube twice its size.
    pub fn leaf_fine_grid(&self, key: CellKey) -> LocalGrid {
        let g = self.leaf_node(key);
        let half = (self.e / 2) as i64;
        LocalGrid {
            n: 2 * self.e as usize,
            h: self.h,
            origin: self.node_pos([g[0] - half, g[1] - half, g[2] - half]),
        }
    }

    /// World position of fine node `g`.
    pub fn node_pos(&self, g: [i64; 3]) -> [f64; 3] {
        [
            self.cube.origin[0] + g[0] as f64 * self.h,
            self.cube.origin[1] + g[1] as f64 * self.h,
            self.cube.origin[2] + g[2] as f64 * self.h,
        ]
    }

    /// Nodes per axis of a leaf's detail grid.
    pub fn detail_n(&self) -> usize {
        (self.e + 2 * self.ov + 1) as usize
    }
}

/// The coarse global solution.
pub struct CoarseField {
    grid: LocalGrid,
    values: Vec<f32>,
    r: i64,
    pad: i64,
}

impl CoarseField {
    /// What a block of `dims` fine nodes from node `lo` reads of the coarse solution, for
    /// [`Blend`]: the coarse nodes around it in fixed point (`unit`; indices clamped to the
    /// grid), per-axis trilinear tables, and `log2 r`.
    fn block(
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
    fn max_abs(&self) -> f64 {
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

/// A store cell's points sorted by leaf cell.
struct SortedCell {
    pos: Vec<[f64; 3]>,
    nrm: Vec<[f32; 3]>,
    col: Vec<[u16; 4]>,
    inten: Vec<f32>,
    ranges: Vec<(CellKey, usize, usize)>,
}

impl SortedCell {
    fn new(b: PointBatch, cube: &Cube, leaf_level: u32) -> SortedCell {
        let keys: Vec<CellKey> = b
            .pos
            .iter()
            .map(|p| CellKey::new(leaf_level, cube.cell_coords(*p, leaf_level)))
            .collect();
        let mut order: Vec<u32> = (0..b.len() as u32).collect();
        order.sort_by_key(|&i| (keys[i as usize], i));
        let pos: Vec<[f64; 3]> = order.iter().map(|&i| b.pos[i as usize]).collect();
        let nrm: Vec<[f32; 3]> = order.iter().map(|&i| b.normal[i as usize]).collect();
        let col: Vec<[u16; 4]> = if b.color.is_empty() {
            Vec::new()
        } else {
            order.iter().map(|&i| b.color[i as usize]).collect()
        };
        let inten: Vec<f32> = if b.intensity.is_empty() {
            Vec::new()
        } else {
            order.iter().map(|&i| b.intensity[i as usize]).collect()
        };
        let mut ranges = Vec::new();
        let mut s = 0;
        for (j, &i) in order.iter().enumerate() {
            let k = keys[i as usize];
            if j + 1 == order.len() || keys[order[j + 1] as usize] != k {
                ranges.push((k, s, j + 1));
                s = j + 1;
            }
        }
        SortedCell {
            pos,
            nrm,
            col,
            inten,
            ranges,
        }
    }

    fn bytes(&self) -> u64 {
        (self.pos.len() * 36 + self.col.len() * 8 + self.inten.len() * 4 + self.ranges.len() * 24)
            as u64
    }

    fn range(&self, k: CellKey) -> (usize, usize) {
        match self.ranges.binary_search_by_key(&k, |r| r.0) {
            Ok(i) => (self.ranges[i].1, self.ranges[i].2),
            Err(_) => (0, 0),
        }
    }
}

/// Points of the store by leaf cell, through a cache of decoded store cells bounded in bytes.
struct PointSource<'a> {
    store: &'a Store,
    plan: Plan,
    by_key: HashMap<CellKey, usize>,
    deeper: HashMap<CellKey, Vec<usize>>,
    cache: HashMap<usize, Arc<SortedCell>>,
    lru: VecDeque<usize>,
    bytes: u64,
    cap: u64,
}

impl<'a> PointSource<'a> {
    fn new(store: &'a Store, plan: Plan, cap: u64) -> PointSource<'a> {
        let mut by_key = HashMap::new();
        let mut deeper: HashMap<CellKey, Vec<usize>> = HashMap::new();
        for (i, c) in store.manifest.cells.iter().enumerate() {
            if c.level > plan.leaf_level {
                let mut k = c.key;
                while k.level() > plan.leaf_level {
                    k = k.parent();
                }
                deeper.entry(k).or_default().push(i);
            } else {
                by_key.insert(c.key, i);
            }
        }
        PointSource {
            store,
            plan,
            by_key,
            deeper,
            cache: HashMap::new(),
            lru: VecDeque::new(),
            bytes: 0,
            cap,
        }
    }

    fn covering(&self, k: CellKey) -> Vec<usize> {
        if let Some(v) = self.deeper.get(&k) {
            return v.clone();
        }
        let mut a = k;
        loop {
            if let Some(&i) = self.by_key.get(&a) {
                return vec![i];
            }
            if a == CellKey::ROOT {
                return Vec::new();
            }
            a = a.parent();
        }
    }

    fn cell(&mut self, i: usize) -> Result<Arc<SortedCell>> {
        if let Some(c) = self.cache.get(&i) {
            let c = Arc::clone(c);
            if let Some(pos) = self.lru.iter().position(|&j| j == i) {
                self.lru.remove(pos);
            }
            self.lru.push_back(i);
            return Ok(c);
        }
        let c = Arc::new(self.load(i)?);
        self.insert(i, Arc::clone(&c));
        Ok(c)
    }

    fn load(&self, i: usize) -> Result<SortedCell> {
        let b = self.store.read_cell(i)?;
        Ok(SortedCell::new(b, &self.plan.cube, self.plan.leaf_level))
    }

    fn insert(&mut self, i: usize, c: Arc<SortedCell>) {
        self.bytes += c.bytes();
        self.cache.insert(i, c);
        self.lru.push_back(i);
        while self.bytes > self.cap && self.lru.len() > 1 {
            if let Some(old) = self.lru.pop_front()
                && let Some(o) = self.cache.remove(&old)
            {
                self.bytes -= o.bytes();
            }
        }
    }

    /// Read and sort the store cells `wanted` that are not cached yet, in parallel on `pool`
    /// (decompression is most of a cell's cost), as many as half the cache holds; the rest
    /// are read when asked for. Only speed depends on this, never the points returned.
    fn preload(&mut self, wanted: &[usize], pool: &rayon::ThreadPool) -> Result<()> {
        let mut seen = std::collections::HashSet::new();
        let mut missing = Vec::new();
        let mut est = 0u64;
        for &i in wanted {
            if self.cache.contains_key(&i) || !seen.insert(i) {
                continue;
            }
            // SortedCell::bytes of the cell's points, without colours.
            est += self.store.manifest.cells[i].count * 36;
            if est > self.cap / 2 {
                break;
            }
            missing.push(i);
        }
        let loaded: Vec<Result<SortedCell>> =
            pool.install(|| missing.par_iter().map(|&i| self.load(i)).collect());
        for (i, c) in missing.into_iter().zip(loaded) {
            self.insert(i, Arc::new(c?));
        }
        Ok(())
    }

    /// The leaf-level cells meeting box `bx` (world), z slowest.
    fn keys_in(&self, bx: &Aabb) -> Vec<CellKey> {
        let lvl = self.plan.leaf_level;
        let side = 1i64 << lvl;
        let ca = self.plan.cube.cell_coords(bx.min, lvl).map(|v| v as i64);
        let cb = self.plan.cube.cell_coords(bx.max, lvl).map(|v| v as i64);
        let mut out = Vec::new();
        for z in ca[2].max(0)..=cb[2].min(side - 1) {
            for y in ca[1].max(0)..=cb[1].min(side - 1) {
                for x in ca[0].max(0)..=cb[0].min(side - 1) {
                    out.push(CellKey::new(lvl, [x as u32, y as u32, z as u32]));
                }
            }
        }
        out
    }

    /// Leaf `key` and its neighbours sharing a face, edge or corner, within the cube, z
    /// slowest.
    fn neighbours(key: CellKey) -> Vec<CellKey> {
        let (l, c) = key.decode();
        let side = 1i64 << l;
        let mut out = Vec::with_capacity(27);
        for dz in -1i64..=1 {
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let q = [c[0] as i64 + dx, c[1] as i64 + dy, c[2] as i64 + dz];
                    if q.iter().all(|&v| v >= 0 && v < side) {
                        out.push(CellKey::new(l, q.map(|v| v as u32)));
                    }
                }
            }
        }
        out
    }

    /// Call `f(cell, j)` for each point `j` of leaf-level cell `k` that lies in `bx`, in the
    /// store's order.
    fn visit(
        &mut self,
        k: CellKey,
        bx: &Aabb,
        mut f: impl FnMut(&SortedCell, usize),
    ) -> Result<()> {
        for si in self.covering(k) {
            let sc = self.cell(si)?;
            let (s, e) = sc.range(k);
            for j in s..e {
                if bx.contains(sc.pos[j]) {
                    f(&sc, j);
                }
            }
        }
        Ok(())
    }

    /// The store cells [`PointSource::near_points`] reads first for the box `lo..hi` and
    /// `margin`.
    fn cells_near(&self, lo: [f64; 3], hi: [f64; 3], margin: f64) -> Vec<usize> {
        let bx = Aabb { min: lo, max: hi }.grown(margin);
        self.keys_in(&bx)
            .into_iter()
            .flat_map(|k| self.covering(k))
            .collect()
    }

    /// The store cells [`PointSource::gather`] reads for leaf `key`.
    fn cells_for_leaf(&self, key: CellKey) -> Vec<usize> {
        Self::neighbours(key)
            .into_iter()
            .flat_map(|k| self.covering(k))
            .collect()
    }

    /// The points (with their colours, when the store has them) within `margin` of the box
    /// `lo..hi` (world), widening the margin (doubling, up to 6 times) while none is found.
    fn near_points(&mut self, lo: [f64; 3], hi: [f64; 3], margin: f64) -> Result<NearPoints> {
        let mut out = NearPoints::default();
        let mut m = margin;
        for _ in 0..7 {
            let bx = Aabb { min: lo, max: hi }.grown(m);
            for k in self.keys_in(&bx) {
                self.visit(k, &bx, |sc, j| {
                    out.pos.push(sc.pos[j]);
                    let c = sc.col.get(j).copied().unwrap_or([0; 4]);
                    out.col.push([c[0], c[1], c[2]]);
                    out.inten.push(sc.inten.get(j).copied().unwrap_or(0.0));
                })?;
            }
            out.lo = bx.min;
            out.hi = bx.max;
            if !out.pos.is_empty() {
                break;
            }
            m *= 2.0;
        }
        Ok(out)
    }

    /// The points of leaf `key`'s 1.8× box, and how many of them (the first ones) lie in the
    /// cell itself.
    fn gather(&mut self, key: CellKey) -> Result<LeafPoints> {
        let cell_box = self.plan.cube.cell_box(key);
        // The 1.8× box: 0.4 of the edge beyond each face.
        let reach = cell_box.grown(0.4 * (cell_box.max[0] - cell_box.min[0]));
        let mut own = LeafPoints::default();
        let mut rest = LeafPoints::default();
        for nk in Self::neighbours(key) {
            let dst = if nk == key { &mut own } else { &mut rest };
            self.visit(nk, &reach, |sc, j| {
                dst.pos.push(sc.pos[j]);
                dst.nrm.push(sc.nrm[j]);
            })?;
        }
        own.own = own.pos.len();
        own.pos.extend(rest.pos);
        own.nrm.extend(rest.nrm);
        Ok(own)
    }
}

/// Input points near a tile (those within `lo..hi`), with their colours (zero without).
#[derive(Default)]
struct NearPoints {
    pos: Vec<[f64; 3]>,
    col: Vec<[u16; 3]>,
    inten: Vec<f32>,
    lo: [f64; 3],
    hi: [f64; 3],
}

/// Number of input points blended into a vertex's colour.
const COLOUR_NEIGHBOURS: usize = 4;

/// Input points whose plane a vertex is moved onto (`fit`).
pub const FIT_NEIGHBOURS: usize = 20;

/// What the input points say about one vertex.
struct VertexFit {
    pos: [f64; 3],
    color: [u8; 3],
    intensity: f32,
    /// Farthest neighbour used: the answer is exact when the gathered box reaches beyond it.
    reach: f64,
}

impl NearPoints {
    /// For each vertex: its position moved onto the plane of its [`FIT_NEIGHBOURS`] nearest
    /// input points (when `fit`), and its colour, the inverse-distance blend (weights
    /// `1/max(d, h/100)`) of its [`COLOUR_NEIGHBOURS`] nearest points, 16-bit channels to 8
    /// bits by rounding `v/257`. Neighbours are ordered by distance, then position, then
    /// colour, so the answer depends only on the point set. Also returns the vertices whose
    /// answer may not be exact: their farthest neighbour lies beyond the gathered box's faces.
    ///
    /// The fit is a one-step moving-least-squares projection (Alexa et al. 2003, §3): the
    /// plane through the neighbours' mean with their least-variance normal. It moves a vertex
    /// only where its nearest point is within two voxels, by at most two voxels, and only by
    /// what exceeds twice the standard error of the plane's offset (`√λ₀ / k`), so on noisy
    /// points the smooth Poisson surface is kept and on precise ones the surface follows them
    /// as a screened solve would (Kazhdan & Hoppe 2013).
    fn fit_vertices(
        &self,
        vertices: &[[f64; 3]],
        h: f64,
        fit: bool,
    ) -> (Vec<VertexFit>, Vec<usize>) {
        if self.pos.is_empty() {
            let out = vertices
                .iter()
                .map(|v| VertexFit {
                    pos: *v,
                    color: [128; 3],
                    intensity: 0.0,
                    reach: 0.0,
                })
                .collect();
            return (out, Vec::new());
        }
        let grid = PointGrid::new(&self.pos, self.lo, self.hi, 2.5 * h);
        let want = if fit {
            FIT_NEIGHBOURS
        } else {
            COLOUR_NEIGHBOURS
        };
        // Two more than needed, so that ties at the last place are seen and broken alike.
        let k = want + 2;
        let mut inexact = Vec::new();
        let mut found = Vec::with_capacity(k);
        let out = vertices
            .iter()
            .enumerate()
            .map(|(vi, v)| {
                grid.nearest(*v, k, &mut found);
                let mut nb: Vec<(f64, [f64; 3], [u16; 3], f32)> = found
                    .iter()
                    .map(|&(d2, i)| {
                        let i = i as usize;
                        (d2, self.pos[i], self.col[i], self.inten[i])
                    })
                    .collect();
                nb.sort_by(|a, b| {
                    a.0.total_cmp(&b.0)
                        .then(a.1.partial_cmp(&b.1).unwrap_or(std::cmp::Ordering::Equal))
                        .then(a.2.cmp(&b.2))
                        .then(a.3.total_cmp(&b.3))
                });
                nb.truncate(want);
                let reach = nb.last().map_or(0.0, |x| x.0.sqrt());
                let room = (0..3)
                    .map(|a| (v[a] - self.lo[a]).min(self.hi[a] - v[a]))
                    .fold(f64::INFINITY, f64::min);
                if reach >= room {
                    inexact.push(vi);
                }
                let mut acc = [0f64; 4];
                let mut sw = 0.0;
                for (d2, _, c, i) in nb.iter().take(COLOUR_NEIGHBOURS) {
                    let w = 1.0 / d2.sqrt().max(h * 0.01);
                    for a in 0..3 {
                        acc[a] += w * c[a] as f64;
                    }
                    acc[3] += w * *i as f64;
                    sw += w;
                }
                let color =
                    [0, 1, 2].map(|a| ((acc[a] / sw) / 257.0).round().clamp(0.0, 255.0) as u8);
                let pos = if fit { project(*v, &nb, h) } else { *v };
                VertexFit {
                    pos,
                    color,
                    intensity: (acc[3] / sw) as f32,
                    reach,
                }
            })
            .collect();
        (out, inexact)
    }
}

/// A tile's points bucketed in a uniform grid, for exact k-nearest queries by growing shells
/// of cells: after the shell at Chebyshev distance `r` from the query's cell, every point not
/// yet seen lies at least `r·s` plus the query's distance to its own cell's faces away.
struct PointGrid<'a> {
    pos: &'a [[f64; 3]],
    lo: [f64; 3],
    s: f64,
    dims: [usize; 3],
    /// Start of each cell's points in `idx` (cells + 1 entries).
    start: Vec<u32>,
    /// Point indices, by cell.
    idx: Vec<u32>,
}

impl<'a> PointGrid<'a> {
    /// Points `pos` within `lo..hi`, in cells sized so that an occupied cell holds about 4
    /// points (starting from `s`; on a surface a cell's share grows with its area). Measured
    /// on a 1M-point bumpy sphere at depth 9, 2 to 16 points a cell were within 10% of each
    /// other, 4 the fastest; the tile stage took 5.9 s against 7.3 s with a kd-tree
    /// (kiddo).
    fn new(pos: &'a [[f64; 3]], lo: [f64; 3], hi: [f64; 3], s: f64) -> PointGrid<'a> {
        const OCCUPANCY: f64 = 4.0;
        let n = pos.len();
        let extent = (0..3)
            .map(|a| hi[a] - lo[a])
            .fold(0f64, f64::max)
            .max(1e-300);
        let mut s = s.clamp(extent * 1e-6, extent);
        let dims_for = |s: f64| [0, 1, 2].map(|a| (((hi[a] - lo[a]) / s).ceil() as usize).max(1));
        let cell_of = |p: &[f64; 3], s: f64, d: [usize; 3]| {
            let c = [0, 1, 2].map(|a| (((p[a] - lo[a]) / s) as usize).min(d[a] - 1));
            (c[2] * d[1] + c[1]) * d[0] + c[0]
        };
        for _ in 0..3 {
            while dims_for(s).iter().product::<usize>() > 8 * n + 4096 {
                s *= 2.0;
            }
            let d = dims_for(s);
            let mut cells: Vec<usize> = pos.iter().map(|p| cell_of(p, s, d)).collect();
            cells.sort_unstable();
            cells.dedup();
            let occupancy = n as f64 / cells.len().max(1) as f64;
            // Points on a surface: a cell's share grows with its area.
            let f = (OCCUPANCY / occupancy).sqrt().clamp(0.25, 4.0);
            if (0.7..1.4).contains(&f) {
                break;
            }
            s = (s * f).min(extent);
        }
        while dims_for(s).iter().product::<usize>() > 8 * n + 4096 {
            s *= 2.0;
        }
        let dims = dims_for(s);
        let mut start = vec![0u32; dims.iter().product::<usize>() + 1];
        let cell: Vec<usize> = pos.iter().map(|p| cell_of(p, s, dims)).collect();
        for &c in &cell {
            start[c + 1] += 1;
        }
        for i in 1..start.len() {
            start[i] += start[i - 1];
        }
        let mut fill = start.clone();
        let mut idx = vec![0u32; n];
        for (i, &c) in cell.iter().enumerate() {
            idx[fill[c] as usize] = i as u32;
            fill[c] += 1;
        }
        PointGrid {
            pos,
            lo,
            s,
            dims,
            start,
            idx,
        }
    }

    /// The `k` points nearest `q` (fewer if there are fewer) into `out`, as (squared
    /// distance, index) in increasing order (ties by index).
    fn nearest(&self, q: [f64; 3], k: usize, out: &mut Vec<(f64, u32)>) {
        out.clear();
        if k == 0 || self.pos.is_empty() {
            return;
        }
        let d = self.dims.map(|v| v as i64);
        let qc =
            [0, 1, 2].map(|a| (((q[a] - self.lo[a]) / self.s).floor() as i64).clamp(0, d[a] - 1));
        // The query's distance to its cell's faces (0 when outside the grid).
        let face = (0..3)
            .map(|a| {
                let c0 = self.lo[a] + qc[a] as f64 * self.s;
                (q[a] - c0).min(c0 + self.s - q[a]).max(0.0)
            })
            .fold(f64::INFINITY, f64::min);
        let mut r = 0i64;
        loop {
            let lo = qc.map(|c| c - r);
            let hi = qc.map(|c| c + r);
            for z in lo[2].max(0)..=hi[2].min(d[2] - 1) {
                for y in lo[1].max(0)..=hi[1].min(d[1] - 1) {
                    // Inside the shell only its two ends along x are new.
                    let inner = z != lo[2] && z != hi[2] && y != lo[1] && y != hi[1];
                    let step = if inner { hi[0] - lo[0] } else { 1 };
                    let mut x = if inner { lo[0] } else { lo[0].max(0) };
                    while x <= hi[0].min(d[0] - 1) {
                        if x < 0 {
                            x += step;
                            continue;
                        }
                        let c = ((z * d[1] + y) * d[0] + x) as usize;
                        for &i in &self.idx[self.start[c] as usize..self.start[c + 1] as usize] {
                            let p = self.pos[i as usize];
                            let d2 = (p[0] - q[0]).powi(2)
                                + (p[1] - q[1]).powi(2)
                                + (p[2] - q[2]).powi(2);
                            out.push((d2, i));
                        }
                        x += step;
                    }
                }
            }
            // Keep the k best seen: a point not among them cannot be among the k nearest.
            let by = |a: &(f64, u32), b: &(f64, u32)| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1));
            if out.len() > k {
                out.select_nth_unstable_by(k - 1, by);
                out.truncate(k);
            }
            let kth = out.iter().map(|e| e.0).fold(0f64, f64::max);
            let reach = r as f64 * self.s + face;
            let whole = (0..3).all(|a| lo[a] <= 0 && hi[a] >= d[a] - 1);
            if whole || (out.len() == k && kth <= reach * reach) {
                out.sort_unstable_by(by);
                return;
            }
            r += 1;
        }
    }
}

/// `v` moved onto the plane of its neighbours `nb` (see [`NearPoints::fit_vertices`]).
fn project(v: [f64; 3], nb: &[(f64, [f64; 3], [u16; 3], f32)], h: f64) -> [f64; 3] {
    if nb.len() < 3 || nb[0].0 > 4.0 * h * h {
        return v;
    }
    let n = nb.len() as f64;
    let mut c = [0f64; 3];
    for (_, p, _, _) in nb {
        for a in 0..3 {
            c[a] += p[a] / n;
        }
    }
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    for (_, p, _, _) in nb {
        let d = nalgebra::Vector3::new(p[0] - c[0], p[1] - c[1], p[2] - c[2]);
        m += d * d.transpose();
    }
    let e = m.symmetric_eigen();
    let i = e.eigenvalues.imin();
    let nrm = e.eigenvectors.column(i);
    let off = (v[0] - c[0]) * nrm[0] + (v[1] - c[1]) * nrm[1] + (v[2] - c[2]) * nrm[2];
    let se = e.eigenvalues[i].max(0.0).sqrt() / n;
    if off.abs() > 2.0 * h {
        return v;
    }
    // Shrunk toward zero by how much of it the plane's error could explain.
    let step = if off == 0.0 {
        0.0
    } else {
        off * (1.0 - (2.0 * se / off).powi(2)).max(0.0)
    };
    [0, 1, 2].map(|a| v[a] - step * nrm[a])
}

#[derive(Default)]
struct LeafPoints {
    pos: Vec<[f64; 3]>,
    nrm: Vec<[f32; 3]>,
    own: usize,
}

/// A leaf's detail grid in the blend's fixed point (none for a leaf left to the coarse
/// solution) and its share of the iso-value.
#[derive(Debug)]
struct LeafDetail {
    detail: Option<Detail>,
    iso_sum: f64,
    iso_count: u64,
}

/// The two solvers every leaf uses: its fine grid and its coarse local grid.
struct LeafSolvers {
    fine: Solver,
    coarse: Solver,
}

impl LeafSolvers {
    fn new(plan: &Plan) -> LeafSolvers {
        let fine = plan.leaf_fine_grid(CellKey::new(plan.leaf_level, [0; 3]));
        LeafSolvers {
            fine: Solver::new(&fine, plan.sigma_vox),
            coarse: Solver::new(&leaf_coarse_grid(plan, &fine), plan.sigma_vox),
        }
    }
}

/// A leaf's coarse local grid: its fine grid at the coarse spacing (node `J` on fine node `rJ`).
fn leaf_coarse_grid(plan: &Plan, fine: &LocalGrid) -> LocalGrid {
    LocalGrid {
        n: fine.n / plan.r as usize,
        h: fine.h * plan.r as f64,
        origin: fine.origin,
    }
}

fn solve_leaf(
    plan: &Plan,
    unit: f32,
    solvers: &LeafSolvers,
    key: CellKey,
    pts: &LeafPoints,
    coarse: &CoarseField,
) -> LeafDetail {
    let fine = plan.leaf_fine_grid(key);
    let coarse_local = leaf_coarse_grid(plan, &fine);
    let f = solvers.fine.solve(&fine, &pts.pos, &pts.nrm);
    let c = solvers.coarse.solve(&coarse_local, &pts.pos, &pts.nrm);
    let m = plan.detail_n();
    let nc = coarse_local.n;
    // Per axis, detail node s sits on fine node q = E/2 − ov + s, between coarse nodes
    // ⌊q/r⌋ and ⌊q/r⌋ + 1 (clamped) with weights 1 − t and t, t = (q mod r)/r.
    let r = plan.r as i64;
    let q0 = (plan.e / 2) as i64 - plan.ov as i64;
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
    }
}

/// The paper's refinement test against the coarse solution: the mean distance of a 10%
/// sample of the cell's points (every tenth) to the coarse field's level set through them,
/// to first order `|F(p) − F̄| / |∇F(p)|`, with `F̄` the mean of `F` over the sample.
fn coarse_error(coarse: &CoarseField, pts: &LeafPoints) -> f64 {
    let own = &pts.pos[..pts.own];
    let sample: Vec<[f64; 3]> = own.iter().step_by(10).copied().collect();
    if sample.is_empty() {
        return 0.0;
    }
    let vals: Vec<f64> = sample.iter().map(|p| coarse.eval(*p)).collect();
    let level = vals.iter().sum::<f64>() / vals.len() as f64;
    let d = 0.5 * coarse.grid.h;
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
fn coarse_only(pts: &LeafPoints, coarse: &CoarseField) -> LeafDetail {
    LeafDetail {
        detail: None,
        iso_sum: pts.pos[..pts.own].iter().map(|p| coarse.eval(*p)).sum(),
        iso_count: pts.own as u64,
    }
}

/// Leaf checkpoints: this magic, the cell key, the iso sum (f64) and count (u64), the detail's
/// exponent (u32) and a flag (u32: 1 with a detail), then the detail's 16-bit values
/// ([`quantise_detail`], padded to even), all little-endian, zstd-compressed.
const LEAF_MAGIC: &[u8; 8] = b"SFLEAF02";
const LEAF_HEADER: usize = 40;

fn leaf_path(dir: &Path, key: CellKey) -> PathBuf {
    dir.join(format!("{}.zst", key.file_name()))
}

/// Values of a detail grid of `m³` nodes, padded to even.
fn detail_len(m: usize) -> usize {
    let n = m * m * m;
    n + n % 2
}

fn write_leaf(dir: &Path, key: CellKey, d: &LeafDetail) -> Result<()> {
    let values = d.detail.as_ref().map_or(&[][..], |d| &d.values[..]);
    let mut raw = Vec::with_capacity(LEAF_HEADER + values.len() * 2);
    raw.extend_from_slice(LEAF_MAGIC);
    raw.extend_from_slice(&key.0.to_le_bytes());
    raw.extend_from_slice(&d.iso_sum.to_le_bytes());
    raw.extend_from_slice(&d.iso_count.to_le_bytes());
    raw.extend_from_slice(&d.detail.as_ref().map_or(0u32, |d| d.shift).to_le_bytes());
    raw.extend_from_slice(&(d.detail.is_some() as u32).to_le_bytes());
    for v in values {
        raw.extend_from_slice(&v.to_le_bytes());
    }
    let z = zstd::bulk::compress(&raw, 1)
        .map_err(|e| Error::Internal(format!("zstd compression failed: {e}")))?;
    let path = leaf_path(dir, key);
    let tmp = path.with_extension("tmp");
    let mut f = std::fs::File::create(&tmp).with_path(&tmp)?;
    f.write_all(&z).with_path(&tmp)?;
    drop(f);
    std::fs::rename(&tmp, &path).with_path(&path)
}

fn read_leaf(dir: &Path, key: CellKey, m: usize) -> Result<LeafDetail> {
    let path = leaf_path(dir, key);
    let mut z = Vec::new();
    std::fs::File::open(&path)
        .and_then(|mut f| f.read_to_end(&mut z))
        .with_path(&path)?;
    let n = detail_len(m);
    let raw = zstd::bulk::decompress(&z, LEAF_HEADER + n * 2 + 16)
        .map_err(|e| Error::input(&path, format!("corrupt leaf checkpoint: {e}")))?;
    if raw.len() >= 8 && raw[..6] == LEAF_MAGIC[..6] && raw[..8] != LEAF_MAGIC[..] {
        return Err(Error::input(
            &path,
            format!(
                "leaf checkpoint written by another version of scanflow ({}; this one reads {}): run again without --resume in a new work directory",
                String::from_utf8_lossy(&raw[..8]),
                String::from_utf8_lossy(LEAF_MAGIC)
            ),
        ));
    }
    let u32_at = |o: usize| u32::from_le_bytes([raw[o], raw[o + 1], raw[o + 2], raw[o + 3]]);
    let u64_at = |o: usize| {
        let mut a = [0u8; 8];
        a.copy_from_slice(&raw[o..o + 8]);
        u64::from_le_bytes(a)
    };
    if raw.len() < LEAF_HEADER || raw[..8] != LEAF_MAGIC[..] {
        return Err(Error::input(
            &path,
            "corrupt leaf checkpoint: wrong size or magic",
        ));
    }
    let (shift, has) = (u32_at(32), u32_at(36));
    let want = LEAF_HEADER + if has == 1 { n * 2 } else { 0 };
    if has > 1 || raw.len() != want || shift > MAX_SHIFT {
        return Err(Error::input(
            &path,
            format!(
                "corrupt leaf checkpoint: {} bytes with detail flag {has} and exponent {shift}, expected {want} bytes and an exponent of at most {MAX_SHIFT}",
                raw.len()
            ),
        ));
    }
    if u64_at(8) != key.0 {
        return Err(Error::input(&path, "leaf checkpoint of another cell"));
    }
    let detail = (has == 1).then(|| Detail {
        values: raw[LEAF_HEADER..]
            .chunks_exact(2)
            .map(|b| i16::from_le_bytes([b[0], b[1]]))
            .collect(),
        shift,
    });
    Ok(LeafDetail {
        detail,
        iso_sum: f64::from_bits(u64_at(16)),
        iso_count: u64_at(24),
    })
}

/// The detail of refined leaf `key` (the tile stage reads only those).
fn leaf_detail(dir: &Path, key: CellKey, m: usize) -> Result<Detail> {
    read_leaf(dir, key, m)?.detail.ok_or_else(|| {
        Error::input(
            leaf_path(dir, key),
            "leaf checkpoint without a detail, where the run refined this leaf",
        )
    })
}

const TILE_MAGIC: &[u8; 8] = b"SFTILE04";

fn tile_path(dir: &Path, t: u64) -> PathBuf {
    dir.join(format!("{t:016x}.zst"))
}

/// Checkpoint a tile's mesh (after trimming): edge keys, f64 positions, triangles, then the
/// vertex colours when there are any.
fn write_tile(path: &Path, m: &TileMesh) -> Result<()> {
    let mut raw = Vec::with_capacity(32 + m.keys.len() * 35 + m.triangles.len() * 12);
    raw.extend_from_slice(TILE_MAGIC);
    raw.extend_from_slice(&(m.keys.len() as u64).to_le_bytes());
    raw.extend_from_slice(&(m.triangles.len() as u64).to_le_bytes());
    raw.extend_from_slice(&(m.colors.len() as u64).to_le_bytes());
    raw.extend_from_slice(&(m.intensity.len() as u64).to_le_bytes());
    for k in &m.keys {
        raw.extend_from_slice(&k.0.to_le_bytes());
    }
    for p in &m.positions {
        for v in p {
            raw.extend_from_slice(&v.to_le_bytes());
        }
    }
    for t in &m.triangles {
        for v in t {
            raw.extend_from_slice(&v.to_le_bytes());
        }
    }
    for c in &m.colors {
        raw.extend_from_slice(c);
    }
    for v in &m.intensity {
        raw.extend_from_slice(&v.to_le_bytes());
    }
    let z = zstd::bulk::compress(&raw, 1)
        .map_err(|e| Error::Internal(format!("zstd compression failed: {e}")))?;
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, z).with_path(&tmp)?;
    std::fs::rename(&tmp, path).with_path(path)
}

fn read_tile(path: &Path) -> Result<TileMesh> {
    let z = std::fs::read(path).with_path(path)?;
    let bad = |what: &str| Error::input(path, format!("corrupt tile checkpoint: {what}"));
    let raw = zstd::stream::decode_all(&z[..]).map_err(|e| bad(&e.to_string()))?;
    if raw.len() < 40 || &raw[..8] != TILE_MAGIC {
        return Err(bad("wrong magic"));
    }
    let u64_at = |o: usize| {
        let mut a = [0u8; 8];
        a.copy_from_slice(&raw[o..o + 8]);
        u64::from_le_bytes(a)
    };
    let (nv, nt) = (u64_at(8) as usize, u64_at(16) as usize);
    let (nc, ni) = (u64_at(24) as usize, u64_at(32) as usize);
    if !(nc == 0 || nc == nv)
        || !(ni == 0 || ni == nv)
        || raw.len() != 40 + nv * 32 + nt * 12 + nc * 3 + ni * 4
    {
        return Err(bad("wrong size"));
    }
    let mut m = TileMesh::default();
    let mut o = 40;
    for _ in 0..nv {
        m.keys.push(crate::types::EdgeKey(u64_at(o)));
        o += 8;
    }
    for _ in 0..nv {
        m.positions
            .push([0, 1, 2].map(|k| f64::from_bits(u64_at(o + 8 * k))));
        o += 24;
    }
    for _ in 0..nt {
        let mut t = [0u32; 3];
        for v in &mut t {
            *v = u32::from_le_bytes([raw[o], raw[o + 1], raw[o + 2], raw[o + 3]]);
            o += 4;
        }
        m.triangles.push(t);
    }
    for c in raw[o..o + nc * 3].chunks_exact(3) {
        m.colors.push([c[0], c[1], c[2]]);
    }
    o += nc * 3;
    for v in raw[o..].chunks_exact(4) {
        m.intensity
            .push(f32::from_le_bytes([v[0], v[1], v[2], v[3]]));
    }
    Ok(m)
}

/// What a work directory was made for; a resumed run must match it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct RunInfo {
    scanflow: String,
    trim: bool,
    #[serde(default)]
    fit: bool,
    error: f64,
    min_points: u64,
    store_points: u64,
    store_cells_crc: Vec<u32>,
    plan: Plan,
}

/// Reconstruct the surface of the points in `store` into the PLY mesh `out`.
pub fn reconstruct(
    store: &Store,
    out: &Path,
    params: &ReconParams,
    ctx: &Ctx,
) -> Result<ReconStats> {
    let t0 = Instant::now();
    let m = &store.manifest;
    if !m.attributes.normal {
        return Err(Error::input(
            &store.dir,
            "the store's points have no normals (nx ny nz), which reconstruction requires: ingest it again with --normals auto or estimate, or reconstruct from the point files (normals are then estimated)",
        ));
    }
    if m.point_count < 16 {
        return Err(Error::input(
            &store.dir,
            format!("only {} points: a solve needs at least 16", m.point_count),
        ));
    }
    let plan = Plan::new(
        m.cube,
        params.depth,
        params.sigma_vox,
        params.tile_voxels,
        ctx.budget.total(),
    )?;
    // The work directory: refuse another run's files unless resuming the same run.
    let leaves_dir = params.work_dir.join("leaves");
    let info = RunInfo {
        scanflow: env!("CARGO_PKG_VERSION").into(),
        trim: params.trim,
        fit: params.fit,
        error: params.error,
        min_points: params.min_points,
        store_points: m.point_count,
        store_cells_crc: m.cells.iter().map(|c| c.crc32).collect(),
        plan,
    };
    let info_path = params.work_dir.join("run.json");
    if info_path.exists() {
        let old: Option<RunInfo> = std::fs::read_to_string(&info_path)
            .ok()
            .and_then(|t| serde_json::from_str(&t).ok());
        if !params.resume {
            return Err(Error::input(
                &params.work_dir,
                "work directory holds another run's files; pass --resume to continue that run, or choose another --work-dir",
            ));
        }
        if old.as_ref() != Some(&info) {
            return Err(Error::input(
                &params.work_dir,
                "cannot resume: the work directory was made for other inputs or options",
            ));
        }
    } else {
        std::fs::create_dir_all(&leaves_dir).with_path(&leaves_dir)?;
        let text = serde_json::to_string_pretty(&info)
            .map_err(|e| Error::Internal(format!("run.json: {e}")))?;
        std::fs::write(&info_path, text).with_path(&info_path)?;
    }
    std::fs::create_dir_all(&leaves_dir).with_path(&leaves_dir)?;
    let tiles_dir = params.work_dir.join("tiles");
    std::fs::create_dir_all(&tiles_dir).with_path(&tiles_dir)?;

    // Pass 1: splat every point into the coarse grid; collect occupied leaf cells; the
    // covariance of the points to refuse planar and linear inputs.
    let cgrid = plan.coarse_grid();
    let _coarse_permit = ctx
        .budget
        .acquire(cgrid.scratch_bytes(), "the coarse global solve")?;
    let stage = ctx.progress.stage("splat", Some(m.point_count), "points");
    let mut v = vec![[0f32; 3]; cgrid.len()];
    let mut occupied = BTreeSet::new();
    let mut support = Support::new(&plan);
    let mut moments = [0f64; 10];
    let wave = 2 * ctx.threads();
    let ncells = m.cells.len();
    let mut i = 0;
    while i < ncells {
        let ids: Vec<usize> = (i..(i + wave).min(ncells)).collect();
        let bytes: u64 = ids.iter().map(|&j| m.cells[j].count * 52).sum();
        let _permit = ctx.budget.acquire(bytes, "a wave of store cells")?;
        let batches: Vec<Result<PointBatch>> = ctx
            .pool
            .install(|| ids.par_iter().map(|&j| store.read_cell(j)).collect());
        for b in batches {
            let b = b?;
            fft_solve::splat(&cgrid, &b.pos, &b.normal, &mut v);
            for p in &b.pos {
                support.mark(*p);
                occupied.insert(CellKey::new(
                    plan.leaf_level,
                    plan.cube.cell_coords(*p, plan.leaf_level),
                ));
                let c = m.bounds.min;
                let q = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
                moments[0] += 1.0;
                moments[1] += q[0];
                moments[2] += q[1];
                moments[3] += q[2];
                moments[4] += q[0] * q[0];
                moments[5] += q[1] * q[1];
                moments[6] += q[2] * q[2];
                moments[7] += q[0] * q[1];
                moments[8] += q[0] * q[2];
                moments[9] += q[1] * q[2];
            }
            stage.inc(b.len() as u64);
        }
        i += wave;
    }
    stage.finish(None);
    check_not_flat(store, &moments)?;
    let stage = ctx.progress.stage("coarse", None, "solves");
    let coarse = CoarseField {
        values: ctx
            .pool
            .install(|| fft_solve::solve_splatted(&cgrid, v, plan.sigma_vox)),
        grid: cgrid,
        r: plan.r as i64,
        pad: plan.pad as i64,
    };
    stage.finish(None);

    // Pass 2: leaves, in Morton order, solved in parallel waves, spilled to the work dir.
    let leaves: Vec<CellKey> = occupied.into_iter().collect();
    let fine_bytes = LocalGrid {
        n: 2 * plan.e as usize,
        h: plan.h,
        origin: [0.0; 3],
    }
    .scratch_bytes();
    // Leaves in Morton order need the store cells around them: a small cache suffices.
    let point_cap = (ctx.budget.total() / 4).min(128 << 20);
    let mut src = PointSource::new(store, plan, point_cap);
    let _cache_permit = ctx.budget.acquire(point_cap, "the store cell cache")?;
    let stage = ctx
        .progress
        .stage("leaves", Some(leaves.len() as u64), "leaves");
    let mut iso_sum = 0.0;
    let mut iso_count = 0u64;
    let mut reused = 0;
    let mut refined_set = BTreeSet::new();
    let tol = params.error * m.bounds.diagonal();
    let dm = plan.detail_n();
    let solvers = LeafSolvers::new(&plan);
    // Fixed point for the blend (`extract::field`): the coarse values within 2^21 units;
    // leaf details are stored in it.
    let unit = unit_for(coarse.max_abs());
    for wave_keys in leaves.chunks(wave) {
        // Leaves a resumed run checkpointed already are read back, the others solved.
        let done: Vec<bool> = wave_keys
            .iter()
            .map(|&k| params.resume && leaf_path(&leaves_dir, k).exists())
            .collect();
        let wanted: Vec<usize> = wave_keys
            .iter()
            .zip(&done)
            .filter(|(_, done)| !**done)
            .flat_map(|(&k, _)| src.cells_for_leaf(k))
            .collect();
        src.preload(&wanted, &ctx.pool)?;
        let mut todo = Vec::new();
        for (&k, &done) in wave_keys.iter().zip(&done) {
            if done {
                todo.push((k, None));
            } else {
                todo.push((k, Some(src.gather(k)?)));
            }
        }
        let pts_bytes: u64 = todo
            .iter()
            .map(|(_, p)| p.as_ref().map_or(0, |p| p.pos.len() as u64 * 36))
            .sum();
        let _permit = ctx.budget.acquire(
            // At most one solve a worker runs at once.
            fine_bytes * todo.len().min(ctx.threads()) as u64 + pts_bytes,
            "a wave of leaf solves",
        )?;
        let res: Vec<Result<(f64, u64, bool, bool)>> = ctx.pool.install(|| {
            todo.par_iter()
                .map(|(k, pts)| match pts {
                    None => {
                        let d = read_leaf(&leaves_dir, *k, dm)?;
                        Ok((d.iso_sum, d.iso_count, true, d.detail.is_some()))
                    }
                    Some(p) => {
                        let refine =
                            p.own as u64 >= params.min_points && coarse_error(&coarse, p) > tol;
                        let d = if refine {
                            solve_leaf(&plan, unit, &solvers, *k, p, &coarse)
                        } else {
                            coarse_only(p, &coarse)
                        };
                        write_leaf(&leaves_dir, *k, &d)?;
                        Ok((d.iso_sum, d.iso_count, false, d.detail.is_some()))
                    }
                })
                .collect()
        });
        for (r, k) in res.into_iter().zip(wave_keys) {
            let (s, c, was_reused, refined) = r?;
            iso_sum += s;
            iso_count += c;
            reused += was_reused as usize;
            if refined {
                refined_set.insert(*k);
            }
        }
        stage.inc(wave_keys.len() as u64);
    }
    stage.finish(None);
    let with_color = m.attributes.color;
    let with_intensity = m.attributes.intensity;
    let near_src = (with_color || with_intensity || params.fit).then(|| std::sync::Mutex::new(src));
    let iso = if iso_count > 0 {
        iso_sum / iso_count as f64
    } else {
        0.0
    };

    // Pass 3: tiles in Morton order: blend, extract, weld, write.
    let leaf_set = refined_set;
    let ntiles_axis = plan.n / plan.tile;
    let tiles_total = ntiles_axis.pow(3);
    let own = pou::leaf_weights(plan.e as i64, plan.ov as i64);
    let geom = GridGeom {
        origin: plan.cube.origin,
        h: plan.h,
        n: plan.n,
    };
    // Both welder callbacks write to the one writer.
    let mut gpu = crate::extract::gpu::GpuExtractor::new(params.gpu)?;
    if let Some(g) = &gpu {
        log::info!("extracting tiles on the GPU: {}", g.adapter_name());
    }
    let writer =
        std::cell::RefCell::new(MeshPlyWriter::create_with(out, with_color, with_intensity)?);
    let mut welder = Welder::new();
    // Tiles in Morton order reuse the leaves of their neighbours: the cache keeps twice the
    // leaves of the last wave (the next wave's tiles are its neighbours), within a sixth of
    // the budget.
    let detail_cap = ctx.budget.total() / 6;
    let mut gpu_totals = GpuTotals::default();
    let mut detail_cache = DetailCache::new(&leaves_dir, dm, detail_cap);
    let _detail_permit = ctx.budget.acquire(detail_cap, "the leaf detail cache")?;
    let tile_nodes = (plan.tile + 1).pow(3);
    let stage = ctx.progress.stage("tiles", Some(tiles_total), "tiles");
    let mut tiles_done = 0usize;
    let mut t = 0u64;
    let last_tile = |key: crate::types::EdgeKey| -> u64 {
        let (node, _axis) = geom.decode_edge(key);
        let c = node.map(|v| (v / plan.tile).min(ntiles_axis - 1) as u32);
        morton3(c)
    };
    while t < tiles_total {
        // A wave of non-empty tiles.
        let mut wave_tiles = Vec::new();
        while t < tiles_total && wave_tiles.len() < wave {
            let c = crate::types::demorton3(t);
            let lo = c.map(|v| v as i64 * plan.tile as i64);
            let hi = lo.map(|v| v + plan.tile as i64);
            let near = leaves_near(&plan, &leaf_set, lo, hi);
            let (mn, mx) = coarse.range(lo, hi);
            let empty = near.is_empty() && (mn as f64 > iso || (mx as f64) < iso);
            if !empty {
                wave_tiles.push((t, lo, near));
            }
            t += 1;
        }
        detail_cache.fit(2 * wave_tiles.iter().map(|w| w.2.len()).sum::<usize>());
        // Tiles a resumed run checkpointed already are read back, the others extracted.
        let done: Vec<bool> = wave_tiles
            .iter()
            .map(|w| params.resume && tile_path(&tiles_dir, w.0).exists())
            .collect();
        let todo: Vec<&(u64, [i64; 3], Vec<CellKey>)> = wave_tiles
            .iter()
            .zip(&done)
            .filter(|(_, done)| !**done)
            .map(|(w, _)| w)
            .collect();
        // The box whose points a tile's fit and colours read: the tile and a margin.
        let near_box = |lo: [i64; 3]| {
            let a = plan.node_pos(lo);
            let b = plan.node_pos(lo.map(|v| v + plan.tile as i64));
            (a, b, plan.h * plan.e as f64 * 0.25)
        };
        // Read what the wave needs in parallel first: store cells for the fit and colours,
        // leaf details for the blend.
        if let Some(src) = near_src.as_ref() {
            let mut src = src
                .lock()
                .map_err(|_| Error::Internal("the colour point source was poisoned".into()))?;
            let wanted: Vec<usize> = todo
                .iter()
                .flat_map(|(_, lo, _)| {
                    let (a, b, margin) = near_box(*lo);
                    src.cells_near(a, b, margin)
                })
                .collect();
            src.preload(&wanted, &ctx.pool)?;
        }
        let keys: Vec<CellKey> = todo.iter().flat_map(|w| w.2.iter().copied()).collect();
        detail_cache.prefetch(&keys, &ctx.pool)?;
        let mut loaded = Vec::with_capacity(wave_tiles.len());
        let mut near_pts: Vec<Option<NearPoints>> = Vec::with_capacity(wave_tiles.len());
        for ((tt, lo, near), &done) in wave_tiles.iter().zip(&done) {
            if done {
                loaded.push((*tt, *lo, None));
                near_pts.push(None);
                continue;
            }
            near_pts.push(match near_src.as_ref() {
                Some(src) => {
                    let mut src = src.lock().map_err(|_| {
                        Error::Internal("the colour point source was poisoned".into())
                    })?;
                    let (a, b, margin) = near_box(*lo);
                    Some(src.near_points(a, b, margin)?)
                }
                None => None,
            });
            let mut ds = Vec::with_capacity(near.len());
            for k in near {
                ds.push((*k, detail_cache.get(*k)?));
            }
            loaded.push((*tt, *lo, Some(ds)));
        }
        let _permit = ctx
            .budget
            .acquire(loaded.len() as u64 * tile_nodes * 12, "a wave of tiles")?;
        let dims = [(plan.tile + 1) as usize; 3];
        let finish =
            |tt: u64, mut mesh: TileMesh, cp: &Option<NearPoints>| -> Result<(u64, TileMesh)> {
                if params.trim {
                    trim_mesh(&mut mesh, |c| support.near(c));
                }
                if let Some(cp) = cp {
                    let (mut fits, inexact) = cp.fit_vertices(&mesh.positions, plan.h, params.fit);
                    // Vertices whose neighbours may lie beyond the gathered box: their true
                    // neighbours lie within their current farthest one, so one wider gather
                    // around them is exact (rare: vertices far from every point).
                    if let (false, Some(src)) = (inexact.is_empty(), near_src.as_ref()) {
                        let reach = inexact.iter().map(|&i| fits[i].reach).fold(0.0, f64::max);
                        let mut lo = [f64::INFINITY; 3];
                        let mut hi = [f64::NEG_INFINITY; 3];
                        let vs: Vec<[f64; 3]> =
                            inexact.iter().map(|&i| mesh.positions[i]).collect();
                        for v in &vs {
                            for a in 0..3 {
                                lo[a] = lo[a].min(v[a]);
                                hi[a] = hi[a].max(v[a]);
                            }
                        }
                        let wide = src
                            .lock()
                            .map_err(|_| Error::Internal("the point source was poisoned".into()))?
                            .near_points(lo, hi, reach * (1.0 + 1e-9) + plan.h * 1e-6)?;
                        let (fixed, _) = wide.fit_vertices(&vs, plan.h, params.fit);
                        for (&vi, f) in inexact.iter().zip(fixed) {
                            fits[vi] = f;
                        }
                    }
                    for (p, f) in mesh.positions.iter_mut().zip(&fits) {
                        *p = f.pos;
                    }
                    if with_color {
                        mesh.colors = fits.iter().map(|f| f.color).collect();
                    }
                    if with_intensity {
                        mesh.intensity = fits.iter().map(|f| f.intensity).collect();
                    }
                }
                write_tile(&tile_path(&tiles_dir, tt), &mesh)?;
                Ok((tt, mesh))
            };
        let meshes: Vec<Result<(u64, TileMesh)>> = match gpu.as_mut() {
            // GPU: a thread feeds the device tile after tile (fields built there from the leaf
            // grids) while the pool finishes the tiles it has extracted (fit, colour, trim,
            // checkpoint).
            Some(g) => {
                type Slot = Mutex<Option<Result<(u64, TileMesh)>>>;
                let done: Vec<Slot> = loaded.iter().map(|_| Mutex::new(None)).collect();
                let (tx, rx) = crossbeam_channel::bounded::<(usize, Result<TileMesh>)>(2);
                let pool = &ctx.pool;
                std::thread::scope(|s| -> Result<()> {
                    let (loaded, plan, own, coarse) = (&loaded, &plan, &own, &coarse);
                    let gpu_totals = &mut gpu_totals;
                    s.spawn(move || {
                        for (i, (_, lo, ds)) in loaded.iter().enumerate() {
                            let Some(ds) = ds else { continue };
                            let b = tile_blend(plan, own, coarse, unit, *lo, ds);
                            let mut mesh = TileMesh::default();
                            // The host side of the GPU call uses rayon: keep it on our pool.
                            let r = pool
                                .install(|| g.extract_blend(&b, iso as f32, &geom, &mut mesh))
                                .map(|st| {
                                    gpu_totals.add(&st);
                                    mesh
                                });
                            if tx.send((i, r)).is_err() {
                                break;
                            }
                        }
                    });
                    for (i, (tt, _, ds)) in loaded.iter().enumerate() {
                        if let (None, Ok(mut d)) = (ds, done[i].lock()) {
                            *d = Some(read_tile(&tile_path(&tiles_dir, *tt)).map(|m| (*tt, m)));
                        }
                    }
                    pool.in_place_scope(|sc| {
                        for (i, r) in rx {
                            let (done, finish, near_pts, loaded) =
                                (&done, &finish, &near_pts, &loaded);
                            sc.spawn(move |_| {
                                let tt = loaded[i].0;
                                let r = r.and_then(|m| finish(tt, m, &near_pts[i]));
                                if let Ok(mut d) = done[i].lock() {
                                    *d = Some(r);
                                }
                            });
                        }
                    });
                    Ok(())
                })?;
                done.into_iter()
                    .map(|d| {
                        d.into_inner().ok().flatten().unwrap_or_else(|| {
                            Err(Error::Internal("a tile was not extracted".into()))
                        })
                    })
                    .collect()
            }
            None => ctx.pool.install(|| {
                loaded
                    .par_iter()
                    .zip(near_pts.par_iter())
                    .map(|((tt, lo, ds), cp)| {
                        let Some(ds) = ds else {
                            return Ok((*tt, read_tile(&tile_path(&tiles_dir, *tt))?));
                        };
                        let f = tile_blend(&plan, &own, &coarse, unit, *lo, ds).eval();
                        let mut mesh = TileMesh::default();
                        marching_cubes(
                            &f,
                            dims,
                            lo.map(|v| v as u64),
                            iso as f32,
                            &geom,
                            &mut mesh,
                        )?;
                        finish(*tt, mesh, cp)
                    })
                    .collect()
            }),
        };
        for m in meshes {
            let (tt, mesh) = m?;
            welder.add_tile(
                tt,
                &mesh,
                last_tile,
                |_, i, p| {
                    writer.borrow_mut().vertex_with(
                        p,
                        mesh.colors.get(i).copied(),
                        mesh.intensity.get(i).copied(),
                    )
                },
                |tri| writer.borrow_mut().triangle(tri),
            )?;
            tiles_done += 1;
        }
        stage.inc((t - stage.done()).min(tiles_total));
    }
    stage.finish(None);
    if gpu.is_some() {
        gpu_totals.log();
    }
    let ws = writer.into_inner().finish()?;
    Ok(ReconStats {
        vertices: ws.vertices,
        faces: ws.faces,
        leaves: leaves.len(),
        leaves_refined: leaf_set.len(),
        leaves_reused: reused,
        tiles: tiles_done,
        iso,
        leaf_voxels: plan.e,
        coarse_ratio: plan.r,
        tile_voxels: plan.tile,
        peak_frontier: welder.peak_frontier(),
        secs: t0.elapsed().as_secs_f64(),
    })
}

/// Which coarse voxels hold input points (for `--trim`).
struct Support {
    origin: [f64; 3],
    inv_h: f64,
    n: i64,
    bits: Vec<u64>,
}

impl Support {
    fn new(plan: &Plan) -> Support {
        let n = (plan.n / plan.r) as i64;
        Support {
            origin: plan.cube.origin,
            inv_h: 1.0 / (plan.h * plan.r as f64),
            n,
            bits: vec![0u64; ((n * n * n) as usize).div_ceil(64)],
        }
    }

    fn cell(&self, p: [f64; 3]) -> [i64; 3] {
        [0, 1, 2]
            .map(|a| (((p[a] - self.origin[a]) * self.inv_h).floor() as i64).clamp(0, self.n - 1))
    }

    fn mark(&mut self, p: [f64; 3]) {
        let c = self.cell(p);
        let i = ((c[2] * self.n + c[1]) * self.n + c[0]) as usize;
        self.bits[i / 64] |= 1 << (i % 64);
    }

    /// True when a point lies in the coarse voxel of `p` or one of its 26 neighbours.
    fn near(&self, p: [f64; 3]) -> bool {
        let c = self.cell(p);
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let q = [c[0] + dx, c[1] + dy, c[2] + dz];
                    if q.iter().any(|&v| v < 0 || v >= self.n) {
                        continue;
                    }
                    let i = ((q[2] * self.n + q[1]) * self.n + q[0]) as usize;
                    if self.bits[i / 64] & (1 << (i % 64)) != 0 {
                        return true;
                    }
                }
            }
        }
        false
    }
}

/// Keep the triangles whose centroid `keep` accepts, and only the vertices they use.
fn trim_mesh(mesh: &mut TileMesh, keep: impl Fn([f64; 3]) -> bool) {
    let mut used = vec![u32::MAX; mesh.positions.len()];
    let mut tris = Vec::with_capacity(mesh.triangles.len());
    let mut keys = Vec::new();
    let mut positions = Vec::new();
    let mut colors = Vec::new();
    let mut intensity = Vec::new();
    for t in &mesh.triangles {
        let p = t.map(|i| mesh.positions[i as usize]);
        let c = [0, 1, 2].map(|a| (p[0][a] + p[1][a] + p[2][a]) / 3.0);
        if !keep(c) {
            continue;
        }
        let nt = t.map(|i| {
            let i = i as usize;
            if used[i] == u32::MAX {
                used[i] = keys.len() as u32;
                keys.push(mesh.keys[i]);
                positions.push(mesh.positions[i]);
                if let Some(c) = mesh.colors.get(i) {
                    colors.push(*c);
                }
                if let Some(v) = mesh.intensity.get(i) {
                    intensity.push(*v);
                }
            }
            used[i]
        });
        tris.push(nt);
    }
    mesh.triangles = tris;
    mesh.keys = keys;
    mesh.positions = positions;
    mesh.colors = colors;
    mesh.intensity = intensity;
}

/// Refuse point sets that span no volume: a plane or a line has no inside.
fn check_not_flat(store: &Store, m: &[f64; 10]) -> Result<()> {
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
            &store.dir,
            "all points lie on a line: a surface needs points spread in three dimensions",
        ));
    }
    if ev[0] <= 1e-12 * top {
        return Err(Error::input(
            &store.dir,
            "all points lie on a plane: a closed surface needs points spread in three dimensions",
        ));
    }
    Ok(())
}

/// Leaves whose detail support (cell plus overlap) meets fine nodes `lo..=hi`.
fn leaves_near(
    plan: &Plan,
    leaves: &BTreeSet<CellKey>,
    lo: [i64; 3],
    hi: [i64; 3],
) -> Vec<CellKey> {
    let e = plan.e as i64;
    let ov = plan.ov as i64;
    let side = (plan.n / plan.e) as i64;
    let c0 = lo.map(|v| ((v - ov - e).div_euclid(e) + 1).max(0));
    let c1 = hi.map(|v| ((v + ov).div_euclid(e)).min(side - 1));
    let mut out = Vec::new();
    for z in c0[2]..=c1[2] {
        for y in c0[1]..=c1[1] {
            for x in c0[0]..=c1[0] {
                let k = CellKey::new(plan.leaf_level, [x as u32, y as u32, z as u32]);
                if leaves.contains(&k) {
                    out.push(k);
                }
            }
        }
    }
    out.sort();
    out
}

/// A tile's `(T+1)³` nodes from fine node `lo` as a blend ([`Blend`]) of the coarse solution
/// and the leaf details `details` (fixed point in `unit`), with per-axis leaf weights `own`
/// ([`pou::leaf_weights`]). [`Blend::eval`] or the GPU evaluates it.
fn tile_blend<'a>(
    plan: &Plan,
    own: &[i32],
    coarse: &CoarseField,
    unit: f32,
    lo: [i64; 3],
    details: &'a [(CellKey, Arc<Detail>)],
) -> Blend<'a> {
    let dims = [(plan.tile + 1) as usize; 3];
    let (cvals, coarse_dims, axes) = coarse.block(lo, dims, unit);
    Blend {
        lo,
        dims,
        axes,
        coarse: cvals,
        coarse_dims,
        coarse_bits: plan.r.trailing_zeros(),
        e: plan.e as i64,
        ov: plan.ov as i64,
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
    }
}

/// What the GPU did over a run, for the log.
#[derive(Debug, Default)]
struct GpuTotals {
    tiles: u64,
    on_device: u64,
    fell_back: u64,
    leaves_sent: u64,
    bytes: u64,
    secs: f64,
}

impl GpuTotals {
    fn add(&mut self, s: &crate::extract::GpuStats) {
        self.tiles += 1;
        self.on_device += s.field_on_gpu as u64;
        self.fell_back += s.fell_back as u64;
        self.leaves_sent += s.leaves_sent;
        self.bytes += s.upload_bytes;
        self.secs += s.upload_secs + s.kernel_secs + s.download_secs + s.host_secs;
    }

    fn log(&self) {
        log::info!(
            "GPU: {} tiles in {:.2} s, {} with the field built on the device, {} on the CPU \
             after a GPU failure; {} leaf grids and {:.1} MB sent",
            self.tiles,
            self.secs,
            self.on_device,
            self.fell_back,
            self.leaves_sent,
            self.bytes as f64 / 1e6
        );
    }
}

/// Leaf details read back from the work directory, cached up to a byte cap.
struct DetailCache {
    dir: PathBuf,
    m: usize,
    map: HashMap<CellKey, Arc<Detail>>,
    lru: VecDeque<CellKey>,
    cap_entries: usize,
    max_entries: usize,
}

impl DetailCache {
    fn new(dir: &Path, m: usize, cap_bytes: u64) -> DetailCache {
        // 16-bit details (`quantise_detail`).
        let per = (m * m * m * 2) as u64;
        DetailCache {
            dir: dir.to_path_buf(),
            m,
            map: HashMap::new(),
            lru: VecDeque::new(),
            cap_entries: ((cap_bytes / per.max(1)) as usize).max(64),
            max_entries: ((cap_bytes / per.max(1)) as usize).max(64),
        }
    }

    /// Keep at most `want` entries (at least 64, at most the byte cap allows).
    fn fit(&mut self, want: usize) {
        self.cap_entries = want.clamp(64, self.max_entries);
        self.evict();
    }

    fn evict(&mut self) {
        self.evict_to(self.cap_entries);
    }

    /// Drop the least recently used entries until at most `keep` remain.
    fn evict_to(&mut self, keep: usize) {
        while self.lru.len() > keep {
            if let Some(old) = self.lru.pop_front() {
                self.map.remove(&old);
            }
        }
    }

    /// Make the details of `keys` resident: those cached become the most recently used, the
    /// others are read in parallel on `pool` (as many as the cache holds), after evicting the
    /// least recently used to make room. Only speed depends on this.
    fn prefetch(&mut self, keys: &[CellKey], pool: &rayon::ThreadPool) -> Result<()> {
        let mut seen = std::collections::HashSet::new();
        let mut missing = Vec::new();
        for &k in keys {
            if !seen.insert(k) {
                continue;
            }
            if self.map.contains_key(&k) {
                if let Some(at) = self.lru.iter().position(|&j| j == k) {
                    self.lru.remove(at);
                }
                self.lru.push_back(k);
            } else if missing.len() < self.cap_entries {
                missing.push(k);
            }
        }
        self.evict_to(self.cap_entries - missing.len());
        let (dir, m) = (&self.dir, self.m);
        let loaded: Vec<Result<Detail>> = pool.install(|| {
            missing
                .par_iter()
                .map(|&k| leaf_detail(dir, k, m))
                .collect()
        });
        for (k, d) in missing.into_iter().zip(loaded) {
            self.map.insert(k, Arc::new(d?));
            self.lru.push_back(k);
        }
        Ok(())
    }

    /// Leaf `k`'s detail in fixed point.
    fn get(&mut self, k: CellKey) -> Result<Arc<Detail>> {
        if let Some(d) = self.map.get(&k) {
            return Ok(Arc::clone(d));
        }
        let d = Arc::new(leaf_detail(&self.dir, k, self.m)?);
        self.map.insert(k, Arc::clone(&d));
        self.lru.push_back(k);
        self.evict();
        Ok(d)
    }
}

/// One global FFT solve over the whole cube at `depth`, extracted as a single tile: the
/// reference the two-level adaptive solve is measured against at depths where `(2^depth)³`
/// nodes fit in memory (`notes/adfft.md`). The periodic grid is padded by an eighth of the cube
/// on each side, as the coarse solve is.
pub fn global_solve(
    pos: &[[f64; 3]],
    nrm: &[[f32; 3]],
    cube: &Cube,
    depth: u32,
    sigma_vox: f64,
) -> Result<TileMesh> {
    let n = 1usize << depth;
    let pad = (n / 8).max(2);
    let h = cube.size / n as f64;
    let grid = LocalGrid {
        n: n + 2 * pad,
        h,
        origin: cube.origin.map(|o| o - pad as f64 * h),
    };
    let f = fft_solve::solve(&grid, pos, nrm, sigma_vox);
    let iso = pos.iter().map(|p| grid.eval(&f, *p)).sum::<f64>() / pos.len().max(1) as f64;
    let m = n + 1;
    let mut block = Vec::with_capacity(m * m * m);
    for z in 0..m {
        for y in 0..m {
            for x in 0..m {
                block.push(f[((z + pad) * grid.n + y + pad) * grid.n + x + pad]);
            }
        }
    }
    let geom = GridGeom {
        origin: cube.origin,
        h,
        n: n as u64,
    };
    let mut mesh = TileMesh::default();
    marching_cubes(&block, [m; 3], [0; 3], iso as f32, &geom, &mut mesh)?;
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leaf_checkpoints_round_trip_and_bad_ones_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let m = 5;
        let key = CellKey::new(3, [1, 2, 3]);
        let raw: Vec<f32> = (0..m * m * m).map(|i| (i as f32 - 60.0) * 0.37).collect();
        let refined = LeafDetail {
            detail: Some(quantise_detail(&raw, 1.0 / 64.0)),
            iso_sum: -12.5,
            iso_count: 7,
        };
        write_leaf(dir.path(), key, &refined).unwrap();
        let back = read_leaf(dir.path(), key, m).unwrap();
        assert_eq!(back.detail, refined.detail);
        assert_eq!((back.iso_sum, back.iso_count), (-12.5, 7));
        assert_eq!(
            leaf_detail(dir.path(), key, m).unwrap(),
            refined.detail.unwrap()
        );
        // A leaf left to the coarse solution: no detail, which the tile stage must not read.
        let plain = CellKey::new(3, [0, 0, 0]);
        let coarse = LeafDetail {
            detail: None,
            iso_sum: 1.0,
            iso_count: 2,
        };
        write_leaf(dir.path(), plain, &coarse).unwrap();
        assert!(read_leaf(dir.path(), plain, m).unwrap().detail.is_none());
        let e = leaf_detail(dir.path(), plain, m).unwrap_err().to_string();
        assert!(e.contains("without a detail") && e.contains(".zst"), "{e}");
        // Bad files: another grid size, another cell, an older format, garbage.
        let e = read_leaf(dir.path(), key, m + 1).unwrap_err().to_string();
        assert!(
            e.contains("corrupt leaf checkpoint") && e.contains("expected"),
            "{e}"
        );
        std::fs::copy(leaf_path(dir.path(), key), leaf_path(dir.path(), plain)).unwrap();
        let e = read_leaf(dir.path(), plain, m).unwrap_err().to_string();
        assert!(e.contains("another cell"), "{e}");
        let mut old = b"SFLEAF01".to_vec();
        old.extend_from_slice(&[0; 24]);
        std::fs::write(
            leaf_path(dir.path(), key),
            zstd::bulk::compress(&old, 1).unwrap(),
        )
        .unwrap();
        let e = read_leaf(dir.path(), key, m).unwrap_err().to_string();
        assert!(
            e.contains("another version of scanflow") && e.contains("SFLEAF01"),
            "{e}"
        );
        std::fs::write(leaf_path(dir.path(), key), b"not zstd").unwrap();
        let e = read_leaf(dir.path(), key, m).unwrap_err().to_string();
        assert!(e.contains("corrupt leaf checkpoint"), "{e}");
    }

    #[test]
    fn point_grid_finds_the_exact_nearest_points() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        for (n, spread) in [
            (0usize, 1.0),
            (1, 1.0),
            (30, 1.0),
            (3000, 1.0),
            (3000, 0.01),
        ] {
            // Clustered and spread points, some repeated.
            let mut pos: Vec<[f64; 3]> = (0..n)
                .map(|_| [0, 1, 2].map(|_| rng.random_range(0.0..spread)))
                .collect();
            if n > 10 {
                pos[3] = pos[2];
            }
            let (lo, hi) = ([0.0; 3], [spread; 3]);
            for s in [0.001, 0.05, 0.3] {
                let g = PointGrid::new(&pos, lo, hi, s);
                let mut out = Vec::new();
                for _ in 0..200 {
                    let q = [0, 1, 2].map(|_| rng.random_range(-0.2 * spread..1.2 * spread));
                    for k in [1, 6, 22] {
                        g.nearest(q, k, &mut out);
                        let mut all: Vec<(f64, u32)> = pos
                            .iter()
                            .enumerate()
                            .map(|(i, p)| {
                                let d2 = (0..3).map(|a| (p[a] - q[a]).powi(2)).sum::<f64>();
                                (d2, i as u32)
                            })
                            .collect();
                        all.sort_by(|a, b| a.partial_cmp(b).unwrap());
                        all.truncate(k);
                        let dist = |v: &[(f64, u32)]| v.iter().map(|x| x.0).collect::<Vec<_>>();
                        assert_eq!(dist(&out), dist(&all), "n {n} s {s} k {k}");
                    }
                }
            }
        }
    }

    #[test]
    fn projection_follows_precise_points_and_ignores_noise() {
        let h = 0.01;
        // Precise points on z = 0: a vertex 0.3 voxel above moves onto the plane.
        let mut nb: Vec<(f64, [f64; 3], [u16; 3], f32)> = Vec::new();
        for i in 0..5 {
            for j in 0..4 {
                let p = [i as f64 * 0.004 - 0.008, j as f64 * 0.004 - 0.006, 0.0];
                nb.push((p[0] * p[0] + p[1] * p[1], p, [0; 3], 0.0));
            }
        }
        nb.sort_by(|a, b| a.0.total_cmp(&b.0));
        let v = project([0.0, 0.0, 0.003], &nb, h);
        assert!(v[2].abs() < 1e-9, "{v:?}");
        // Too far from every point (more than two voxels): left alone.
        let far: Vec<_> = nb.iter().map(|x| (x.0 + 1.0, x.1, x.2, x.3)).collect();
        assert_eq!(project([0.0, 0.0, 0.003], &far, h), [0.0, 0.0, 0.003]);
        // Noisy points: an offset within the plane's error is not followed.
        let noisy: Vec<_> = nb
            .iter()
            .enumerate()
            .map(|(i, x)| {
                let z = if i % 2 == 0 { 0.004 } else { -0.004 };
                (x.0, [x.1[0], x.1[1], z], x.2, x.3)
            })
            .collect();
        let v = project([0.0, 0.0, 0.0015], &noisy, h);
        assert!(v[2] > 0.0015 * 0.5, "{v:?}");
    }
}
