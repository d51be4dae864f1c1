//! Pass 3, scatter: points grouped by leaf, appended to per-leaf buffers, flushed as zstd
//! frames.
//!
//! Determinism: chunks are grouped in parallel but appended in chunk order, and the flush
//! policy depends only on the sequence of appends, so a cell file's bytes do not depend on
//! the number of threads. Buffers are compressed in parallel, each cut into frames of about
//! [`FRAME_BYTES`] so that one big buffer still keeps every worker busy; frames are written in
//! a fixed order.

use std::io::Write;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::error::{Error, IoContext, Result};
use crate::exec::Ctx;
use crate::io::ChunkSpec;
use crate::store::Sizes;
use crate::store::cell_file::RecordLayout;
use crate::store::input::Inputs;
use crate::store::octree::{GridMap, Hierarchy};
use crate::types::{Aabb, CellKey, Cube, PointBatch};

/// Uncompressed size of a frame, in bytes (rounded down to whole records).
pub const FRAME_BYTES: usize = 2 << 20;

/// Capacity of the writer thread's buffer per open cell file: large sequential writes.
const WRITE_BUFFER_BYTES: usize = 1 << 20;

/// Read every input once more, wave by wave, and scatter its points into the leaves of
/// `hier` through `sc`; returns the cells written. A wave is two halves: while the workers
/// load and group one half's chunks, the calling thread appends the other half's groups in
/// chunk order (that copy, serial, left a core idle a third of the time when the two
/// alternated).
pub fn scatter_pass(
    inputs: &Inputs,
    chunks: &[(usize, ChunkSpec)],
    sizes: &Sizes,
    cube: &Cube,
    hier: &Hierarchy,
    mut sc: Scatter,
    ctx: &Ctx,
) -> Result<Vec<CellOut>> {
    let stage = ctx.progress.stage("scatter", Some(inputs.total), "points");
    // Decoded chunks and their groups live in slots reused from half to half: fresh buffers
    // per chunk cost a page fault per 4 KiB, a quarter of the pass's time. The slots are
    // admitted once, for the whole pass.
    let _permit = ctx.budget.acquire(
        sizes.wave.min(chunks.len()) as u64 * sizes.chunk_bytes,
        "a wave of chunks of points",
    )?;
    let half = (sizes.wave / 2).max(1);
    let mut loading: Vec<Slot> = (0..half).map(|_| Slot::default()).collect();
    let mut loaded: Vec<Slot> = (0..half).map(|_| Slot::default()).collect();
    let load = |part: &[(usize, ChunkSpec)], slots: &mut [Slot]| -> Result<()> {
        let done: Vec<Result<()>> = part
            .par_iter()
            .zip(slots.par_iter_mut())
            .map(|((ri, spec), slot)| {
                inputs.load(&mut slot.batch, *ri, spec)?;
                slot.group(cube, hier, &inputs.layout)?;
                stage.inc(spec.count);
                Ok(())
            })
            .collect();
        done.into_iter().collect()
    };
    // Each round loads the next half into `loading` while appending `loaded`'s first
    // `ready` groups; the first round has nothing to append, the last nothing to load.
    let mut parts = chunks.chunks(half);
    let mut ready = 0;
    loop {
        let next = parts.next();
        if next.is_none() && ready == 0 {
            break;
        }
        let mut next_done: Result<()> = Ok(());
        let pushed = ctx.pool.in_place_scope(|s| {
            if let Some(p) = next {
                let slots = &mut loading;
                let done = &mut next_done;
                s.spawn(move |_| *done = load(p, slots));
            }
            loaded[..ready]
                .iter()
                .try_for_each(|slot| sc.push(&ctx.pool, &slot.grouped))
        });
        pushed?;
        next_done?;
        std::mem::swap(&mut loading, &mut loaded);
        ready = next.map_or(0, |p| p.len());
    }
    let cells_out = sc.finish(&ctx.pool)?;
    stage.finish(None);
    Ok(cells_out)
}

