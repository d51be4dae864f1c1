//! A split ingest: `scanflow ingest FILES -o STORE --shard I/N`, one task of a cluster array
//! job, against a work directory every task shares (ARCHITECTURE.md step 1, split).
//!
//! The store's passes become lists of work items, done as the reconstruction's leaves and
//! tiles are ([`crate::pipeline::shard`]: own slice first, claims by exclusive create, then a
//! second pass over every item still missing; no task waits for another):
//!
//! | stage | items | checkpoint |
//! |---|---|---|
//! | count (and a recount on the exact cube, when needed) | slices of [`CHUNKS_PER_ITEM`] input chunks of up to [`SPLIT_CHUNK_POINTS`] points ([`split_chunk_points`]) | the slice's counts on the grid ([`Partial`]) |
//! | scatter | the same slices | a *pack*: the slice's frames, cell after cell, with their index ([`crate::store::assemble`]) |
//! | assemble and split | [`LEAVES_PER_ITEM`] leaves of the hierarchy | their cell files, frames appended from every pack in order, split when over the limit, and their manifest entries |
//! | normals, pass 1 (when estimated) | [`CELLS_PER_ITEM`] cells | side files (normals, components) and the cells' orientation data |
//! | normals, pass 2 | one | the components' signs |
//! | normals, pass 3 | [`CELLS_PER_ITEM`] cells | the cells rewritten with their normals |
//!
//! Between stages every task reads every checkpoint of the stage before (the summed counts,
//! the hierarchy, the cell list): the same numbers in every task, as the item boundaries
//! depend on neither `--threads` nor the shard count. Any task that finds the last stage
//! complete writes the manifest and renames the staged store into place (`rename(2)` of a
//! directory: one task's succeeds; the others find the store there and stop), then removes
//! the work directory; a task that then fails because the work directory went away finds
//! the store complete and succeeds.
//!
//! **Same store.** Points reach each cell in input order, as in one process: the packs hold
//! the slices in input order and a cell appends their frames in that order; the split reads
//! its cell in that order. Only the zstd frame boundaries differ from one process's store, so
//! the points, the normals, and everything `reconstruct` makes of them are the same.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use serde::{Deserialize, Serialize};

use super::ingest::{IngestParams, IngestStats};
use super::shard::{Claims, Shard};
use super::workdir::{self, INGEST_DIR, RunIdentity, StoreSource};
use crate::error::{Error, IoContext, Result, Setting};
use crate::exec::Ctx;
use crate::fs::atomic::{self, Durability};
use crate::io::InputSpec;
use crate::normals::{self, CellResult, Signs};
use crate::store::assemble::{self, Pack};
use crate::store::count::{first_cube, recount_cube};
use crate::store::manifest::{CellEntry, MANIFEST, Manifest};
use crate::store::{
    CELLS_DIR, Found, NormalsMode, Partial, Prepared, StageDir, Staged, cell_entry,
};

/// Most points per input chunk of a split ingest (45 MiB in flight a chunk): one process's
/// largest chunk.
pub const SPLIT_CHUNK_POINTS: u64 = crate::store::MAX_CHUNK_POINTS;

/// Fewest points per input chunk of a split ingest.
pub const MIN_SPLIT_CHUNK_POINTS: u64 = 2048;

/// Count and scatter items a split ingest aims at for inputs too small to fill items of
/// whole chunks of [`SPLIT_CHUNK_POINTS`].
pub const MIN_ITEMS: u64 = 64;

/// Points per input chunk of a split ingest of `total` points: from the point count alone, so
/// that every task cuts the inputs alike whatever its `--threads` and `--mem`; small inputs
/// get small chunks, to make [`MIN_ITEMS`] items.
pub fn split_chunk_points(total: u64) -> u64 {
    (total / (CHUNKS_PER_ITEM as u64 * MIN_ITEMS)).clamp(MIN_SPLIT_CHUNK_POINTS, SPLIT_CHUNK_POINTS)
}

/// Most bytes a split ingest's cell buffers hold before they are flushed: a cap that the
/// budget's slice reaches from a --mem of 256 MiB up.
pub const SPLIT_BUFFER_BYTES: usize = 32 << 20;

/// Chunks per count and scatter item: up to 4 Mi points, a few seconds of a core's work,
/// so that an item's own costs (a counting grid, fresh buffers, every cell's last frame)
/// stay small beside it.
pub const CHUNKS_PER_ITEM: usize = 16;

