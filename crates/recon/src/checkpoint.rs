//! The work directory's checkpoint formats: the coarse pass's results (`SFCOARS3`), a split
//! run's chunks of the coarse pass's parts (`SFDPART1`, `SFSPART3`), a leaf's detail
//! (`SFLEAF03`) and a tile's mesh (`SFTILE07`, positions relative to the cube's lower
//! corner), all zstd-compressed little-endian records written atomically, so that a killed
//! run leaves each file whole or absent and a resumed run reuses what it finds.

use std::borrow::Cow;
use std::io::Write;
use std::path::{Path, PathBuf};

use super::density::DensityBox;
use super::grid::SplatBox;
use super::noise::{JetStats, NoiseStats, PairStats};
use super::screen::{SCREEN_PART_ENTRY_BYTES, ScreenPart};
use crate::error::{Error, IoContext, Result, Setting};
use crate::fs::atomic::{self, Durability};
use crate::fs::le::{LeReader, LeWriter};
use crate::types::{CellKey, Detail, EdgeKey, MAX_SHIFT, TileMesh};

/// zstd level of checkpoints: the fastest, since they are read back once.
const ZSTD_LEVEL: i32 = 1;

/// Leaf checkpoints: this magic, the cell key, the iso sum (f64) and count (u64), the detail's
/// exponent (u32) and a flag (u32: 1 with a detail), then the detail's 16-bit values
/// ([`quantise_detail`], padded to even), all little-endian, zstd-compressed.
const LEAF_MAGIC: &[u8; 8] = b"SFLEAF03";
/// Bytes of a leaf checkpoint's header: magic (8), key (8), iso sum (8), iso count (8),
/// exponent (4), detail flag (4).
const LEAF_HEADER: usize = 40;

/// The checkpoint of leaf `key` in directory `dir`.
pub fn leaf_path(dir: &Path, key: CellKey) -> PathBuf {
    dir.join(format!("{}.zst", key.file_name()))
}

/// Values of a detail grid of `m³` nodes, padded to even.
fn detail_len(m: usize) -> usize {
    let n = m * m * m;
    n + n % 2
}

/// What a leaf checkpoint holds, as the leaf's solve made it: its detail grid in the
/// blend's fixed point (none for a leaf left to the coarse solution) and its share of the
/// iso-value.
#[derive(Debug)]
pub struct LeafDetail {
    /// The detail, `detail_n³` nodes (none: the leaf is left to the coarse solution).
    pub detail: Option<Detail>,
    /// Sum of the field at the cell's samples.
    pub iso_sum: f64,
    /// Number of the cell's samples.
    pub iso_count: u64,
    /// Conjugate-gradient iterations of the leaf's screened fine solve (0 for a leaf left to
    /// the coarse solution, or read back from a checkpoint).
    pub iterations: u32,
}

/// Checkpoint leaf `key`'s detail `d` in directory `dir`.
pub fn write_leaf(dir: &Path, key: CellKey, d: &LeafDetail) -> Result<()> {
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
    let z = zstd::bulk::compress(&raw, ZSTD_LEVEL)
        .map_err(|e| Error::Internal(format!("zstd compression failed: {e}")))?;
    // Renamed, not synced: a checkpoint lost to a crash is solved again.
    atomic::write(&leaf_path(dir, key), &z, Durability::Renamed)
}

