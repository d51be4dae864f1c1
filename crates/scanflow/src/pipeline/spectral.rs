//! Spectral processing chained over a store (the [`spectral`](crate::spectral) module docs
//! give the math): pass 1 lays out, fits and treats every cell's patches, wave by wave, and
//! checkpoints them in the work directory (`patches/`); pass 2 visits the cells in Morton order,
//! blends each cell's points (or resamples its patches) from the patches reaching it, and
//! streams the points to the output.
//!
//! Memory: a wave of cells holds their points, halos and patches ([`PASS1_BYTES_PER_POINT`]
//! per point, waves of at most [`Share::NormalsWave`]); decoded cells and patch files are
//! kept in byte-bounded caches ([`Share::NormalsCellCache`] each, at least
//! [`MIN_CACHE_BYTES`]).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use rayon::prelude::*;

use super::workdir::{PATCHES as PATCHES_DIR, RESAMPLED};
use crate::error::{Error, IoContext, Result, Setting};
use crate::exec::Ctx;
use crate::exec::budget::Share;
use crate::exec::cache::Lru;
use crate::fs::atomic::{self, Durability};
use crate::io::mesh_write::VertexFormat;
use crate::io::ply_write::{PointFileOptions, PointPlyWriter};
use crate::spectral::cell::{self, Around, CellPatches, CellPlan};
use crate::spectral::checkpoint;
use crate::spectral::layout::LayoutParams;
use crate::spectral::patch::{Overlap, Patch, PatchWork, Treatment};
use crate::store::Store;
use crate::store::manifest::next_wave;
use crate::types::{Aabb, Attributes, Cube, PointBatch};

/// Bytes held per point of a cell in pass 1: its record decoded (about 64), its halo's share
/// (as many again), the admission index (8), patch membership (8) and the patches' grids
/// (about 2 nodes a point at 8 bytes, counting the overlap).
pub const PASS1_BYTES_PER_POINT: u64 = 64 * 2 + 8 + 8 + 16;

/// Bytes held per point of a cell in pass 2: its record decoded, the blended copy, the
/// heaviest patch, and the patches around it (about 16).
pub const PASS2_BYTES_PER_POINT: u64 = 64 * 2 + 4 + 16;

/// Least capacity of each cache.
pub const MIN_CACHE_BYTES: u64 = 16 << 20;

/// Cells per worker thread in a wave.
const CELLS_PER_THREAD: usize = 2;

/// Options of a spectral run.
#[derive(Debug, Clone)]
pub struct SpectralParams {
    /// Patch layout.
    pub layout: LayoutParams,
    /// Patch overlap.
    pub overlap: Overlap,
    /// The work directory (patch checkpoints go to `patches/` in it).
    pub work_dir: PathBuf,
    /// Reuse the patch checkpoints an earlier run of the same job left.
    pub resume: bool,
}

/// What a run measured.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct SpectralStats {
    /// Points read.
    pub points_in: u64,
    /// Points written.
    pub points_out: u64,
    /// Store cells.
    pub cells: usize,
    /// Patches.
    pub patches: u64,
    /// Smallest, mean and largest patch (members).
    pub patch_members: [f64; 3],
    /// Mean and largest normal-cone aperture, degrees.
    pub aperture_deg: [f64; 2],
    /// Mean and largest RMS approximation error of the height fields, relative to the
    /// bounding-box diagonal.
    pub sda_rms_rel: [f64; 2],
    /// Mean and largest Parseval error (RMS change of a patch's heights), relative to the
    /// diagonal.
    pub parseval_rel: [f64; 2],
    /// Mean estimated noise (Wiener), relative to the diagonal.
    pub noise_rel: f64,
    /// Points whose blended normal took the least-squares fallback.
    pub normal_fallback: u64,
    /// Points no patch admitted (kept as they were).
    pub unblended: u64,
    /// Points in patches too small to approximate.
    pub unpatched: u64,
    /// Patches reused from an earlier run's checkpoints.
    pub resumed_cells: usize,
    /// The bounding-box diagonal.
    pub diagonal: f64,
    /// Seconds in pass 1 (layout, height fields, spectra, filters).
    pub secs_patches: f64,
    /// Of those, seconds in the layout and the patches' frames.
    pub secs_layout: f64,
    /// Seconds in pass 2 (blending or resampling, and writing).
    pub secs_blend: f64,
}

