//! The input points as the reconstruction reads them: store cells decoded and sorted by leaf
//! cell, through one byte-bounded cache, handed to the leaf solves ([`LeafPoints`]) and to the
//! vertex fit ([`NearPoints`]).

use std::collections::{HashMap, HashSet};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use rayon::prelude::*;

use crate::error::Result;
use crate::exec::Ctx;
use crate::exec::budget::Permit;
use crate::exec::cache::Lru;
use crate::recon::density::DensityGrid;
use crate::recon::leaf::LEAF_POINT_BYTES;
use crate::recon::plan::LEAF_REACH;
use crate::recon::voxel_sum::{SUM_MIN_POINTS_PER_VOXEL, VOXEL_SUM_BYTES, VoxelSum, sum_voxels};
use crate::recon::{LeafPoints, Plan};
use crate::store::Store;
use crate::surface::NearPoints;
use crate::types::{Aabb, CellKey, Cube, PointBatch};

/// Bytes a sorted point holds: position f64×3 (24) and normal f32×3 (12), as in a leaf's
/// points.
pub const SORTED_POINT_BYTES: u64 = LEAF_POINT_BYTES;
/// Bytes a sorted point's colour holds: RGBA u16×4.
const SORTED_COLOUR_BYTES: u64 = 8;
/// Bytes a sorted point's intensity holds: f32.
const SORTED_INTENSITY_BYTES: u64 = 4;
/// Bytes of a leaf range of a sorted cell: key u64 and two usize bounds.
const SORTED_RANGE_BYTES: u64 = 24;
/// Times [`PointSource::near_points_wave`] doubles its margin while it finds no point.
const NEAR_POINTS_WIDENINGS: usize = 6;

/// A store cell's points sorted by leaf cell; or, for a level above the finest where the
/// cell is dense, its points summed per voxel of the level's lattice ([`VoxelSum`]), sorted by
/// leaf cell.
struct SortedCell {
    pos: Vec<[f64; 3]>,
    nrm: Vec<[f32; 3]>,
    col: Vec<[u16; 4]>,
    inten: Vec<f32>,
    voxels: Vec<VoxelSum>,
    /// Per leaf cell, its range of `pos` (or of `voxels`, where they are not empty).
    ranges: Vec<(CellKey, usize, usize)>,
}

impl SortedCell {
    fn new(b: PointBatch, cube: &Cube, leaf_level: u32) -> SortedCell {
        let keys: Vec<CellKey> = b
            .pos
            .iter()
            .map(|p| CellKey::new(leaf_level, cube.cell_coords(*p, leaf_level)))
            .collect();
        let (order, ranges) = bucket_by_key(&keys);
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
        SortedCell {
            pos,
            nrm,
            col,
            inten,
            voxels: Vec::new(),
            ranges,
        }
    }

    /// The points of `b` summed per voxel of `cube`'s lattice at `depth`, where they are at
    /// least [`SUM_MIN_POINTS_PER_VOXEL`] a voxel; otherwise sorted as [`SortedCell::new`].
    fn summed(b: PointBatch, cube: &Cube, depth: u32, leaf_level: u32) -> SortedCell {
        let vox: Vec<[u32; 3]> = b.pos.iter().map(|p| cube.cell_coords(*p, depth)).collect();
        // The leaf holding a voxel, from the voxel itself: a voxel lies in one leaf.
        let shift = depth - leaf_level;
        let leaf = |v: [u32; 3]| CellKey::new(leaf_level, v.map(|c| c >> shift));
        // By leaf, then voxel (z, y, x; 21 bits each at the supported depths), then input
        // order: the index sorted with its key, not through it (whose scattered reads made
        // the sort most of a level's read).
        let mut keyed: Vec<(CellKey, u64, u32)> = vox
            .iter()
            .zip(0..)
            .map(|(v, i)| {
                let packed = ((v[2] as u64) << 42) | ((v[1] as u64) << 21) | v[0] as u64;
                (leaf(*v), packed, i)
            })
            .collect();
        keyed.sort_unstable();
        let order: Vec<u32> = keyed.into_iter().map(|k| k.2).collect();
        let distinct = 1 + order
            .windows(2)
            .filter(|w| vox[w[0] as usize] != vox[w[1] as usize])
            .count();
        if b.is_empty() || b.len() < SUM_MIN_POINTS_PER_VOXEL * distinct {
            return SortedCell::new(b, cube, leaf_level);
        }
        let pos: Vec<[f64; 3]> = order.iter().map(|&i| b.pos[i as usize]).collect();
        let nrm: Vec<[f32; 3]> = order.iter().map(|&i| b.normal[i as usize]).collect();
        let vs: Vec<[u32; 3]> = order.iter().map(|&i| vox[i as usize]).collect();
        let voxels = sum_voxels(&pos, &nrm, &vs, cube, depth);
        let ranges = runs(voxels.len(), |j| leaf(voxels[j].at.map(|c| c as u32)));
        SortedCell {
            pos: Vec::new(),
            nrm: Vec::new(),
            col: Vec::new(),
            inten: Vec::new(),
            voxels,
            ranges,
        }
    }