/// Leaves of the hierarchy per assembly item.
pub const LEAVES_PER_ITEM: usize = 8;

/// Cells per normals item: one, a cell being up to `--max-cell-points` points of fits (a
/// task works on as many at once as it has threads).
pub const CELLS_PER_ITEM: usize = 1;

/// What a task of a split ingest ended with.
#[derive(Debug)]
pub enum SplitOutcome {
    /// This task committed the store.
    Committed(IngestStats),
    /// The store was complete: another task committed it.
    Done,
}

/// One assembly item's checkpoint: its cells' manifest entries and those left over the limit.
#[derive(Debug, Serialize, Deserialize)]
struct Assembled {
    cells: Vec<CellEntry>,
    oversized: usize,
}

/// One normals pass-3 item's checkpoint: each rewritten cell's index, size and CRC-32.
#[derive(Debug, Serialize, Deserialize)]
struct Oriented {
    cells: Vec<(usize, u64, u32)>,
}

/// The directories of a split ingest, under `work/ingest/`.
struct Dirs {
    root: PathBuf,
    claims: Claims,
}

impl Dirs {
    fn sub(&self, name: &str) -> PathBuf {
        self.root.join(name)
    }
    fn store(&self) -> PathBuf {
        self.sub("store")
    }
}

/// Run shard `shard` of the split ingest of `inputs` into the store `out`, in the work
/// directory `work` that every task shares; see the [module docs](self).
pub fn ingest_split(
    inputs: &[InputSpec],
    out: &Path,
    params: &IngestParams,
    shard: Shard,
    work: &Path,
    ctx: &Ctx,
) -> Result<SplitOutcome> {
    if complete(out, inputs, params)? {
        // A task killed between the commit and the removal leaves the work directory.
        if workdir::is_work_dir(work) {
            let _ = workdir::remove_owned(work);
        }
        return Ok(SplitOutcome::Done);
    }
    let sp = params.store_params();
    let mut prep =
        Prepared::open_chunked(inputs, &sp, |total| Some(split_chunk_points(total)), ctx)?;
    prep.limit_buffers(SPLIT_BUFFER_BYTES);
    let options = [
        ("command", "ingest".to_string()),
        (
            Setting::MaxCellPoints.name(),
            sp.max_cell_points.to_string(),
        ),
        (Setting::SkipInvalid.name(), sp.skip_invalid.to_string()),
        (Setting::ZstdLevel.name(), sp.zstd_level.to_string()),
        // The counting grid and the cell buffers follow the budget (and the cells' frames
        // follow the buffers): every task must size them alike. Under the defaults both
        // are at their caps from a --mem of 256 MiB up, so tasks on nodes whose free
        // memory differs agree.
        ("counting grid levels", prep.levels.to_string()),
        ("cell buffer bytes", prep.cap.to_string()),
    ];
    let identity = RunIdentity::with_options(
        &StoreSource::Points(inputs.to_vec()),
        params.normals,
        &params.normal_params,
        &options,
    )?;
    let lease = workdir::join(work, &identity)?;
    let root = lease.dir().join(INGEST_DIR);
    let dirs = Dirs {
        claims: Claims::new(&root.join("claims")),
        root,
    };
    let run = (|| {
        for d in [
            "claims",
            "count0",
            "count1",
            "packs",
            "assembled",
            "raw",
            "fits",
            "sides",
            "orient",
        ] {
            std::fs::create_dir_all(dirs.sub(d)).with_path(dirs.sub(d))?;
        }
        std::fs::create_dir_all(dirs.store().join(CELLS_DIR)).with_path(dirs.store())?;
        let staged = build(prep, out, shard, &dirs, ctx)?;
        finish(staged, params, shard, &dirs, ctx)
    })();
    let outcome = match run {
        Ok(st) => SplitOutcome::Committed(st),
        // Another task committed the store and removed the work directory under this one.
        Err(_) if complete(out, inputs, params)? => SplitOutcome::Done,
        Err(e) => return Err(e),
    };
    // The store is complete: nothing in the work directory is needed any more. A task still
    // finishing an item there may keep it from emptying; the last one out removes it.
    match lease.remove() {
        // Another task removed it first.
        Err(Error::Io { err, .. }) if err.kind() == std::io::ErrorKind::NotFound => {}
        Ok(left) if !left.is_empty() => log::warn!(
            "{}: kept: it holds {} entries scanflow did not make",
            work.display(),
            left.len()
        ),
        Ok(_) => {}
        Err(e) => log::info!("work directory not removed yet ({e}): another task is finishing"),
    }
    Ok(outcome)
}