/// Running sums over patches.
#[derive(Default)]
struct Sums {
    n: u64,
    members: [f64; 3],
    aperture: [f64; 2],
    sda: [f64; 2],
    parseval: [f64; 2],
    noise: f64,
}

impl Sums {
    fn add(&mut self, p: &Patch) {
        let m = p.members as f64;
        if self.n == 0 {
            self.members[0] = m;
        }
        self.n += 1;
        self.members = [
            self.members[0].min(m),
            self.members[1] + m,
            self.members[2].max(m),
        ];
        let a = p.aperture as f64;
        self.aperture = [self.aperture[0] + a, self.aperture[1].max(a)];
        let s = p.sda_rms as f64;
        self.sda = [self.sda[0] + s, self.sda[1].max(s)];
        let e = p.parseval_rms as f64;
        self.parseval = [self.parseval[0] + e, self.parseval[1].max(e)];
        self.noise += p.noise_rms as f64;
    }

    fn into_stats(self, st: &mut SpectralStats) {
        let n = self.n.max(1) as f64;
        let d = st.diagonal;
        st.patches = self.n;
        st.patch_members = [self.members[0], self.members[1] / n, self.members[2]];
        st.aperture_deg = [
            self.aperture[0] / n * 180.0 / std::f64::consts::PI,
            self.aperture[1] * 180.0 / std::f64::consts::PI,
        ];
        st.sda_rms_rel = [self.sda[0] / n / d, self.sda[1] / d];
        st.parseval_rel = [self.parseval[0] / n / d, self.parseval[1] / d];
        st.noise_rel = self.noise / n / d;
    }
}

/// What pass 1 counts: the run's statistics and the sums over its patches.
pub(super) struct Tally {
    pub(super) st: SpectralStats,
    sums: Sums,
}

impl Tally {
    pub(super) fn new(store: &Store) -> Tally {
        Tally {
            st: SpectralStats {
                points_in: store.manifest.point_count,
                cells: store.manifest.cells.len(),
                diagonal: store.manifest.bounds.diagonal(),
                ..Default::default()
            },
            sums: Sums::default(),
        }
    }

    /// The statistics, with the patch sums folded in.
    pub(super) fn finish(self) -> SpectralStats {
        let mut st = self.st;
        self.sums.into_stats(&mut st);
        st
    }
}

/// What pass 1 keeps of a cell: where its patches reach.
#[derive(Debug, Clone)]
pub(super) struct CellReach {
    /// Union of its patches' world bounds (empty when it has none).
    reach: Aabb,
    /// Points a resampling of each of its patches at its own rate gives (0 unless
    /// resampling), in patch order.
    points: Vec<f64>,
}

impl CellReach {
    /// What a cell's patches tell pass 2.
    fn of(patches: &[Patch]) -> CellReach {
        let mut reach = Aabb::EMPTY;
        let mut points = Vec::with_capacity(patches.len());
        for p in patches {
            let (lo, hi) = p.frame.world_bounds();
            reach.add(lo);
            reach.add(hi);
            // The rate times the area the members stand for (their share of the box's points).
            let b = p.frame.bx;
            let area = (b[2] - b[0]) * (b[3] - b[1]) * p.members as f64 / p.admitted.max(1) as f64;
            points.push(p.rate as f64 * area);
        }
        CellReach { reach, points }
    }
}

/// A cache of decoded store cells.
struct Cells<'a> {
    store: &'a Store,
    lru: Lru<usize, Arc<PointBatch>>,
}