/// Read back leaf `key`'s checkpoint from `dir`, for a detail grid of `m³` nodes.
pub fn read_leaf(dir: &Path, key: CellKey, m: usize) -> Result<LeafDetail> {
    let path = leaf_path(dir, key);
    let z = std::fs::read(&path).with_path(&path)?;
    let n = detail_len(m);
    let raw = zstd::bulk::decompress(&z, LEAF_HEADER + n * 2 + 16)
        .map_err(|e| Error::input(&path, format!("corrupt leaf checkpoint: {e}")))?;
    let h = leaf_header(&path, &raw, key)?;
    let want = LEAF_HEADER + if h.has_detail { n * 2 } else { 0 };
    if raw.len() != want {
        return Err(Error::input(
            &path,
            format!(
                "corrupt leaf checkpoint: {} bytes, expected {want}",
                raw.len()
            ),
        ));
    }
    let detail = h.has_detail.then(|| Detail {
        values: raw[LEAF_HEADER..]
            .chunks_exact(2)
            .map(|b| i16::from_le_bytes([b[0], b[1]]))
            .collect(),
        shift: h.shift,
    });
    Ok(LeafDetail {
        detail,
        iso_sum: h.iso_sum,
        iso_count: h.iso_count,
        iterations: 0,
    })
}

/// What a leaf checkpoint's header says.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LeafSummary {
    /// Sum of the leaf's field at its samples.
    pub iso_sum: f64,
    /// Samples summed.
    pub iso_count: u64,
    /// Whether the leaf was refined (its checkpoint holds a detail).
    pub has_detail: bool,
    /// The detail's exponent.
    shift: u32,
}

/// Leaf `key`'s checkpoint in `dir` read as far as its header: its iso sum and count and
/// whether it holds a detail (the detail itself is checked where the tiles read it).
pub fn read_leaf_summary(dir: &Path, key: CellKey) -> Result<LeafSummary> {
    use std::io::Read;
    let path = leaf_path(dir, key);
    let f = std::fs::File::open(&path).with_path(&path)?;
    let mut raw = Vec::with_capacity(LEAF_HEADER);
    zstd::stream::read::Decoder::new(f)
        .with_path(&path)?
        .take(LEAF_HEADER as u64)
        .read_to_end(&mut raw)
        .map_err(|e| Error::input(&path, format!("corrupt leaf checkpoint: {e}")))?;
    leaf_header(&path, &raw, key)
}

/// The header of leaf `key`'s checkpoint `path`, from its decompressed bytes `raw` (the
/// header at least).
fn leaf_header(path: &Path, raw: &[u8], key: CellKey) -> Result<LeafSummary> {
    if raw.len() >= 8 && raw[..6] == LEAF_MAGIC[..6] && raw[..8] != LEAF_MAGIC[..] {
        return Err(Error::input(
            path,
            format!(
                "leaf checkpoint written by another version of scanflow ({}; this one reads {}): run again without {} in a new work directory",
                String::from_utf8_lossy(&raw[..8]),
                String::from_utf8_lossy(LEAF_MAGIC),
                Setting::Resume
            ),
        ));
    }
    if raw.len() < LEAF_HEADER || raw[..8] != LEAF_MAGIC[..] {
        return Err(Error::input(
            path,
            "corrupt leaf checkpoint: wrong size or magic",
        ));
    }
    let u32_at = |o: usize| u32::from_le_bytes([raw[o], raw[o + 1], raw[o + 2], raw[o + 3]]);
    let u64_at = |o: usize| {
        let mut a = [0u8; 8];
        a.copy_from_slice(&raw[o..o + 8]);
        u64::from_le_bytes(a)
    };
    let (shift, has) = (u32_at(32), u32_at(36));
    if has > 1 || shift > MAX_SHIFT {
        return Err(Error::input(
            path,
            format!(
                "corrupt leaf checkpoint: detail flag {has} and exponent {shift}, expected 0 or 1 and an exponent of at most {MAX_SHIFT}"
            ),
        ));
    }
    if u64_at(8) != key.0 {
        return Err(Error::input(path, "leaf checkpoint of another cell"));
    }
    Ok(LeafSummary {
        iso_sum: f64::from_bits(u64_at(16)),
        iso_count: u64_at(24),
        has_detail: has == 1,
        shift,
    })
}