/// Whether `out` is a complete store of `inputs` made with `params` (a task arriving after
/// the commit); an error when something else is there, naming the option that differs: a
/// task of another run that arrives after the first run's tasks have finished must fail as
/// it would have while they ran.
fn complete(out: &Path, inputs: &[InputSpec], params: &IngestParams) -> Result<bool> {
    if !out.exists() {
        return Ok(false);
    }
    let theirs = out.join(MANIFEST);
    let m = theirs
        .is_file()
        .then(|| Manifest::load(out).ok())
        .flatten()
        .ok_or_else(|| {
            Error::input(
                out,
                format!(
                    "output store already exists and is not a complete store; remove it or choose another {}",
                    Setting::Output
                ),
            )
        })?;
    let same = m.inputs.len() == inputs.len()
        && m.inputs
            .iter()
            .zip(inputs)
            .all(|(e, i)| Path::new(&e.path) == i.path);
    if !same {
        return Err(Error::input(
            out,
            format!(
                "output store already exists and was made from other inputs; remove it or choose another {}",
                Setting::Output
            ),
        ));
    }
    let mut differ = Vec::new();
    let sp = params.store_params();
    if let Some(level) = m.zstd_level.filter(|&l| l != sp.zstd_level) {
        differ.push(format!(
            "{} {level} there, {} here",
            Setting::ZstdLevel,
            sp.zstd_level
        ));
    }
    if let Some(skip) = m.skip_invalid.filter(|&s| s != sp.skip_invalid) {
        let said = |on: bool| if on { "given" } else { "not given" };
        differ.push(format!(
            "{} {} there, {} here",
            Setting::SkipInvalid,
            said(skip),
            said(sp.skip_invalid)
        ));
    }
    if m.max_cell_points != params.max_cell_points {
        differ.push(format!(
            "{} {} there, {} here",
            Setting::MaxCellPoints,
            m.max_cell_points,
            params.max_cell_points
        ));
    }
    match (&m.estimated_normals, params.normals) {
        (Some(_), NormalsMode::Use) => differ.push(format!(
            "{}: estimated there, the inputs' here",
            Setting::Normals
        )),
        (None, NormalsMode::Estimate) => differ.push(format!(
            "{}: the inputs' there, estimated here",
            Setting::Normals
        )),
        (Some(e), _) if e.k != params.normal_params.k => differ.push(format!(
            "{} {} there, {} here",
            Setting::Neighbours,
            e.k,
            params.normal_params.k
        )),
        (Some(e), _) if e.robust != params.normal_params.robust => differ.push(format!(
            "{} {} there, {} here",
            Setting::RobustNormals,
            e.robust,
            params.normal_params.robust
        )),
        _ => {}
    }
    if !differ.is_empty() {
        return Err(Error::input(
            out,
            format!(
                "output store already exists and was made with other options ({}); remove it or choose another {}",
                differ.join("; "),
                Setting::Output
            ),
        ));
    }
    Ok(true)
}

/// Do the items of one stage: `n` of them, named `prefix` and their index in the claims, each
/// skipped when `done` says its checkpoint exists, else claimed (first pass) and done by
/// `work`.
fn items(
    shard: Shard,
    n: usize,
    dirs: &Dirs,
    prefix: &str,
    done: impl Fn(usize) -> bool,
    mut work: impl FnMut(usize) -> Result<()>,
) -> Result<()> {
    let order = shard.order(n);
    for &claiming in shard.passes() {
        let cursor = AtomicUsize::new(0);
        while let Some(i) = next_item(&order, &cursor, claiming, dirs, prefix, &done)? {
            work(i)?;
        }
    }
    Ok(())
}