    fn bytes(&self) -> u64 {
        self.pos.len() as u64 * SORTED_POINT_BYTES
            + self.voxels.len() as u64 * VOXEL_SUM_BYTES
            + self.col.len() as u64 * SORTED_COLOUR_BYTES
            + self.inten.len() as u64 * SORTED_INTENSITY_BYTES
            + self.ranges.len() as u64 * SORTED_RANGE_BYTES
    }

    fn range(&self, k: CellKey) -> (usize, usize) {
        match self.ranges.binary_search_by_key(&k, |r| r.0) {
            Ok(i) => (self.ranges[i].1, self.ranges[i].2),
            Err(_) => (0, 0),
        }
    }

    /// The indices in `pos` of leaf cell `k`'s points (none in a summed cell).
    fn points_of(&self, k: CellKey) -> std::ops::Range<usize> {
        let (s, e) = self.range(k);
        if self.voxels.is_empty() { s..e } else { 0..0 }
    }

    /// Leaf cell `k`'s voxel sums (none in a cell of points).
    fn voxels_of(&self, k: CellKey) -> &[VoxelSum] {
        let (s, e) = self.range(k);
        &self.voxels[s.min(self.voxels.len())..e.min(self.voxels.len())]
    }
}

/// The order that sorts `keys` by key, equal keys in input order, and each key's range in
/// it: a counting sort over the distinct keys, which are few (the leaf cells a store cell
/// overlaps). The comparison sort it replaces, through an index, was a twentieth of the tile
/// stage's time at 100M points.
fn bucket_by_key(keys: &[CellKey]) -> (Vec<u32>, Vec<(CellKey, usize, usize)>) {
    // Points come in runs of one leaf: the runs' keys, sorted and deduplicated.
    let mut distinct: Vec<CellKey> = Vec::new();
    for &k in keys {
        if distinct.last() != Some(&k) {
            distinct.push(k);
        }
    }
    distinct.sort_unstable();
    distinct.dedup();
    let mut bucket = Vec::with_capacity(keys.len());
    let mut last: Option<(CellKey, usize)> = None;
    let mut start = vec![0usize; distinct.len() + 1];
    for &k in keys {
        let b = match last {
            Some((lk, lb)) if lk == k => lb,
            // Every key is among the distinct ones.
            _ => distinct.binary_search(&k).unwrap_or_else(|at| at),
        };
        last = Some((k, b));
        bucket.push(b as u32);
        start[b + 1] += 1;
    }
    for i in 1..start.len() {
        start[i] += start[i - 1];
    }
    let ranges = distinct
        .iter()
        .enumerate()
        .map(|(b, &k)| (k, start[b], start[b + 1]))
        .collect();
    let mut order = vec![0u32; keys.len()];
    for (i, &b) in bucket.iter().enumerate() {
        order[start[b as usize]] = i as u32;
        start[b as usize] += 1;
    }
    (order, ranges)
}