/// The detail of refined leaf `key` (the tile stage reads only those).
pub fn leaf_detail(dir: &Path, key: CellKey, m: usize) -> Result<Detail> {
    read_leaf(dir, key, m)?.detail.ok_or_else(|| {
        Error::input(
            leaf_path(dir, key),
            "leaf checkpoint without a detail, where the run refined this leaf",
        )
    })
}

/// Tile checkpoints: this magic, then the counts of vertices, triangles, colours,
/// intensities and densities (u64 each), then the records ([`write_tile`]).
const TILE_MAGIC: &[u8; 8] = b"SFTILE08";
/// Bytes of a tile checkpoint's header: magic and five counts.
const TILE_HEADER: usize = 48;
/// Bytes of a tile checkpoint's vertex: edge key (u64) and position (f64×3).
const TILE_VERTEX_BYTES: usize = 32;
/// Bytes of a tile checkpoint's triangle: three u32 indices.
const TILE_TRIANGLE_BYTES: usize = 12;

/// The checkpoint of tile `t` (its Morton index) in directory `dir`.
pub fn tile_path(dir: &Path, t: u64) -> PathBuf {
    dir.join(format!("{t:016x}.zst"))
}

/// Checkpoint a tile's mesh (after trimming): edge keys, f64 positions, triangles, then the
/// vertex colours, intensities and densities when there are any.
pub fn write_tile(path: &Path, m: &TileMesh) -> Result<()> {
    let mut raw = Vec::with_capacity(
        TILE_HEADER
            + m.keys.len() * (TILE_VERTEX_BYTES + 7)
            + m.triangles.len() * TILE_TRIANGLE_BYTES,
    );
    raw.extend_from_slice(TILE_MAGIC);
    raw.extend_from_slice(&(m.keys.len() as u64).to_le_bytes());
    raw.extend_from_slice(&(m.triangles.len() as u64).to_le_bytes());
    raw.extend_from_slice(&(m.colors.len() as u64).to_le_bytes());
    raw.extend_from_slice(&(m.intensity.len() as u64).to_le_bytes());
    raw.extend_from_slice(&(m.density.len() as u64).to_le_bytes());
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
    for v in m.intensity.iter().chain(&m.density) {
        raw.extend_from_slice(&v.to_le_bytes());
    }
    let z = zstd::bulk::compress(&raw, ZSTD_LEVEL)
        .map_err(|e| Error::Internal(format!("zstd compression failed: {e}")))?;
    atomic::write(path, &z, Durability::Renamed)
}