/// One chunk's buffers: its points, their leaves and their records grouped by leaf.
#[derive(Default)]
struct Slot {
    batch: PointBatch,
    leaf: Vec<u32>,
    grouped: Grouped,
}

impl Slot {
    /// [`group_batch`] of the slot's points into its own buffers.
    fn group(&mut self, cube: &Cube, h: &Hierarchy, layout: &RecordLayout) -> Result<()> {
        leaves_of(&self.batch, cube, h, &mut self.leaf)?;
        group(
            &self.batch,
            &self.leaf,
            h.leaves.len(),
            layout,
            &mut self.grouped,
        );
        Ok(())
    }
}

/// Group the points of `b` by their leaf of `h`, a hierarchy over `cube`.
pub fn group_batch(
    b: &PointBatch,
    cube: &Cube,
    h: &Hierarchy,
    layout: &RecordLayout,
) -> Result<Grouped> {
    let mut leaf = Vec::new();
    let mut g = Grouped::default();
    leaves_of(b, cube, h, &mut leaf)?;
    group(b, &leaf, h.leaves.len(), layout, &mut g);
    Ok(g)
}

/// The leaf of `h` (over `cube`) of each point of `b`, into `leaf`.
fn leaves_of(b: &PointBatch, cube: &Cube, h: &Hierarchy, leaf: &mut Vec<u32>) -> Result<()> {
    let map = GridMap::new(cube, h.base, h.levels);
    leaf.clear();
    leaf.reserve(b.len());
    for p in &b.pos {
        let m = map.index(*p);
        leaf.push(h.leaf_of(m).ok_or_else(|| {
            Error::Internal(format!(
                "point {p:?} fell in no cell (grid cell {m}); input changed while reading?"
            ))
        })?);
    }
    Ok(())
}

/// One chunk's records, grouped by leaf.
#[derive(Debug, Default)]
pub struct Grouped {
    /// Records, leaf by leaf.
    pub bytes: Vec<u8>,
    /// `(leaf, byte start, byte end, count, bounds)` per non-empty leaf, by leaf id.
    pub groups: Vec<(u32, usize, usize, u64, Aabb)>,
}

/// Group the points of `b` by leaf (`leaf[i] < leaves` for point `i`), keeping input order
/// within a leaf: a counting sort, so linear in points plus leaves.
pub fn group(
    b: &PointBatch,
    leaf: &[u32],
    leaves: usize,
    layout: &RecordLayout,
    out: &mut Grouped,
) {
    out.groups.clear();
    let stride = layout.stride;
    let mut start = vec![0usize; leaves + 1];
    for &l in leaf {
        start[l as usize + 1] += 1;
    }
    for l in 0..leaves {
        if start[l + 1] > 0 {
            out.groups
                .push((l as u32, 0, 0, start[l + 1] as u64, Aabb::EMPTY));
        }
        start[l + 1] += start[l];
    }
    for g in &mut out.groups {
        g.1 = start[g.0 as usize] * stride;
        g.2 = g.1 + g.3 as usize * stride;
    }
    out.bytes.clear();
    out.bytes.resize(leaf.len() * stride, 0);
    let mut next = start;
    let mut group_of = vec![0u32; leaves];
    for (gi, g) in out.groups.iter().enumerate() {
        group_of[g.0 as usize] = gi as u32;
    }
    for (i, &l) in leaf.iter().enumerate() {
        let slot = next[l as usize];
        next[l as usize] += 1;
        layout.encode_into(b, i, &mut out.bytes[slot * stride..(slot + 1) * stride]);
        out.groups[group_of[l as usize] as usize].4.add(b.pos[i]);
    }
}

/// State of one output cell.
#[derive(Debug)]
pub struct CellOut {
    /// The cell.
    pub key: CellKey,
    /// Its file.
    pub file: PathBuf,
    /// Records written or buffered.
    pub count: u64,
    /// Bounds of its points.
    pub bounds: Aabb,
    /// Compressed bytes written.
    pub bytes: u64,
    crc: crc32fast::Hasher,
    buf: Vec<u8>,
}