/// [`items`] done by as many workers of the pool as it has threads at once, each taking the
/// next item of this task's order: for items that use one core each (a cell's normals).
fn items_concurrent(
    shard: Shard,
    n: usize,
    dirs: &Dirs,
    prefix: &str,
    done: impl Fn(usize) -> bool + Sync,
    work: impl Fn(usize) -> Result<()> + Sync,
    ctx: &Ctx,
) -> Result<()> {
    use rayon::prelude::*;
    let order = shard.order(n);
    for &claiming in shard.passes() {
        let cursor = AtomicUsize::new(0);
        let worker = || -> Result<()> {
            while let Some(i) = next_item(&order, &cursor, claiming, dirs, prefix, &done)? {
                work(i)?;
            }
            Ok(())
        };
        let ended: Vec<Result<()>> = ctx.pool.install(|| {
            (0..ctx.threads().min(n.max(1)))
                .into_par_iter()
                .map(|_| worker())
                .collect()
        });
        ended.into_iter().collect::<Result<()>>()?;
    }
    Ok(())
}

/// The next item of `order`, from `cursor` on, to do in this pass: its checkpoint missing
/// (`done`), and in a claiming pass its claim taken by this call.
fn next_item(
    order: &[usize],
    cursor: &AtomicUsize,
    claiming: bool,
    dirs: &Dirs,
    prefix: &str,
    done: &impl Fn(usize) -> bool,
) -> Result<Option<usize>> {
    while let Some(&i) = order.get(cursor.fetch_add(1, Ordering::Relaxed)) {
        if !done(i) && (!claiming || dirs.claims.take(&format!("{prefix}{i}"))?) {
            return Ok(Some(i));
        }
    }
    Ok(None)
}

/// Item `i`'s range of `n` things, `per` an item.
fn range(i: usize, per: usize, n: usize) -> Range<usize> {
    i * per..((i + 1) * per).min(n)
}

/// Count, scatter, assemble and split: the staged store in `dirs`, its cells complete
/// (without their normals when these are to be estimated).
fn build(prep: Prepared, out: &Path, shard: Shard, dirs: &Dirs, ctx: &Ctx) -> Result<Staged> {
    let chunks = prep.chunks()?;
    let slices: Vec<&[(usize, crate::io::ChunkSpec)]> = chunks.chunks(CHUNKS_PER_ITEM).collect();
    let n = slices.len();

    let (cube, total) = count_pass(&prep, &slices, shard, dirs, ctx)?;
    crate::store::no_valid_points(&prep.inputs, &total.bounds)?;
    prep.inputs.raise_max_colors(&total.max_color);
    prep.inputs.settle_colour_scale();
    let hier = {
        let _permit = ctx.budget.acquire(prep.grid_bytes(), "the counting grid")?;
        prep.hierarchy(&total.counts)
    };
    let (bounds, skipped) = (total.bounds, total.skipped);
    drop(total);

    // Scatter: each slice into its pack.
    let pack = |i: usize| dirs.sub("packs").join(format!("{i}.pack"));
    let stage = ctx
        .progress
        .stage("scatter", Some(prep.inputs.total), "points");
    items(
        shard,
        n,
        dirs,
        "s-",
        |i| pack(i).exists(),
        |i| {
            let tmp = atomic::temp_name(&pack(i));
            let made = prep.scatter_pack(slices[i], &cube, &hier, &tmp, &stage, ctx);
            match made.and_then(|_| std::fs::rename(&tmp, pack(i)).with_path(pack(i))) {
                Ok(()) => Ok(()),
                Err(e) => {
                    atomic::remove_temp(&tmp);
                    Err(e)
                }
            }
        },
    )?;
    stage.finish(None);

    // Assemble and split, a few leaves an item.
    let leaves = hier.leaves.len();
    let k = leaves.div_ceil(LEAVES_PER_ITEM);
    let assembled = |i: usize| dirs.sub("assembled").join(format!("{i}.json"));
    // Cells whose normals are still to be estimated wait in `raw/`: the store's `cells/`
    // receives them rewritten with their normals.
    let wants_normals = prep.inputs.estimate_normals;
    let cells_dir = if wants_normals {
        dirs.sub("raw")
    } else {
        dirs.store().join(CELLS_DIR)
    };
    let mut packs: Option<(Vec<Pack>, crate::exec::budget::Permit)> = None;
    let stage = ctx.progress.stage("assemble", Some(leaves as u64), "cells");
    items(
        shard,
        k,
        dirs,
        "a-",
        |i| assembled(i).exists(),
        |i| {
            if packs.is_none() {
                let p = (0..n)
                    .map(|j| Pack::open(&pack(j)))
                    .collect::<Result<Vec<_>>>()?;
                let bytes = p.iter().map(Pack::index_bytes).sum();
                let permit = ctx.budget.acquire(bytes, "the packs' indices")?;
                packs = Some((p, permit));
            }
            let Some((p, _)) = &packs else {
                return Err(Error::Internal("packs not opened".into()));
            };
            let r = range(i, LEAVES_PER_ITEM, leaves);
            // A directory of this task's own, so that a task doing the same item meanwhile
            // never writes into the same files; each cell is renamed into the store whole.
            let tmp = atomic::temp_name(&dirs.sub(&format!("a{i}")));
            std::fs::create_dir(&tmp).with_path(&tmp)?;
            let done = (|| {
                let cells = assemble::assemble(p, &hier, r.clone(), &tmp, &ctx.pool)?;
                let over: Vec<bool> = r.clone().map(|l| hier.leaves[l].oversized).collect();
                let (cells, oversized) = prep.splitter(&cube, &tmp).run(cells, &over, ctx)?;
                let mut entries = Vec::new();
                for c in cells.iter().filter(|c| c.count > 0) {
                    let e = cell_entry(c);
                    let dest = cells_dir.join(&e.file);
                    std::fs::rename(&c.file, &dest).with_path(&dest)?;
                    entries.push(e);
                }
                let text = serde_json::to_vec(&Assembled {
                    cells: entries,
                    oversized,
                })
                .map_err(|e| Error::Internal(format!("assembled cells: {e}")))?;
                atomic::write(&assembled(i), &text, Durability::Renamed)
            })();
            let _ = std::fs::remove_dir_all(&tmp);
            stage.inc(r.len() as u64);
            done
        },
    )?;
    stage.finish(None);
    drop(packs);

    let (cells, oversized_cells) = read_assembled(k, assembled)?;
    let found = Found {
        cube,
        bounds,
        skipped,
        oversized_cells,
    };
    let mut staged = prep.staged(StageDir::Shared(dirs.store()), out, cells, found);
    if wants_normals {
        staged.read_cells_from(cells_dir);
    }
    Ok(staged)
}