/// Read back a tile checkpoint written by [`write_tile`].
pub fn read_tile(path: &Path) -> Result<TileMesh> {
    let z = std::fs::read(path).with_path(path)?;
    let bad = |what: &str| Error::input(path, format!("corrupt tile checkpoint: {what}"));
    let raw = zstd::stream::decode_all(&z[..]).map_err(|e| bad(&e.to_string()))?;
    if raw.len() >= 8 && raw[..6] == TILE_MAGIC[..6] && raw[..8] != TILE_MAGIC[..] {
        return Err(Error::input(
            path,
            format!(
                "tile checkpoint written by another version of scanflow ({}; this one reads {}): run again without {} in a new work directory",
                String::from_utf8_lossy(&raw[..8]),
                String::from_utf8_lossy(TILE_MAGIC),
                Setting::Resume
            ),
        ));
    }
    if raw.len() < TILE_HEADER || &raw[..8] != TILE_MAGIC {
        return Err(bad("wrong magic"));
    }
    let u64_at = |o: usize| {
        let mut a = [0u8; 8];
        a.copy_from_slice(&raw[o..o + 8]);
        u64::from_le_bytes(a)
    };
    let (nv, nt) = (u64_at(8) as usize, u64_at(16) as usize);
    let (nc, ni, nd) = (
        u64_at(24) as usize,
        u64_at(32) as usize,
        u64_at(40) as usize,
    );
    if [nc, ni, nd].iter().any(|&n| !(n == 0 || n == nv))
        || raw.len()
            != TILE_HEADER
                + nv * TILE_VERTEX_BYTES
                + nt * TILE_TRIANGLE_BYTES
                + nc * 3
                + (ni + nd) * 4
    {
        return Err(bad("wrong size"));
    }
    let mut m = TileMesh::default();
    let mut o = TILE_HEADER;
    for _ in 0..nv {
        m.keys.push(EdgeKey(u64_at(o)));
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
    let f32s = |b: &[u8]| -> Vec<f32> {
        b.chunks_exact(4)
            .map(|v| f32::from_le_bytes([v[0], v[1], v[2], v[3]]))
            .collect()
    };
    m.intensity = f32s(&raw[o..o + ni * 4]);
    m.density = f32s(&raw[o + ni * 4..]);
    Ok(m)
}

/// The coarse pass's checkpoint, a record of `fs::le` (zstd-compressed): this magic, the
/// coarse solve's iterations (u32) and the run's screening weight (f64), the noise
/// statistics (the within-voxel sums, then both jets' sums, degrees of freedom and fits),
/// then four arrays each after its length (u64): the coarse solution (f32), the sampling
/// density's counts (u32), the support's bits (u64) and the occupied leaf cells' keys (u64);
/// then the CRC-32 of all that.
const COARSE_MAGIC: &[u8; 8] = b"SFCOARS3";

/// The coarse pass's results, as a checkpoint holds them: the grids borrowed when written,
/// owned when read back.
#[derive(Debug, Clone, PartialEq)]
pub struct CoarseCheckpoint<'a> {
    /// Conjugate-gradient iterations of the coarse solve.
    pub iterations: u32,
    /// The screening weight the run settled on.
    pub point_weight: f64,
    /// The samples' noise.
    pub noise: NoiseStats,
    /// The coarse solution's node values.
    pub field: Cow<'a, [f32]>,
    /// The sampling density's counts.
    pub density: Cow<'a, [u32]>,
    /// The coarse voxels holding points, as bits.
    pub support: Cow<'a, [u64]>,
    /// The finest level's occupied leaf cells, in Morton order.
    pub occupied: Vec<CellKey>,
}

/// The coarse pass's checkpoint in the leaf checkpoints' directory `dir`: removed with them
/// when the plan changes, reused when they are.
pub fn coarse_path(dir: &Path) -> PathBuf {
    dir.join("coarse.zst")
}

/// Checkpoint the coarse pass's results `c` at `path`, compressed as they are written (no
/// copy of the grids beside them).
pub fn write_coarse(path: &Path, c: &CoarseCheckpoint) -> Result<()> {
    let zerr = |e: std::io::Error| Error::Internal(format!("zstd compression failed: {e}"));
    let mut z = zstd::stream::Encoder::new(Vec::new(), ZSTD_LEVEL).map_err(zerr)?;
    // The record of `fs::le`, its CRC-32 taken as the bytes stream through.
    let mut crc = crc32fast::Hasher::new();
    let mut put = |b: &[u8]| {
        crc.update(b);
        z.write_all(b).map_err(zerr)
    };
    put(COARSE_MAGIC)?;
    put(&c.iterations.to_le_bytes())?;
    put(&c.point_weight.to_le_bytes())?;
    // The noise as `put_noise` lays it out for the split parts, so the two cannot drift.
    let mut noise = LeWriter::default();
    put_noise(&mut noise, &c.noise);
    put(&noise.bytes)?;
    put(&(c.field.len() as u64).to_le_bytes())?;
    for v in c.field.iter() {
        put(&v.to_le_bytes())?;
    }
    put(&(c.density.len() as u64).to_le_bytes())?;
    for v in c.density.iter() {
        put(&v.to_le_bytes())?;
    }
    put(&(c.support.len() as u64).to_le_bytes())?;
    for v in c.support.iter() {
        put(&v.to_le_bytes())?;
    }
    put(&(c.occupied.len() as u64).to_le_bytes())?;
    for k in &c.occupied {
        put(&k.0.to_le_bytes())?;
    }
    z.write_all(&crc.finalize().to_le_bytes()).map_err(zerr)?;
    let z = z.finish().map_err(zerr)?;
    atomic::write(path, &z, Durability::Renamed)
}