impl CellOut {
    /// CRC-32 of the file as written so far.
    pub fn crc32(&self) -> u32 {
        self.crc.clone().finalize()
    }
}

/// The scatter of one hierarchy's leaves.
pub struct Scatter {
    layout: RecordLayout,
    cells: Vec<CellOut>,
    buffered: usize,
    cap: usize,
    zstd_level: i32,
    writer: FrameWriter,
}

/// Frames queued for the writer thread at most; a slow disk then slows the scatter down
/// instead of filling memory.
const WRITE_QUEUE: usize = 16;

/// A thread that appends compressed frames to cell files in the order they are sent, so
/// that disk writes (and dirty-page throttling) overlap with parsing and compression.
struct FrameWriter {
    tx: Option<crossbeam_channel::Sender<(usize, PathBuf, Vec<u8>)>>,
    handle: Option<std::thread::JoinHandle<Result<()>>>,
}

impl FrameWriter {
    fn start() -> Result<FrameWriter> {
        let (tx, rx) = crossbeam_channel::bounded::<(usize, PathBuf, Vec<u8>)>(WRITE_QUEUE);
        let handle = std::thread::Builder::new()
            .name("scanflow-writer".into())
            .spawn(move || -> Result<()> {
                let mut open: Option<(usize, PathBuf, std::io::BufWriter<std::fs::File>)> = None;
                for (i, path, z) in rx {
                    if open.as_ref().map(|o| o.0) != Some(i) {
                        if let Some((_, p, mut w)) = open.take() {
                            w.flush().with_path(&p)?;
                        }
                        let f = std::fs::OpenOptions::new()
                            .append(true)
                            .open(&path)
                            .with_path(&path)?;
                        open = Some((
                            i,
                            path,
                            std::io::BufWriter::with_capacity(WRITE_BUFFER_BYTES, f),
                        ));
                    }
                    if let Some((_, p, w)) = open.as_mut() {
                        w.write_all(&z).with_path(p)?;
                    }
                }
                if let Some((_, p, mut w)) = open.take() {
                    w.flush().with_path(&p)?;
                }
                Ok(())
            })
            .map_err(|e| Error::Internal(format!("cannot start the writer thread: {e}")))?;
        Ok(FrameWriter {
            tx: Some(tx),
            handle: Some(handle),
        })
    }

    fn send(&self, i: usize, path: &Path, z: Vec<u8>) -> std::result::Result<(), ()> {
        match &self.tx {
            Some(tx) => tx.send((i, path.to_path_buf(), z)).map_err(|_| ()),
            None => Err(()),
        }
    }

    fn finish(&mut self) -> Result<()> {
        drop(self.tx.take());
        match self.handle.take() {
            Some(h) => h
                .join()
                .map_err(|_| Error::Internal("the writer thread panicked".into()))?,
            None => Ok(()),
        }
    }
}

impl Drop for FrameWriter {
    fn drop(&mut self) {
        let _ = self.finish();
    }
}

impl Scatter {
    /// Cells `keys` under `dir`, buffering at most `cap_bytes` before flushing.
    pub fn new(
        dir: &Path,
        keys: &[CellKey],
        layout: RecordLayout,
        cap_bytes: usize,
        zstd_level: i32,
    ) -> Result<Scatter> {
        let mut cells = Vec::with_capacity(keys.len());
        for &key in keys {
            let file = dir.join(format!("{}.zst", key.file_name()));
            // Create (truncate) now, so that a cell's file exists even before its first frame.
            std::fs::File::create(&file).with_path(&file)?;
            cells.push(CellOut {
                key,
                file,
                count: 0,
                bounds: Aabb::EMPTY,
                bytes: 0,
                crc: crc32fast::Hasher::new(),
                buf: Vec::new(),
            });
        }
        Ok(Scatter {
            layout,
            cells,
            buffered: 0,
            cap: cap_bytes.max(FRAME_BYTES),
            zstd_level,
            writer: FrameWriter::start()?,
        })
    }

