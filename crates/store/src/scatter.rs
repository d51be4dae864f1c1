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

use crate::Prepared;
use crate::cell_file::RecordLayout;
use crate::error::{Error, IoContext, Result};
use crate::exec::Ctx;
use crate::exec::progress::Stage;
use crate::fs::le::{LeReader, LeWriter};
use crate::io::ChunkSpec;
use crate::octree::{GridMap, Hierarchy};
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
    prep: &Prepared,
    chunks: &[(usize, ChunkSpec)],
    cube: &Cube,
    hier: &Hierarchy,
    mut sc: Scatter,
    stage: &Stage,
    ctx: &Ctx,
) -> Result<Scattered> {
    let (inputs, sizes) = (&prep.inputs, &prep.sizes);
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
    sc.finish(&ctx.pool)
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
    /// An empty cell `key` written to `file`.
    pub fn new(key: CellKey, file: PathBuf) -> CellOut {
        CellOut {
            key,
            file,
            count: 0,
            bounds: Aabb::EMPTY,
            bytes: 0,
            crc: crc32fast::Hasher::new(),
            buf: Vec::new(),
        }
    }

    /// Add `len` compressed bytes appended to its file, of CRC-32 `crc32` (taken once, when
    /// they were compressed: the file's CRC-32 is combined from its frames').
    pub fn wrote(&mut self, len: u64, crc32: u32) {
        self.crc
            .combine(&crc32fast::Hasher::new_with_initial_len(crc32, len));
        self.bytes += len;
    }

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
    pack: Option<Pack>,
}

/// Where a packed scatter's frames went: one file, frames appended in the order flushed.
#[derive(Debug, Default)]
struct Pack {
    path: PathBuf,
    bytes: u64,
    /// `(cell, frame)` of every frame, in file order.
    frames: Vec<(u32, Frame)>,
}

/// What a scatter wrote: its cells, and for a packed scatter where each cell's frames lie in
/// the pack ([`PackIndex`]).
pub struct Scattered {
    /// The cells, in the order of the keys given.
    pub cells: Vec<CellOut>,
    /// The pack's index (a packed scatter only).
    pub pack: Option<PackIndex>,
}

/// One cell's part of a pack: its points' count and bounds and its frames, in order.
#[derive(Debug, Clone, PartialEq)]
pub struct PackCell {
    /// The cell's index among the scatter's keys.
    pub cell: u32,
    /// Records.
    pub count: u64,
    /// Bounds of its points.
    pub bounds: Aabb,
    /// Its frames in the pack, in order.
    pub frames: Vec<Frame>,
}

/// Where one compressed frame lies in a pack, and its CRC-32 (a cell's CRC-32 is combined
/// from its frames' without reading them again).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame {
    /// Its first byte in the pack.
    pub offset: u64,
    /// Its length in bytes.
    pub len: u32,
    /// CRC-32 of its bytes.
    pub crc32: u32,
}

/// The index of a pack: every non-empty cell's part, by cell. Stored at the pack's end,
/// followed by its length (`u64`), its CRC-32 (`u32`) and [`PACK_MAGIC`], little-endian.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PackIndex {
    /// The cells with points, in cell order.
    pub cells: Vec<PackCell>,
}

/// The last bytes of a pack.
pub const PACK_MAGIC: &[u8; 8] = b"SFPACK01";

impl PackIndex {
    /// The index as bytes (see [`PackIndex`]).
    fn encode(&self) -> Vec<u8> {
        let mut w = LeWriter::default();
        w.u64(self.cells.len() as u64);
        for c in &self.cells {
            w.u32(c.cell);
            w.u64(c.count);
            c.bounds
                .min
                .iter()
                .chain(&c.bounds.max)
                .for_each(|&v| w.f64(v));
            w.u64(c.frames.len() as u64);
            for f in &c.frames {
                w.u64(f.offset);
                w.u32(f.len);
                w.u32(f.crc32);
            }
        }
        w.bytes
    }

    /// Append the index and its trailer to the pack `path` and sync it.
    pub fn append_to(&self, path: &Path) -> Result<()> {
        let idx = self.encode();
        let mut f = std::fs::OpenOptions::new()
            .append(true)
            .open(path)
            .with_path(path)?;
        f.write_all(&idx).with_path(path)?;
        f.write_all(&(idx.len() as u64).to_le_bytes())
            .with_path(path)?;
        f.write_all(&crc32fast::hash(&idx).to_le_bytes())
            .with_path(path)?;
        f.write_all(PACK_MAGIC).with_path(path)?;
        f.sync_all().with_path(path)
    }