/// Read back the coarse checkpoint at `path` ([`write_coarse`]); `None` when there is none.
pub fn read_coarse(path: &Path) -> Result<Option<CoarseCheckpoint<'static>>> {
    let z = match std::fs::read(path) {
        Ok(z) => z,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(Error::io(path, e)),
    };
    let bad = |what: &str| Error::input(path, format!("corrupt coarse checkpoint: {what}"));
    let raw = zstd::stream::decode_all(&z[..]).map_err(|e| bad(&e.to_string()))?;
    let mut r = LeReader::open(&raw, COARSE_MAGIC)
        .ok_or_else(|| bad("wrong magic or checksum (cut short, or not this format)"))?;
    let short = || bad("cut short");
    let iterations = r.u32().ok_or_else(short)?;
    let point_weight = r.f64().ok_or_else(short)?;
    let noise = get_noise(&mut r).ok_or_else(short)?;
    // Each array after its length; a length past the record's end stops at its end.
    fn array<'a, T>(
        r: &mut LeReader<'a>,
        mut next: impl FnMut(&mut LeReader<'a>) -> Option<T>,
    ) -> Option<Vec<T>> {
        let n = r.u64()?;
        (0..n).map(|_| next(r)).collect()
    }
    let field = array(&mut r, LeReader::f32).ok_or_else(short)?;
    let density = array(&mut r, LeReader::u32).ok_or_else(short)?;
    let support = array(&mut r, LeReader::u64).ok_or_else(short)?;
    let occupied = array(&mut r, |r| r.u64().map(CellKey)).ok_or_else(short)?;
    if !r.at_end() {
        return Err(bad("bytes after the end"));
    }
    Ok(Some(CoarseCheckpoint {
        iterations,
        point_weight,
        noise,
        field: Cow::Owned(field),
        density: Cow::Owned(density),
        support: Cow::Owned(support),
        occupied,
    }))
}

/// A split run's share of the coarse pass for a chunk of store cells, one of two kinds:
/// the cells' density parts (`SFDPART1`, [`write_density_parts`]) or their splats
/// (`SFSPART3`, [`write_splat_parts`]), each in the leaf checkpoints' directory `dir`.
pub fn coarse_part_path(dir: &Path, kind: CoarsePartKind, chunk: usize) -> PathBuf {
    dir.join(format!("coarse-{}-{chunk:06}.zst", kind.name()))
}

/// The two passes over the store whose parts a split run checkpoints.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CoarsePartKind {
    /// The sampling density ([`DensityBox`]).
    Density,
    /// The splat, the screening's samples and what the coarse pass measures ([`CellSplat`]).
    Splat,
}

impl CoarsePartKind {
    /// The pass's name, as its progress stage shows it.
    pub fn name(self) -> &'static str {
        match self {
            CoarsePartKind::Density => "density",
            CoarsePartKind::Splat => "splat",
        }
    }
}

/// A store cell's share of the coarse pass's splat: its points, its splat and screening
/// aggregates apart from the grids, its noise statistics and moments, and the coarse
/// voxels (support indices) and finest leaves it occupies. The pass adds the cells' shares
/// in cell order, wherever they were computed (`pipeline::reconstruct`).
#[derive(Debug, Clone, PartialEq)]
pub struct CellSplat {
    /// The splat of the weighed normals.
    pub splat: SplatBox,
    /// The screening's aggregates (none when the run does not screen).
    pub screen: ScreenPart,
    /// The noise statistics (zero for the cells not sampled).
    pub noise: NoiseStats,
    /// The points' moments' sums ([`crate::coarse::Moments::sums`]).
    pub moments: [f64; 10],
    /// The coarse voxels holding points, ascending, each once.
    pub marks: Vec<u64>,
    /// The finest level's occupied leaf cells, ascending, each once.
    pub leaves: Vec<CellKey>,
}