/// The runs of equal keys among `len` sorted items (`key(j)` of item `j`): each key with its
/// range.
fn runs(len: usize, key: impl Fn(usize) -> CellKey) -> Vec<(CellKey, usize, usize)> {
    let mut ranges = Vec::new();
    let mut s = 0;
    for j in 0..len {
        let k = key(j);
        if j + 1 == len || key(j + 1) != k {
            ranges.push((k, s, j + 1));
            s = j + 1;
        }
    }
    ranges
}

/// Points of the store by leaf cell, through a cache of decoded store cells bounded in bytes.
pub struct PointSource<'a> {
    store: &'a Store,
    plan: Plan,
    by_key: HashMap<CellKey, usize>,
    deeper: HashMap<CellKey, Vec<usize>>,
    cache: Lru<usize, Arc<SortedCell>>,
    cap: u64,
    /// The samples' shares of the surface, which weigh their normals.
    density: Arc<DensityGrid>,
    /// Dense store cells are read summed per voxel of the plan's lattice
    /// ([`PointSource::summing`]).
    summing: bool,
    /// Cells loaded weigh their normals ([`PointSource::for_positions`] turns it off).
    weigh: bool,
    /// Store cells read so far, and their points, for the log.
    reads: AtomicU64,
    points_read: AtomicU64,
    /// Of those, the cells read one at a time by a loading read, not by a preload, and the
    /// nanoseconds those reads took.
    serial_reads: AtomicU64,
    serial_nanos: AtomicU64,
}