    /// Read the index at the end of the pack `path`, checking its trailer, its checksum and
    /// that every frame lies in the data before it.
    pub fn read(path: &Path) -> Result<PackIndex> {
        use std::io::{Read, Seek, SeekFrom};
        let bad = |why: &str| Error::input(path, format!("damaged ingest pack: {why}"));
        let mut f = std::fs::File::open(path).with_path(path)?;
        let len = f.metadata().with_path(path)?.len();
        if len < 20 {
            return Err(bad("shorter than its trailer"));
        }
        let mut tail = [0u8; 20];
        f.seek(SeekFrom::Start(len - 20)).with_path(path)?;
        f.read_exact(&mut tail).with_path(path)?;
        if &tail[12..] != PACK_MAGIC {
            return Err(bad("no trailer"));
        }
        let n = u64::from_le_bytes(tail[..8].try_into().unwrap_or_default());
        let crc = u32::from_le_bytes(tail[8..12].try_into().unwrap_or_default());
        let data_end = len
            .checked_sub(20 + n)
            .ok_or_else(|| bad("index longer than the file"))?;
        let mut idx = vec![0u8; n as usize];
        f.seek(SeekFrom::Start(data_end)).with_path(path)?;
        f.read_exact(&mut idx).with_path(path)?;
        if crc32fast::hash(&idx) != crc {
            return Err(bad("index checksum mismatch"));
        }
        let mut r = LeReader::raw(&idx);
        let mut cells = Vec::new();
        let ncells = r.u64().ok_or_else(|| bad("truncated index"))?;
        for _ in 0..ncells {
            let c = (|| {
                let (cell, count) = (r.u32()?, r.u64()?);
                let mut v = [0f64; 6];
                for x in &mut v {
                    *x = r.f64()?;
                }
                let mut frames = Vec::new();
                for _ in 0..r.u64()? {
                    frames.push(Frame {
                        offset: r.u64()?,
                        len: r.u32()?,
                        crc32: r.u32()?,
                    });
                }
                Some(PackCell {
                    cell,
                    count,
                    bounds: Aabb {
                        min: [v[0], v[1], v[2]],
                        max: [v[3], v[4], v[5]],
                    },
                    frames,
                })
            })()
            .ok_or_else(|| bad("truncated index"))?;
            if c.frames.iter().any(|f| f.offset + f.len as u64 > data_end) {
                return Err(bad("a frame lies beyond the data"));
            }
            cells.push(c);
        }
        if !r.at_end() {
            return Err(bad("bytes after the index"));
        }
        Ok(PackIndex { cells })
    }
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
            cells.push(CellOut::new(key, file));
        }
        Ok(Scatter {
            layout,
            cells,
            buffered: 0,
            cap: cap_bytes.max(FRAME_BYTES),
            zstd_level,
            writer: FrameWriter::start()?,
            pack: None,
        })
    }

    /// Cells `keys` whose frames all go to the one file `pack` (created, or truncated), in
    /// the order they are flushed; [`Scatter::finish`] then returns the pack's index, which
    /// the caller appends ([`PackIndex::append_to`]). A shard's scatter of some of the
    /// inputs' chunks, whose cells are assembled later from every shard's pack.
    pub fn packed(
        pack: &Path,
        keys: &[CellKey],
        layout: RecordLayout,
        cap_bytes: usize,
        zstd_level: i32,
    ) -> Result<Scatter> {
        std::fs::File::create(pack).with_path(pack)?;
        Ok(Scatter {
            layout,
            cells: keys
                .iter()
                .map(|&k| CellOut::new(k, pack.to_path_buf()))
                .collect(),
            buffered: 0,
            cap: cap_bytes.max(FRAME_BYTES),
            zstd_level,
            writer: FrameWriter::start()?,
            pack: Some(Pack {
                path: pack.to_path_buf(),
                ..Default::default()
            }),
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
        // Each frame's CRC-32 is taken beside its compression, in parallel, once.
        let frames: Vec<Result<(usize, Vec<u8>, u32)>> = pool.install(|| {
            jobs.par_iter()
                .map(|&(i, f)| {
                    let z = zstd::bulk::compress(f, level)
                        .map_err(|e| Error::Internal(format!("zstd compression failed: {e}")))?;
                    let crc = crc32fast::hash(&z);
                    Ok((i, z, crc))
                })
                .collect()
        });
        for compressed in frames {
            let (i, z, crc32) = compressed?;
            let c = &mut self.cells[i];
            c.wrote(z.len() as u64, crc32);
            let sent = match &mut self.pack {
                Some(p) => {
                    let frame = Frame {
                        offset: p.bytes,
                        len: z.len() as u32,
                        crc32,
                    };
                    p.frames.push((i as u32, frame));
                    p.bytes += z.len() as u64;
                    // One open file for every frame.
                    self.writer.send(usize::MAX, &p.path, z)
                }
                None => self.writer.send(i, &c.file, z),
            };
            if sent.is_err() {
                // The writer stopped on an error; finish() reports it.
                break;
            }
        }
        Ok(())
    }

    /// Flush everything and return the cells (and a pack's index).
    pub fn finish(mut self, pool: &rayon::ThreadPool) -> Result<Scattered> {
        self.flush(pool, 0)?;
        self.writer.finish()?;
        let pack = self.pack.take().map(|p| {
            let mut cells: Vec<PackCell> = self
                .cells
                .iter()
                .enumerate()
                .filter(|(_, c)| c.count > 0)
                .map(|(i, c)| PackCell {
                    cell: i as u32,
                    count: c.count,
                    bounds: c.bounds,
                    frames: Vec::new(),
                })
                .collect();
            let mut at = vec![u32::MAX; self.cells.len()];
            for (k, c) in cells.iter().enumerate() {
                at[c.cell as usize] = k as u32;
            }
            for (i, f) in p.frames {
                cells[at[i as usize] as usize].frames.push(f);
            }
            PackIndex { cells }
        });
        Ok(Scattered {
            cells: self.cells,
            pack,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::Attributes;

    #[test]
    fn a_pack_holds_each_cells_frames_in_order_and_damage_is_refused() {
        let d = tempfile::tempdir().unwrap();
        let pack = d.path().join("0.pack");
        let layout = RecordLayout::new(Attributes::default(), false);
        let keys: Vec<CellKey> = (0..3).map(|i| CellKey::ROOT.child(i)).collect();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        // A tiny cap: every push flushes, so cells get several frames, interleaved.
        let mut sc = Scatter::packed(&pack, &keys, layout, 0, 1).unwrap();
        sc.cap = 24;
        let mut want: Vec<Vec<f64>> = vec![Vec::new(); 3];
        for chunk in 0..4 {
            let b = PointBatch {
                pos: (0..6).map(|i| [(chunk * 6 + i) as f64, 0.0, 0.0]).collect(),
                ..Default::default()
            };
            let leaf = [2, 0, 2, 0, 0, 2];
            for (i, &l) in leaf.iter().enumerate() {
                want[l as usize].push(b.pos[i][0]);
            }
            let mut g = Grouped::default();
            group(&b, &leaf, 3, &layout, &mut g);
            sc.push(&pool, &g).unwrap();
        }
        let idx = sc.finish(&pool).unwrap().pack.unwrap();
        idx.append_to(&pack).unwrap();
        let back = PackIndex::read(&pack).unwrap();
        assert_eq!(back, idx);
        assert_eq!(
            back.cells.iter().map(|c| c.cell).collect::<Vec<_>>(),
            [0, 2]
        );
        let bytes = std::fs::read(&pack).unwrap();
        for c in &back.cells {
            assert!(c.frames.len() > 1, "cell {} in one frame", c.cell);
            let mut got = PointBatch::default();
            for f in &c.frames {
                let z = &bytes[f.offset as usize..(f.offset + f.len as u64) as usize];
                assert_eq!(crc32fast::hash(z), f.crc32);
                let raw = zstd::bulk::decompress(z, 1 << 20).unwrap();
                let mut part = PointBatch::default();
                layout.decode(&raw, &mut part);
                got.pos.extend(part.pos);
            }
            let xs: Vec<f64> = got.pos.iter().map(|p| p[0]).collect();
            assert_eq!(xs, want[c.cell as usize]);
            assert_eq!(c.count as usize, xs.len());
        }
        // Truncated, or a byte of the index changed: refused, naming the pack.
        for damage in [bytes.len() - 1, bytes.len() - 30] {
            let mut b = bytes.clone();
            if damage == bytes.len() - 1 {
                b.truncate(damage);
            } else {
                b[damage] ^= 1;
            }
            std::fs::write(&pack, &b).unwrap();
            let e = PackIndex::read(&pack).unwrap_err().to_string();
            assert!(e.contains("0.pack") && e.contains("damaged"), "{e}");
        }
    }

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