impl CellSplat {
    /// Bytes the share holds: its grids and lists, and the share itself (most of it the
    /// noise statistics' pair bins, [`crate::noise::PairStats`]).
    pub fn bytes(&self) -> u64 {
        self.splat.bytes()
            + SCREEN_PART_ENTRY_BYTES * self.screen.len() as u64
            + 8 * (self.marks.len() + self.leaves.len()) as u64
            + std::mem::size_of::<Self>() as u64
    }
}

/// `SFDPART1`: the cell count (u64), then per cell its [`DensityBox`]: `lo` and `dims` (u64
/// each axis) and the counts (u32); then the CRC-32 of all that; zstd-compressed.
const DENSITY_PARTS_MAGIC: &[u8; 8] = b"SFDPART1";

/// `SFSPART3`: the cell count (u64), then per cell ([`CellSplat`]): the splat's `lo` (i64 as
/// u64) and `dims` (u64) per axis and its values (3 f32 a node); the screening's entry count
/// (u64) and entries (key u64, the offsets' sums 3 f64, count u64); the noise statistics (as
/// in `SFCOARS3`); the moments' 10 sums (f64); the marks' and the leaves' counts (u64) and
/// values (u64); then the CRC-32; zstd-compressed.
const SPLAT_PARTS_MAGIC: &[u8; 8] = b"SFSPART3";

/// Write the density parts of a chunk's cells to `path`.
pub fn write_density_parts(path: &Path, parts: &[DensityBox]) -> Result<()> {
    let mut w = LeWriter::new(DENSITY_PARTS_MAGIC);
    w.u64(parts.len() as u64);
    for b in parts {
        b.lo.iter().chain(&b.dims).for_each(|&v| w.u64(v as u64));
        b.counts.iter().for_each(|&c| w.u32(c));
    }
    write_record(path, w)
}

/// Read back the density parts at `path` ([`write_density_parts`]).
pub fn read_density_parts(path: &Path) -> Result<Vec<DensityBox>> {
    read_parts(path, DENSITY_PARTS_MAGIC, |r| {
        let mut v = [0usize; 6];
        for x in &mut v {
            *x = usize::try_from(r.u64()?).ok()?;
        }
        let dims = [v[3], v[4], v[5]];
        let nodes = dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d))?;
        let counts = (0..nodes).map(|_| r.u32()).collect::<Option<Vec<u32>>>()?;
        Some(DensityBox {
            lo: [v[0], v[1], v[2]],
            dims,
            counts,
        })
    })
}

/// The parts of the record at `path` (`magic`, a count, then each part as `one` reads it).
fn read_parts<P>(
    path: &Path,
    magic: &[u8],
    mut one: impl FnMut(&mut LeReader) -> Option<P>,
) -> Result<Vec<P>> {
    let z = std::fs::read(path).with_path(path)?;
    let bad = |what: &str| Error::input(path, format!("corrupt coarse pass part: {what}"));
    let raw = zstd::stream::decode_all(&z[..]).map_err(|e| bad(&e.to_string()))?;
    let mut r = LeReader::open(&raw, magic)
        .ok_or_else(|| bad("wrong magic or checksum (cut short, or not this format)"))?;
    let parts = (|| {
        let cells = r.u64()?;
        (0..cells).map(|_| one(&mut r)).collect::<Option<Vec<P>>>()
    })()
    .ok_or_else(|| bad("cut short"))?;
    if !r.at_end() {
        return Err(bad("bytes after the end"));
    }
    Ok(parts)
}