impl<'a> PointSource<'a> {
    /// The points of `store` by `plan`'s leaf cells, caching up to `cap` bytes of sorted cells;
    /// their normals weighed by confidence and by `density`
    /// ([`weigh_normals`](super::reconstruct::weigh_normals)).
    pub fn new(
        store: &'a Store,
        plan: Plan,
        cap: u64,
        density: Arc<DensityGrid>,
    ) -> PointSource<'a> {
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
            cache: Lru::new(cap),
            cap,
            density,
            summing: false,
            weigh: true,
            reads: AtomicU64::new(0),
            points_read: AtomicU64::new(0),
            serial_reads: AtomicU64::new(0),
            serial_nanos: AtomicU64::new(0),
        }
    }

    /// Store cells read from the store so far (each read again after the cache let it go).
    fn cell_reads(&self) -> CellReads {
        CellReads {
            cells: self.reads.load(Ordering::Relaxed),
            points: self.points_read.load(Ordering::Relaxed),
            serial: self.serial_reads.load(Ordering::Relaxed),
            serial_s: self.serial_nanos.load(Ordering::Relaxed) as f64 * 1e-9,
        }
    }

    /// Log what stage `name` read since `before` ([`PointSource::cell_reads`]).
    fn log_reads(&self, name: &str, before: CellReads) {
        let now = self.cell_reads();
        log::info!(
            "{name}: {} store cells read ({} points; {} of the cells one at a time, {:.2} s) \
             through a cache of {} MiB",
            now.cells - before.cells,
            now.points - before.points,
            now.serial - before.serial,
            now.serial_s - before.serial_s,
            self.cap >> 20
        );
    }

    /// Set the cache's cap to `cap` bytes, letting the least recently used cells go where
    /// it shrinks. Only speed depends on it, never the points read.
    fn set_cache_cap(&mut self, cap: u64) {
        self.cap = cap;
        self.cache.set_capacity(cap);
    }

    /// Start a pass (a level's leaves, or the tiles) that keeps `reserve` bytes of the budget
    /// for its own waves: the reads so far, for [`PointSource::end_pass`]'s log line, and the
    /// cache grown for the pass ([`PointSource::grow_cache`]).
    pub fn begin_pass(&mut self, reserve: u64, ctx: &Ctx) -> Pass {
        Pass {
            before: self.cell_reads(),
            growth: self.grow_cache(reserve, ctx),
        }
    }

    /// End `pass`: log what stage `name` read during it, then give back the cache's growth
    /// (the cap it found, the least recently used cells let go).
    pub fn end_pass(&mut self, pass: Pass, name: &str) {
        self.log_reads(name, pass.before);
        if let Some((cap, _permit)) = pass.growth {
            self.set_cache_cap(cap);
        }
    }

    /// Grow the cache for one pass out of what the budget has free beyond `reserve` (the
    /// pass's own waves), twice the cache (a wave's points copied out of it) and a store cell
    /// being read by each worker, as far as every store cell at once; a growth under a
    /// quarter of the cap is not taken. Only speed depends on it: a pass in Morton order
    /// meets a store cell again as the boxes of leaves or tiles on the far side of an octant
    /// boundary reach into it, and a cache that lets it go in between reads it again.
    /// (Growing to 32 MiB a worker was too little: on 2 cores a 100M-point sphere's 272 store
    /// cells of 18 MB were read 9 times by the finest leaves and 15 times by the tiles
    /// through 128 MiB, half the run's time.) Returns the cap to restore and the permit
    /// holding the growth.
    fn grow_cache(&mut self, reserve: u64, ctx: &Ctx) -> Option<(u64, Permit)> {
        let cap = self.cap;
        let cells = self.store.manifest.cells.len();
        let whole: u64 = (0..cells).map(|i| self.cell_estimate(i)).sum();
        let want = whole.saturating_sub(cap);
        // Besides: a cell being read by each worker, decoded beside the sorted copy the cache
        // counts, with its points' leaf keys and order (12 bytes a point).
        let largest = self.store.manifest.cells.iter().map(|c| c.count).max();
        let decoding = ctx.threads() as u64
            * largest.unwrap_or(0)
            * (super::reconstruct::BATCH_POINT_BYTES + 12);
        let free = ctx.budget.total().saturating_sub(ctx.budget.used());
        let room = free.saturating_sub(reserve + 2 * cap + decoding);
        let grow = want.min(room);
        if grow < cap / 4 {
            return None;
        }
        let permit = ctx.budget.try_acquire(grow)?;
        self.set_cache_cap(cap + grow);
        Some((cap, permit))
    }

    /// The same source reading its dense store cells summed per voxel of the plan's lattice
    /// ([`VoxelSum`]): for the leaves of a level above the finest, which need neither single
    /// points nor their colours.
    pub fn summing(self) -> PointSource<'a> {
        PointSource {
            summing: true,
            ..self
        }
    }

    /// The same source for readers of positions, colours and intensities only (the tiles'
    /// vertex fit): cells loaded from here on keep their normals as stored, unweighed. The
    /// weights were a sixteenth of the tile stage's time (100M points at depth 11), for
    /// normals nobody read.
    pub fn for_positions(self) -> PointSource<'a> {
        PointSource {
            weigh: false,
            ..self
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
            return Ok(Arc::clone(c));
        }
        let t = Instant::now();
        let c = Arc::new(self.load(i)?);
        self.serial_reads.fetch_add(1, Ordering::Relaxed);
        self.serial_nanos
            .fetch_add(t.elapsed().as_nanos() as u64, Ordering::Relaxed);
        self.insert(i, Arc::clone(&c));
        Ok(c)
    }

    fn load(&self, i: usize) -> Result<SortedCell> {
        let mut b = self.store.read_cell(i)?;
        self.reads.fetch_add(1, Ordering::Relaxed);
        self.points_read
            .fetch_add(b.len() as u64, Ordering::Relaxed);
        if self.weigh {
            super::reconstruct::weigh_normals(&mut b, self.plan.confidence, &self.density);
        }
        let (cube, depth, leaf) = (&self.plan.cube, self.plan.depth, self.plan.leaf_level);
        Ok(if self.summing {
            SortedCell::summed(b, cube, depth, leaf)
        } else {
            SortedCell::new(b, cube, leaf)
        })
    }

    fn insert(&mut self, i: usize, c: Arc<SortedCell>) {
        let bytes = c.bytes();
        self.cache.insert(i, c, bytes);
    }

    /// Read and sort the store cells `wanted` that are not cached yet, in parallel on `pool`
    /// (decompression is most of a cell's cost), as many as half the cache holds; the rest
    /// are read when asked for. The least recently used cells are evicted first to make room,
    /// so the cache and the cells being read stay within its cap. Only speed depends on this,
    /// never the points returned.
    fn preload(&mut self, wanted: &[usize], pool: &rayon::ThreadPool) -> Result<()> {
        let mut seen = HashSet::new();
        let mut missing = Vec::new();
        let mut est = 0u64;
        for &i in wanted {
            if self.cache.touch(&i) || !seen.insert(i) {
                continue;
            }
            est += self.cell_estimate(i);
            if est > self.cap / 2 {
                break;
            }
            missing.push(i);
        }
        let est: u64 = missing.iter().map(|&i| self.cell_estimate(i)).sum();
        while !missing.is_empty() && self.cache.bytes() + est > self.cap {
            if self.cache.pop_oldest().is_none() {
                break;
            }
        }
        let loaded: Vec<Result<SortedCell>> =
            pool.install(|| missing.par_iter().map(|&i| self.load(i)).collect());
        for (i, c) in missing.into_iter().zip(loaded) {
            self.insert(i, Arc::new(c?));
        }
        Ok(())
    }

    /// [`SortedCell::bytes`] of store cell `i`'s points without colours: what
    /// [`PointSource::preload`] plans with.
    fn cell_estimate(&self, i: usize) -> u64 {
        self.store.manifest.cells[i].count * SORTED_POINT_BYTES
    }

    /// The end of the run of `items` from `start` whose cells (`cells` of each) not cached
    /// yet fit what [`PointSource::preload`] reads at once, half the cache; a run holds at
    /// least one item. With it, the run's cells, item after item (repeats kept).
    fn run_end<I>(
        &self,
        items: &[I],
        start: usize,
        cells: impl Fn(&Self, &I) -> Vec<usize>,
    ) -> (usize, Vec<usize>) {
        let mut seen = HashSet::new();
        let mut est = 0u64;
        let mut wanted = Vec::new();
        for (n, item) in items.iter().enumerate().skip(start) {
            let mine = cells(self, item);
            for &i in &mine {
                if !self.cache.contains(&i) && seen.insert(i) {
                    est += self.cell_estimate(i);
                }
            }
            if n > start && est > self.cap / 2 {
                return (n, wanted);
            }
            wanted.extend(mine);
        }
        (items.len(), wanted)
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

    /// The store cells [`PointSource::near_points_wave`] reads first for the box `lo..hi` and
    /// `margin`.
    fn cells_near(&self, lo: [f64; 3], hi: [f64; 3], margin: f64) -> Vec<usize> {
        let bx = Aabb { min: lo, max: hi }.grown(margin);
        self.keys_in(&bx)
            .into_iter()
            .flat_map(|k| self.covering(k))
            .collect()
    }

    /// The store cells [`PointSource::gather_wave`] reads for leaf `key`.
    fn cells_for_leaf(&self, key: CellKey) -> Vec<usize> {
        Self::neighbours(key)
            .into_iter()
            .flat_map(|k| self.covering(k))
            .collect()
    }

    /// For each box `(lo, hi, margin)` of a wave, the points (with their colours, when the
    /// store has them) within `margin` of the box `lo..hi` (world), widening the margin
    /// (doubling, up to 6 times) while none is found; read by the workers of `pool`
    /// ([`PointSource::read_wave`]).
    pub fn near_points_wave(
        &mut self,
        pool: &rayon::ThreadPool,
        boxes: &[([f64; 3], [f64; 3], f64)],
    ) -> Result<Vec<NearPoints>> {
        self.read_wave(
            pool,
            boxes,
            |src, &(lo, hi, margin)| src.cells_near(lo, hi, margin),
            |acc, &(lo, hi, margin)| acc.near_points(lo, hi, margin),
        )
    }

    /// The points (with their colours) within Euclidean distance `reach` of the box `lo..hi`
    /// (world): the ball around each point of the box, not the box grown by `reach` along
    /// every axis. For vertices far below a terrain (a closed surface's underside) the grown
    /// box holds a square of ground as wide as their distance to it, and the rounded one only
    /// the patch their nearest points can come from.
    pub fn points_within(&mut self, lo: [f64; 3], hi: [f64; 3], reach: f64) -> Result<NearPoints> {
        let mut out = NearPoints::default();
        let inner = Aabb { min: lo, max: hi };
        let bx = inner.grown(reach);
        let r2 = reach * reach;
        let mut acc = Access::Load(self);
        for k in acc.src().keys_in(&bx) {
            acc.visit(k, &bx, |sc, j| {
                if inner.dist2(sc.pos[j]) <= r2 {
                    take(&mut out, sc, j);
                }
            })?;
        }
        out.lo = bx.min;
        out.hi = bx.max;
        Ok(out)
    }

    /// For each leaf `key` of a wave, the points of its 1.3125× box ([`LEAF_REACH`]), and how
    /// many of them (the first ones) lie in the cell itself; read by the workers of `pool`
    /// ([`PointSource::read_wave`]).
    pub fn gather_wave(
        &mut self,
        pool: &rayon::ThreadPool,
        keys: &[CellKey],
    ) -> Result<Vec<LeafPoints>> {
        self.read_wave(
            pool,
            keys,
            |src, &key| src.cells_for_leaf(key),
            |acc, &key| acc.gather(key),
        )
    }

    /// `read` of every item of a wave, in runs of consecutive items whose cells (`cells` of
    /// each) fit half the cache: a run's cells read in parallel ([`PointSource::preload`]),
    /// then its items read on `pool` from the cache alone, then, in order, loading the cells
    /// for the items whose cells the preload left out (a single item over half the cache, or
    /// a margin widened past them). Both read the same cells in the same order: the results
    /// of reading each item in turn. (One preload for a whole wave left most of a wave's cells
    /// to the serial reads on 16 cores: a 100M-point sphere's leaves read 3× slower than on
    /// 2.)
    fn read_wave<I: Sync, T: Send>(
        &mut self,
        pool: &rayon::ThreadPool,
        items: &[I],
        cells: impl Fn(&Self, &I) -> Vec<usize>,
        read: impl Fn(&mut Access<'_, 'a>, &I) -> Result<Option<T>> + Sync,
    ) -> Result<Vec<T>> {
        let mut out = Vec::with_capacity(items.len());
        let mut start = 0;
        while start < items.len() {
            let (end, wanted) = self.run_end(items, start, &cells);
            let run = &items[start..end];
            self.preload(&wanted, pool)?;
            let cached: Vec<Result<Option<T>>> = {
                let shared: &PointSource<'a> = self;
                pool.install(|| {
                    run.par_iter()
                        .map(|item| read(&mut Access::Cached(shared), item))
                        .collect()
                })
            };
            for (item, got) in run.iter().zip(cached) {
                out.push(match got? {
                    Some(t) => t,
                    None => read(&mut Access::Load(self), item)?
                        .expect("a loading read finds every cell"),
                });
            }
            start = end;
        }
        Ok(out)
    }
}