    /// Append one chunk's groups (chunks must come in input order).
    pub fn push(&mut self, pool: &rayon::ThreadPool, g: &Grouped) -> Result<()> {
        for &(l, s, e, n, bounds) in &g.groups {
            let c = self
                .cells
                .get_mut(l as usize)
                .ok_or_else(|| Error::Internal(format!("leaf {l} out of range")))?;
            c.buf.extend_from_slice(&g.bytes[s..e]);
            c.count += n;
            c.bounds = c.bounds.union(&bounds);
            self.buffered += e - s;
        }
        if self.buffered > self.cap {
            self.flush(pool, self.cap / 2)?;
        }
        Ok(())
    }

    /// Flush the fullest buffers until at most `target` bytes stay buffered.
    fn flush(&mut self, pool: &rayon::ThreadPool, target: usize) -> Result<()> {
        let mut by_size: Vec<usize> = (0..self.cells.len())
            .filter(|&i| !self.cells[i].buf.is_empty())
            .collect();
        by_size.sort_by_key(|&i| (std::cmp::Reverse(self.cells[i].buf.len()), i));
        let mut chosen = Vec::new();
        for i in by_size {
            if self.buffered <= target {
                break;
            }
            self.buffered -= self.cells[i].buf.len();
            chosen.push(i);
        }
        chosen.sort_unstable();
        // Cut each chosen buffer into frames; compress all frames in parallel.
        let frame = (FRAME_BYTES / self.layout.stride).max(1) * self.layout.stride;
        let bufs: Vec<(usize, Vec<u8>)> = chosen
            .iter()
            .map(|&i| (i, std::mem::take(&mut self.cells[i].buf)))
            .collect();
        let jobs: Vec<(usize, &[u8])> = bufs
            .iter()
            .flat_map(|(i, b)| b.chunks(frame).map(move |f| (*i, f)))
            .collect();
        let level = self.zstd_level;
        let frames: Vec<(usize, std::io::Result<Vec<u8>>)> = pool.install(|| {
            jobs.par_iter()
                .map(|&(i, f)| (i, zstd::bulk::compress(f, level)))
                .collect()
        });
        for (i, z) in frames {
            let z = z.map_err(|e| Error::Internal(format!("zstd compression failed: {e}")))?;
            let c = &mut self.cells[i];
            c.crc.update(&z);
            c.bytes += z.len() as u64;
            if self.writer.send(i, &c.file, z).is_err() {
                // The writer stopped on an error; finish() reports it.
                break;
            }
        }
        Ok(())
    }

    /// Flush everything and return the cells.
    pub fn finish(mut self, pool: &rayon::ThreadPool) -> Result<Vec<CellOut>> {
        self.flush(pool, 0)?;
        self.writer.finish()?;
        Ok(self.cells)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::Attributes;

    #[test]
    fn groups_keep_input_order() {
        let layout = RecordLayout::new(Attributes::default(), false);
        let b = PointBatch {
            pos: (0..6).map(|i| [i as f64, 0.0, 0.0]).collect(),
            ..Default::default()
        };
        let mut g = Grouped::default();
        group(&b, &[2, 0, 2, 1, 0, 2], 3, &layout, &mut g);
        let leaves: Vec<(u32, u64)> = g.groups.iter().map(|x| (x.0, x.3)).collect();
        assert_eq!(leaves, vec![(0, 2), (1, 1), (2, 3)]);
        let mut d = PointBatch::default();
        layout.decode(&g.bytes[g.groups[2].1..g.groups[2].2], &mut d);
        assert_eq!(
            d.pos.iter().map(|p| p[0]).collect::<Vec<_>>(),
            vec![0.0, 2.0, 5.0]
        );
    }
}