impl Cells<'_> {
    fn get(&mut self, i: usize) -> Result<Arc<PointBatch>> {
        if let Some(c) = self.lru.get(&i) {
            return Ok(Arc::clone(c));
        }
        let c = Arc::new(self.store.read_cell(i)?);
        self.lru.insert(i, Arc::clone(&c), c.heap_bytes() as u64);
        Ok(c)
    }
}

/// The file of cell `i`'s patches.
fn patch_path(dir: &Path, i: usize) -> PathBuf {
    dir.join(format!("cell-{i:07}.sfp"))
}

/// Read a patch checkpoint.
fn read_patches(path: &Path) -> Result<Vec<Patch>> {
    let bytes = std::fs::read(path).with_path(path)?;
    checkpoint::decode(&bytes).map_err(|m| Error::input(path, m))
}

/// The store's normals, or an error naming it.
pub(super) fn check_store(store: &Store) -> Result<()> {
    if !store.layout.attrs.normal {
        return Err(Error::input(
            &store.dir,
            format!(
                "the points have no normals, which patches are laid out by: ingest with {} auto or estimate",
                Setting::Normals
            ),
        ));
    }
    if store.manifest.point_count == 0 {
        return Err(Error::input(&store.dir, "no points"));
    }
    Ok(())
}

/// Positions with their normals.
type Oriented = (Vec<[f64; 3]>, Vec<[f32; 3]>);

/// The points of cells other than `c` within the box `reach`.
fn gather_halo(cells: &mut Cells<'_>, c: usize, reach: &Aabb) -> Result<Oriented> {
    let (mut pos, mut nor) = (Vec::new(), Vec::new());
    let entries = &cells.store.manifest.cells;
    for o in 0..entries.len() {
        if o == c || !reach.meets(&entries[o].bounds) {
            continue;
        }
        let b = cells.get(o)?;
        for (p, n) in b.pos.iter().zip(&b.normal) {
            if reach.contains(*p) {
                pos.push(*p);
                nor.push(*n);
            }
        }
    }
    Ok((pos, nor))
}

/// What sees each patch's grid before treatment: cell, patch in the cell, the worker's
/// scratch holding the grid in `raw`.
pub(super) type RawGrids<'a> = dyn Fn(usize, usize, &mut PatchWork) + Sync + 'a;