/// Count: on the first cube, and once more on the exact one when the bounds say so. Returns
/// the cube and the summed counts.
fn count_pass(
    prep: &Prepared,
    slices: &[&[(usize, crate::io::ChunkSpec)]],
    shard: Shard,
    dirs: &Dirs,
    ctx: &Ctx,
) -> Result<(crate::types::Cube, Partial)> {
    let n = slices.len();
    let mut cube = first_cube(&prep.provisional);
    let mut total;
    let mut round = 0;
    loop {
        let dir = dirs.sub(&format!("count{round}"));
        let path = |i: usize| dir.join(format!("{i}.cnt"));
        let stage = ctx
            .progress
            .stage("count", Some(prep.inputs.total), "points");
        items(
            shard,
            n,
            dirs,
            &format!("c{round}-"),
            |i| path(i).exists(),
            |i| {
                let _permit = ctx
                    .budget
                    .acquire(prep.grid_bytes() / 2, "the counting grid")?;
                let p = prep.count(slices[i], &cube, &stage, ctx)?;
                atomic::write(&path(i), &p.encode(), Durability::Renamed)
            },
        )?;
        stage.finish(None);
        let _permit = ctx.budget.acquire(prep.grid_bytes(), "the counting grid")?;
        total = Partial::empty(prep.levels, prep.inputs.specs.len());
        for i in 0..n {
            let bytes = std::fs::read(path(i)).with_path(path(i))?;
            total.add(&Partial::decode(&bytes, &path(i))?);
        }
        match (round == 0)
            .then(|| recount_cube(&prep.provisional, &total.bounds))
            .flatten()
        {
            Some(c) => {
                cube = c;
                round = 1;
            }
            None => break,
        }
    }
    Ok((cube, total))
}

/// The cells the `k` assembly items made, in key order, and how many were oversized.
fn read_assembled(
    k: usize,
    assembled: impl Fn(usize) -> PathBuf,
) -> Result<(Vec<CellEntry>, usize)> {
    let mut cells = Vec::new();
    let mut oversized_cells = 0;
    for i in 0..k {
        let text = std::fs::read(assembled(i)).with_path(assembled(i))?;
        let a: Assembled = serde_json::from_slice(&text)
            .map_err(|e| Error::input(assembled(i), format!("damaged checkpoint: {e}")))?;
        cells.extend(a.cells);
        oversized_cells += a.oversized;
    }
    cells.sort_by_key(|c| c.key);
    Ok((cells, oversized_cells))
}