/// Write the splat shares of a chunk's cells to `path`.
pub fn write_splat_parts(path: &Path, parts: &[CellSplat]) -> Result<()> {
    let mut w = LeWriter::new(SPLAT_PARTS_MAGIC);
    w.u64(parts.len() as u64);
    for c in parts {
        c.splat.lo.iter().for_each(|&v| w.u64(v as u64));
        c.splat.dims.iter().for_each(|&v| w.u64(v as u64));
        c.splat.values.iter().flatten().for_each(|&v| w.f32(v));
        w.u64(c.screen.len() as u64);
        for &(key, (sum, count)) in &c.screen {
            w.u64(key);
            sum.iter().for_each(|&v| w.f64(v));
            w.u64(count);
        }
        put_noise(&mut w, &c.noise);
        c.moments.iter().for_each(|&v| w.f64(v));
        for list in [
            &c.marks[..],
            &c.leaves.iter().map(|k| k.0).collect::<Vec<_>>()[..],
        ] {
            w.u64(list.len() as u64);
            list.iter().for_each(|&v| w.u64(v));
        }
    }
    write_record(path, w)
}

/// Read back the splat shares at `path` ([`write_splat_parts`]).
pub fn read_splat_parts(path: &Path) -> Result<Vec<CellSplat>> {
    read_parts(path, SPLAT_PARTS_MAGIC, |r| {
        let lo = [(); 3].map(|_| r.u64().map(|v| v as i64));
        let lo = [lo[0]?, lo[1]?, lo[2]?];
        let mut dims = [0usize; 3];
        for d in &mut dims {
            *d = usize::try_from(r.u64()?).ok()?;
        }
        let nodes = dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d))?;
        let values = (0..nodes)
            .map(|_| Some([r.f32()?, r.f32()?, r.f32()?]))
            .collect::<Option<Vec<_>>>()?;
        let entries = r.u64()?;
        let screen = (0..entries)
            .map(|_| Some((r.u64()?, ([r.f64()?, r.f64()?, r.f64()?], r.u64()?))))
            .collect::<Option<ScreenPart>>()?;
        let noise = get_noise(r)?;
        let mut moments = [0f64; 10];
        for m in &mut moments {
            *m = r.f64()?;
        }
        let mut list = || {
            let n = r.u64()?;
            (0..n).map(|_| r.u64()).collect::<Option<Vec<u64>>>()
        };
        let marks = list()?;
        let leaves = list()?.into_iter().map(CellKey).collect();
        Some(CellSplat {
            splat: SplatBox { lo, dims, values },
            screen,
            noise,
            moments,
            marks,
            leaves,
        })
    })
}

/// The noise statistics as `SFCOARS3` and `SFSPART3` hold them.
fn put_noise(w: &mut LeWriter, n: &NoiseStats) {
    w.f64(n.sum_sq);
    w.u64(n.dof);
    for j in &n.jets {
        w.f64(j.sum_sq);
        w.u64(j.dof);
        w.u64(j.fits);
    }
    for x in n.pairs.bins.iter().flatten().flatten() {
        w.f64(*x);
    }
}

/// Read back [`put_noise`]'s statistics.
fn get_noise(r: &mut LeReader) -> Option<NoiseStats> {
    let mut noise = NoiseStats {
        sum_sq: r.f64()?,
        dof: r.u64()?,
        jets: [JetStats::default(); 2],
        pairs: PairStats::default(),
    };
    for j in &mut noise.jets {
        j.sum_sq = r.f64()?;
        j.dof = r.u64()?;
        j.fits = r.u64()?;
    }
    for x in noise.pairs.bins.iter_mut().flatten().flatten() {
        *x = r.f64()?;
    }
    Some(noise)
}

/// Compress the record `w` and write it to `path` atomically.
fn write_record(path: &Path, w: LeWriter) -> Result<()> {
    let z = zstd::bulk::compress(&w.finish(), ZSTD_LEVEL)
        .map_err(|e| Error::Internal(format!("zstd compression failed: {e}")))?;
    atomic::write(path, &z, Durability::Renamed)
}

#[cfg(test)]
mod tests;