/// Pass 1 over every cell: patches fitted and treated, checkpointed in `dir`. `inspect` sees
/// each cell's points and patches as they are made (not for checkpoints reused); `raw`, when
/// given, each patch's grid before treatment.
pub(super) fn pass1(
    store: &Store,
    treat: &Treatment,
    params: &SpectralParams,
    ctx: &Ctx,
    tally: &mut Tally,
    mut inspect: impl FnMut(usize, &PointBatch, &CellPatches) -> Result<()>,
    raw: Option<&RawGrids<'_>>,
) -> Result<Vec<CellReach>> {
    let t0 = Instant::now();
    let dir = params.work_dir.join(PATCHES_DIR);
    std::fs::create_dir_all(&dir).with_path(&dir)?;
    let entries = &store.manifest.cells;
    let cache_cap = ctx
        .budget
        .share(Share::NormalsCellCache)
        .max(MIN_CACHE_BYTES);
    let _cache_permit = ctx
        .budget
        .acquire(cache_cap, "the cell cache of spectral patches")?;
    let mut cells = Cells {
        store,
        lru: Lru::new(cache_cap),
    };
    let stage = ctx
        .progress
        .stage("patches", Some(store.manifest.point_count), "points");
    let share = ctx.budget.share(Share::NormalsWave);
    let mut reach = Vec::with_capacity(entries.len());
    let mut i = 0;
    while i < entries.len() {
        let (j, bytes) = next_wave(
            &store.manifest.cells,
            i,
            CELLS_PER_THREAD * ctx.threads(),
            share,
            PASS1_BYTES_PER_POINT,
        );
        let _permit = ctx
            .budget
            .acquire(bytes, "a wave of spectral patch cells")?;
        let mut todo = Vec::new();
        for c in i..j {
            let path = patch_path(&dir, c);
            if params.resume
                && path.exists()
                && let Ok(p) = read_patches(&path)
            {
                reach.push((c, CellReach::of(&p)));
                p.iter().for_each(|q| tally.sums.add(q));
                tally.st.resumed_cells += 1;
                continue;
            }
            todo.push((c, cells.get(c)?));
        }
        let tl = Instant::now();
        let plans: Vec<CellPlan> = ctx.pool.install(|| {
            todo.par_iter()
                .map_init(PatchWork::default, |w, (_, b)| {
                    cell::plan_cell(&b.pos, &b.normal, &params.layout, &params.overlap, w)
                })
                .collect()
        });
        tally.st.secs_layout += tl.elapsed().as_secs_f64();
        let mut halos = Vec::with_capacity(todo.len());
        for ((c, _), plan) in todo.iter().zip(&plans) {
            let ext = entries[*c].bounds.extent().into_iter().fold(0f64, f64::max);
            let r = entries[*c].bounds.grown(plan.reach.min(ext));
            halos.push(gather_halo(&mut cells, *c, &r)?);
        }
        let fitted: Vec<CellPatches> = ctx.pool.install(|| {
            todo.par_iter()
                .zip(plans.par_iter().zip(halos.par_iter()))
                .map_init(
                    || {
                        let mut w = PatchWork::default();
                        w.keep_raw = raw.is_some();
                        w
                    },
                    |w, ((c, b), (plan, (hp, hn)))| {
                        let f =
                            cell::fit_cell(&b.pos, &b.normal, hp, hn, plan, treat, w, |k, w| {
                                if let Some(raw) = raw {
                                    raw(*c, k, w)
                                }
                            });
                        stage.inc(b.pos.len() as u64);
                        f
                    },
                )
                .collect()
        });
        drop(halos);
        let written: Vec<Result<()>> = ctx.pool.install(|| {
            todo.par_iter()
                .zip(fitted.par_iter())
                .map(|((c, _), f)| {
                    atomic::write(
                        &patch_path(&dir, *c),
                        &checkpoint::encode(&f.patches),
                        Durability::Renamed,
                    )
                })
                .collect()
        });
        for w in written {
            w?;
        }
        for ((c, b), f) in todo.iter().zip(&fitted) {
            f.patches.iter().for_each(|q| tally.sums.add(q));
            tally.st.unpatched += f.unpatched;
            reach.push((*c, CellReach::of(&f.patches)));
            inspect(*c, b, f)?;
        }
        i = j;
    }
    reach.sort_by_key(|r| r.0);
    stage.finish(None);
    tally.st.secs_patches = t0.elapsed().as_secs_f64();
    Ok(reach.into_iter().map(|(_, r)| r).collect())
}

/// Pass 1 for a run that only needs its patches: the cells' reach and the statistics.
fn patches(
    store: &Store,
    treat: &Treatment,
    params: &SpectralParams,
    ctx: &Ctx,
) -> Result<(Vec<CellReach>, SpectralStats)> {
    check_store(store)?;
    let mut tally = Tally::new(store);
    let reach = pass1(
        store,
        treat,
        params,
        ctx,
        &mut tally,
        |_, _, _| Ok(()),
        None,
    )?;
    Ok((reach, tally.finish()))
}

/// The cells whose patches reach cell `c`'s points, ascending.
fn sources(store: &Store, reach: &[CellReach], c: usize) -> Vec<usize> {
    let b = &store.manifest.cells[c].bounds;
    (0..reach.len())
        .filter(|&o| !reach[o].reach.is_empty() && reach[o].reach.meets(b))
        .collect()
}

/// A cache of decoded patch files.
struct PatchFiles {
    dir: PathBuf,
    lru: Lru<usize, Arc<Vec<Patch>>>,
}