/// Estimate the normals when they are wanted, then commit the store.
fn finish(
    mut staged: Staged,
    params: &IngestParams,
    shard: Shard,
    dirs: &Dirs,
    ctx: &Ctx,
) -> Result<IngestStats> {
    if !staged.wants_normals() {
        return staged.commit(None);
    }
    let t0 = std::time::Instant::now();
    let np = &params.normal_params;
    let n = staged.cells().len();
    let k = n.div_ceil(CELLS_PER_ITEM);
    let total: u64 = staged.cells().iter().map(|c| c.count).sum();
    let sides = dirs.sub("sides");
    let fit = |i: usize| dirs.sub("fits").join(format!("{i}.bin"));
    let stage = ctx.progress.stage("normals", Some(total), "points");
    let st: &Staged = &staged;
    items_concurrent(
        shard,
        k,
        dirs,
        "n-",
        |i| fit(i).exists(),
        |i| {
            let r = normals::fit_cells(st, &sides, np, range(i, CELLS_PER_ITEM, n), &stage, ctx)?;
            atomic::write(&fit(i), &normals::encode_results(&r), Durability::Renamed)
        },
        ctx,
    )?;
    stage.finish(None);
    let mut results: Vec<CellResult> = Vec::with_capacity(n);
    for i in 0..k {
        let bytes = std::fs::read(fit(i)).with_path(fit(i))?;
        results.extend(normals::decode_results(&bytes, &fit(i))?);
    }
    let signs_path = dirs.sub("signs.bin");
    let signs = match std::fs::read(&signs_path) {
        Ok(bytes) => Signs::decode(&bytes, &signs_path)?,
        Err(_) => {
            let s = normals::component_signs(&results, staged.cells(), &sides, ctx)?;
            atomic::write(&signs_path, &s.encode(), Durability::Renamed)?;
            s
        }
    };
    let orient = |i: usize| dirs.sub("orient").join(format!("{i}.json"));
    let stage = ctx.progress.stage("orient", Some(n as u64), "cells");
    let st: &Staged = &staged;
    items_concurrent(
        shard,
        k,
        dirs,
        "o-",
        |i| orient(i).exists(),
        |i| {
            let mut done = Vec::new();
            for c in range(i, CELLS_PER_ITEM, n) {
                let dest = st.cell_path(c);
                let (bytes, crc) = normals::rewrite_cell(st, c, &sides, &signs, &dest)?;
                done.push((c, bytes, crc));
                stage.inc(1);
            }
            let text = serde_json::to_vec(&Oriented { cells: done })
                .map_err(|e| Error::Internal(format!("oriented cells: {e}")))?;
            atomic::write(&orient(i), &text, Durability::Renamed)
        },
        ctx,
    )?;
    stage.finish(None);
    for i in 0..k {
        let text = std::fs::read(orient(i)).with_path(orient(i))?;
        let o: Oriented = serde_json::from_slice(&text)
            .map_err(|e| Error::input(orient(i), format!("damaged checkpoint: {e}")))?;
        for (c, bytes, crc) in o.cells {
            if c >= n {
                return Err(Error::input(orient(i), "damaged checkpoint: no such cell"));
            }
            staged.set_cell_file(c, bytes, crc);
        }
    }
    let summary = normals::summary(&results, &signs, np, total);
    staged.commit(Some((summary, t0.elapsed().as_secs_f64())))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::Cube;

    #[test]
    fn item_ranges_cover_everything_once() {
        for n in [0usize, 1, 7, 8, 9, 100] {
            let k = n.div_ceil(8);
            let all: Vec<usize> = (0..k).flat_map(|i| range(i, 8, n)).collect();
            assert_eq!(all, (0..n).collect::<Vec<_>>());
        }
    }

    #[test]
    fn cube_choice_is_shared_with_one_process() {
        // The split ingest and one process pick their cubes by the same two functions.
        let b = crate::types::Aabb {
            min: [0.0; 3],
            max: [1.0; 3],
        };
        let c: Cube = first_cube(&b);
        assert!(recount_cube(&b, &b).is_none());
        assert!(c.size > 1.0);
    }
}