/// A pass over a [`PointSource`] ([`PointSource::begin_pass`]): the reads before it, and
/// the cache's growth for it (the cap to restore, and the budget it holds until then).
pub struct Pass {
    before: CellReads,
    growth: Option<(u64, Permit)>,
}

/// Counts of a [`PointSource`]'s reads of store cells, for the log.
#[derive(Clone, Copy, Debug)]
struct CellReads {
    /// Store cells read (a cell the cache let go is read again).
    cells: u64,
    /// Their points.
    points: u64,
    /// Of the cells, those read one at a time by a loading read, not by a parallel preload.
    serial: u64,
    /// The seconds those took.
    serial_s: f64,
}

/// How a read reaches the store cells: loading what the cache lacks (and caching it), or
/// from the cache alone, so that workers can read at once after a wave's
/// [`PointSource::preload`]. Both visit the same cells in the same order: the same points.
enum Access<'s, 'a> {
    Load(&'s mut PointSource<'a>),
    Cached(&'s PointSource<'a>),
}

impl<'a> Access<'_, 'a> {
    fn src(&self) -> &PointSource<'a> {
        match self {
            Access::Load(s) => s,
            Access::Cached(s) => s,
        }
    }

    /// Store cell `i`, or `None` where it is not cached and this read does not load.
    fn cell(&mut self, i: usize) -> Result<Option<Arc<SortedCell>>> {
        match self {
            Access::Load(s) => s.cell(i).map(Some),
            Access::Cached(s) => Ok(s.cache.peek(&i).cloned()),
        }
    }

    /// Call `f(cell, j)` for each point `j` of leaf-level cell `k` that lies in `bx`, in the
    /// store's order (a summed cell's are visited by [`Access::visit_voxels`]). `false`
    /// where a cell was not at hand.
    fn visit(
        &mut self,
        k: CellKey,
        bx: &Aabb,
        mut f: impl FnMut(&SortedCell, usize),
    ) -> Result<bool> {
        for si in self.src().covering(k) {
            let Some(sc) = self.cell(si)? else {
                return Ok(false);
            };
            for j in sc.points_of(k) {
                if bx.contains(sc.pos[j]) {
                    f(&sc, j);
                }
            }
        }
        Ok(true)
    }

    /// Call `f(sum)` for each voxel sum of leaf-level cell `k` (in its summed store cells)
    /// whose voxel lies in `bx`, a box whose faces are on the plan's lattice: a voxel lies in
    /// it or out of it, and its centre says which. `false` where a cell was not at hand.
    fn visit_voxels(
        &mut self,
        k: CellKey,
        bx: &Aabb,
        mut f: impl FnMut(&VoxelSum),
    ) -> Result<bool> {
        let (origin, h) = (self.src().plan.cube.origin, self.src().plan.spacing);
        for si in self.src().covering(k) {
            let Some(sc) = self.cell(si)? else {
                return Ok(false);
            };
            for v in sc.voxels_of(k) {
                let c = [0, 1, 2].map(|a| origin[a] + (v.at[a] as f64 + 0.5) * h);
                if bx.contains(c) {
                    f(v);
                }
            }
        }
        Ok(true)
    }

    fn near_points(
        &mut self,
        lo: [f64; 3],
        hi: [f64; 3],
        margin: f64,
    ) -> Result<Option<NearPoints>> {
        let mut out = NearPoints::default();
        let mut m = margin;
        for _ in 0..=NEAR_POINTS_WIDENINGS {
            let bx = Aabb { min: lo, max: hi }.grown(m);
            for k in self.src().keys_in(&bx) {
                if !self.visit(k, &bx, |sc, j| take(&mut out, sc, j))? {
                    return Ok(None);
                }
            }
            out.lo = bx.min;
            out.hi = bx.max;
            if !out.pos.is_empty() {
                break;
            }
            m *= 2.0;
        }
        Ok(Some(out))
    }

    fn gather(&mut self, key: CellKey) -> Result<Option<LeafPoints>> {
        let cell_box = self.src().plan.cube.cell_box(key);
        let reach = cell_box.grown(LEAF_REACH * (cell_box.max[0] - cell_box.min[0]));
        let mut own = LeafPoints::default();
        let mut rest = LeafPoints::default();
        for nk in PointSource::neighbours(key) {
            let dst = if nk == key { &mut own } else { &mut rest };
            let found = self.visit(nk, &reach, |sc, j| {
                dst.pos.push(sc.pos[j]);
                dst.nrm.push(sc.nrm[j]);
            })? && self.visit_voxels(nk, &reach, |v| dst.voxels.push(*v))?;
            if !found {
                return Ok(None);
            }
        }
        own.own = own.pos.len();
        own.own_voxels = own.voxels.len();
        own.pos.extend(rest.pos);
        own.nrm.extend(rest.nrm);
        own.voxels.extend(rest.voxels);
        Ok(Some(own))
    }
}

/// Point `j` of `sc`, with its colour and intensity, into `out`.
fn take(out: &mut NearPoints, sc: &SortedCell, j: usize) {
    out.pos.push(sc.pos[j]);
    let c = sc.col.get(j).copied().unwrap_or([0; 4]);
    out.col.push([c[0], c[1], c[2]]);
    out.inten.push(sc.inten.get(j).copied().unwrap_or(0.0));
}

#[cfg(test)]
mod tests;