impl PatchFiles {
    fn get(&mut self, i: usize) -> Result<Arc<Vec<Patch>>> {
        if let Some(c) = self.lru.get(&i) {
            return Ok(Arc::clone(c));
        }
        let p = Arc::new(read_patches(&patch_path(&self.dir, i))?);
        let bytes: usize = p.iter().map(|q| q.heap_bytes()).sum();
        self.lru.insert(i, Arc::clone(&p), bytes as u64);
        Ok(p)
    }
}

/// Positions as double where float32 would lose the input's resolution: the meshes' rule
/// ([`VertexFormat::for_cube`]), on the store's cube, so that a filtered point file and a
/// mesh of the same store agree.
pub fn needs_double(cube: &Cube) -> bool {
    VertexFormat::for_cube(cube.origin, cube.size, false, false).double
}

/// One cell's patches, shared through the cache.
type CellPatchSet = Arc<Vec<Patch>>;

/// One wave of pass 2: its cells, their batches and the patches around each.
struct Wave {
    cells: Vec<usize>,
    batches: Vec<Arc<PointBatch>>,
    around: Vec<(Vec<CellPatchSet>, Vec<usize>)>,
}

/// Load pass 2's wave `i..j`.
fn load_wave(
    cells: &mut Cells<'_>,
    files: &mut PatchFiles,
    reach: &[CellReach],
    i: usize,
    j: usize,
) -> Result<Wave> {
    let mut w = Wave {
        cells: (i..j).collect(),
        batches: Vec::new(),
        around: Vec::new(),
    };
    for c in i..j {
        w.batches.push(cells.get(c)?);
        let src = sources(cells.store, reach, c);
        let mut sets = Vec::with_capacity(src.len());
        for &s in &src {
            sets.push(files.get(s)?);
        }
        w.around.push((sets, src));
    }
    Ok(w)
}

/// The patches of `sets` as one list (source cells ascending, then patch order) and, for
/// `own`, the indices of that cell's patches in it.
fn flatten<'a>(
    sets: &'a [Arc<Vec<Patch>>],
    src: &[usize],
    own: usize,
) -> (Vec<&'a Patch>, Vec<u32>) {
    let mut all = Vec::new();
    let mut mine = Vec::new();
    for (set, &s) in sets.iter().zip(src) {
        for p in set.iter() {
            if s == own {
                mine.push(all.len() as u32);
            }
            all.push(p);
        }
    }
    (all, mine)
}

/// The caches pass 2 reads through, charged to the budget.
fn pass2_caches<'a>(
    store: &'a Store,
    params: &SpectralParams,
    ctx: &Ctx,
) -> Result<(Cells<'a>, PatchFiles, [crate::exec::budget::Permit; 2])> {
    let cap = ctx
        .budget
        .share(Share::NormalsCellCache)
        .max(MIN_CACHE_BYTES);
    let permits = [
        ctx.budget
            .acquire(cap, "the cell cache of spectral blending")?,
        ctx.budget
            .acquire(cap, "the patch cache of spectral blending")?,
    ];
    Ok((
        Cells {
            store,
            lru: Lru::new(cap),
        },
        PatchFiles {
            dir: params.work_dir.join(PATCHES_DIR),
            lru: Lru::new(cap),
        },
        permits,
    ))
}

/// The attributes a filtered point file carries: the store's, less the scan index, with
/// normals.
fn out_attrs(a: Attributes) -> Attributes {
    Attributes {
        normal: true,
        source: false,
        ..a
    }
}

/// Filter every point of `store` by `filter` and write them to `output` (a point PLY);
/// `scalar` adds each point's Parseval error (its heaviest patch's) as `parseval_error`.
pub fn filter(
    store: &Store,
    output: &Path,
    filter: crate::spectral::filter::Filter,
    scalar: bool,
    params: &SpectralParams,
    ctx: &Ctx,
) -> Result<SpectralStats> {
    let (reach, mut st) = patches(store, &Treatment::Filter(filter), params, ctx)?;
    let t0 = Instant::now();
    let (mut cells, mut files, _permits) = pass2_caches(store, params, ctx)?;
    let opts = PointFileOptions {
        double: needs_double(&store.manifest.cube),
        scalar: scalar.then(|| "parseval_error".to_string()),
    };
    let mut out =
        PointPlyWriter::create_with(output, st.points_in, out_attrs(store.layout.attrs), opts)?;
    let stage = ctx.progress.stage("blend", Some(st.points_in), "points");
    let share = ctx.budget.share(Share::NormalsWave);
    let n = store.manifest.cells.len();
    let mut i = 0;
    while i < n {
        let (j, bytes) = next_wave(
            &store.manifest.cells,
            i,
            CELLS_PER_THREAD * ctx.threads(),
            share,
            PASS2_BYTES_PER_POINT,
        );
        let _permit = ctx
            .budget
            .acquire(bytes, "a wave of spectral blending cells")?;
        let wave = load_wave(&mut cells, &mut files, &reach, i, j)?;
        let done: Vec<(PointBatch, Vec<f32>, cell::BlendStats)> = ctx.pool.install(|| {
            wave.cells
                .par_iter()
                .zip(wave.batches.par_iter().zip(wave.around.par_iter()))
                .map(|(&c, (b, (sets, src)))| {
                    let (all, _) = flatten(sets, src, c);
                    let around = Around::new(all);
                    let mut out = PointBatch::clone(b);
                    out.source.clear();
                    let mut heaviest = Vec::new();
                    let bs =
                        cell::blend_cell(&around, &mut out.pos, &mut out.normal, &mut heaviest);
                    let sc: Vec<f32> = heaviest
                        .iter()
                        .map(|&h| {
                            around
                                .patches
                                .get(h as usize)
                                .map_or(0.0, |p| p.parseval_rms)
                        })
                        .collect();
                    (out, sc, bs)
                })
                .collect()
        });
        for (b, sc, bs) in done {
            out.write_with(&b, Some(&sc))?;
            st.normal_fallback += bs.fallback;
            st.unblended += bs.unblended;
            stage.inc(b.len() as u64);
        }
        i = j;
    }
    stage.finish(None);
    out.finish()?;
    st.points_out = st.points_in;
    st.secs_blend = t0.elapsed().as_secs_f64();
    Ok(st)
}

/// The band of a resampled patch is chosen for an RMS change of its heights of the error
/// bound over this: a band-limited change peaks at a few times its RMS (√2 for one sinusoid),
/// and the bound is on every point. Measured on an exact 80K-point bumpy sphere at
/// `--max-error 5e-4`: the largest distance to the surface was twice the bound with the RMS
/// at the bound itself, and within it with this factor.
pub const PEAK_TO_RMS: f64 = 3.0;

/// Options of [`resample`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResampleParams {
    /// Largest change of the surface, relative to the bounding-box diagonal.
    pub max_error: f64,
    /// About this many points instead of the rate the error bound gives.
    pub points: Option<u64>,
    /// Least band a patch keeps, relative to its grid's Nyquist frequency.
    pub min_band: f64,
}

/// Resample the surface of `store`'s points within `rp.max_error` (§6) and write the new
/// points to `output`.
pub fn resample(
    store: &Store,
    output: &Path,
    rp: &ResampleParams,
    params: &SpectralParams,
    ctx: &Ctx,
) -> Result<SpectralStats> {
    let treat = Treatment::BandLimit {
        max_err: rp.max_error * store.manifest.bounds.diagonal() / PEAK_TO_RMS,
        min_band: rp.min_band,
    };
    let (reach, mut st) = patches(store, &treat, params, ctx)?;
    let t0 = Instant::now();
    let (mut cells, mut files, _permits) = pass2_caches(store, params, ctx)?;
    let n = store.manifest.cells.len();
    // Points at the patches' own rates, summed in cell and patch order.
    let expected: f64 = reach.iter().flat_map(|r| &r.points).sum();
    let scale = match rp.points {
        Some(target) if expected > 0.0 => target as f64 / expected,
        _ => 1.0,
    };
    // The count is known only at the end: points go to a spill file first.
    let spill = params.work_dir.join(RESAMPLED);
    let mut spill_w = std::io::BufWriter::new(std::fs::File::create(&spill).with_path(&spill)?);
    let stage = ctx.progress.stage("resample", Some(st.points_in), "points");
    let share = ctx.budget.share(Share::NormalsWave);
    let mut i = 0;
    let mut count = 0u64;
    while i < n {
        let (j, bytes) = next_wave(
            &store.manifest.cells,
            i,
            CELLS_PER_THREAD * ctx.threads(),
            share,
            PASS2_BYTES_PER_POINT,
        );
        let _permit = ctx.budget.acquire(bytes, "a wave of resampled cells")?;
        let wave = load_wave(&mut cells, &mut files, &reach, i, j)?;
        let done: Vec<(Oriented, u64)> = ctx.pool.install(|| {
            wave.cells
                .par_iter()
                .zip(wave.around.par_iter())
                .map(|(&c, (sets, src))| {
                    let (all, mine) = flatten(sets, src, c);
                    let around = Around::new(all);
                    let (mut p, mut nn) = (Vec::new(), Vec::new());
                    let fb = cell::resample_cell(&around, &mine, scale, &mut p, &mut nn);
                    stage.inc(store.manifest.cells[c].count);
                    ((p, nn), fb)
                })
                .collect()
        });
        for ((p, nn), fb) in done {
            use std::io::Write;
            let mut buf = Vec::with_capacity(p.len() * 36);
            for (a, b) in p.iter().zip(&nn) {
                a.iter()
                    .for_each(|x| buf.extend_from_slice(&x.to_le_bytes()));
                b.iter()
                    .for_each(|x| buf.extend_from_slice(&x.to_le_bytes()));
            }
            spill_w.write_all(&buf).with_path(&spill)?;
            count += p.len() as u64;
            st.normal_fallback += fb;
        }
        i = j;
    }
    stage.finish(None);
    drop(spill_w);
    write_spill(&spill, count, output, &store.manifest.cube)?;
    std::fs::remove_file(&spill).with_path(&spill)?;
    st.points_out = count;
    st.secs_blend = t0.elapsed().as_secs_f64();
    Ok(st)
}

/// Copy `count` spilled points (position f64 ×3, normal f32 ×3) into a point PLY.
fn write_spill(spill: &Path, count: u64, output: &Path, cube: &Cube) -> Result<()> {
    use std::io::Read;
    let opts = PointFileOptions {
        double: needs_double(cube),
        scalar: None,
    };
    let attrs = Attributes {
        normal: true,
        ..Attributes::default()
    };
    let mut out = PointPlyWriter::create_with(output, count, attrs, opts)?;
    let mut r = std::io::BufReader::new(std::fs::File::open(spill).with_path(spill)?);
    let mut rec = [0u8; 36];
    let mut b = PointBatch::default();
    let mut left = count;
    while left > 0 {
        b.clear();
        while left > 0 && b.pos.len() < 1 << 16 {
            r.read_exact(&mut rec).with_path(spill)?;
            let f =
                |k: usize| f64::from_le_bytes(rec[k * 8..k * 8 + 8].try_into().unwrap_or([0; 8]));
            let g = |k: usize| {
                f32::from_le_bytes(rec[24 + k * 4..28 + k * 4].try_into().unwrap_or([0; 4]))
            };
            b.pos.push([f(0), f(1), f(2)]);
            b.normal.push([g(0), g(1), g(2)]);
            left -= 1;
        }
        out.write(&b)?;
    }
    out.finish()
}
