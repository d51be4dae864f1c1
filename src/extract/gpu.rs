//! Marching cubes on the GPU (wgpu compute, WGSL in `shaders/`), one tile at a time, giving
//! exactly the mesh of [`cpu::marching_cubes`]: the same keys in the same order, bitwise the
//! same positions, the same triangles.
//!
//! After Timokhin & Mikhaylyuk, "GPU-based marching cubes with tessellation-generated threads"
//! (2020): only active cells get threads, and no vertex is stored twice. Their OpenGL
//! mechanism (tessellation-generated threads) is replaced by prefix sums, which fix every
//! output position without atomics, so the output does not depend on thread timing.
//!
//! # Passes (per sub-block, see below)
//!
//! 1. `classify.wgsl`, a thread per node: the case of the cell whose lowest corner it is, and
//!    its counts: active (0 or 1), triangles, and *new* vertices: the crossing edges whose
//!    first cell, in cell order, it is (the cell one step lower across the edge, unless the
//!    edge lies on the block's lower face).
//! 2. `scan.wgsl`: exclusive prefix sums of the three counts, a workgroup scan of 1024 items
//!    plus block sums, recursively. The totals (vertices, active cells, triangles) are read
//!    back (16 bytes) to size the outputs exactly.
//! 3. `compact.wgsl`, a thread per node: the list of active cells, in cell order.
//! 4. `emit.wgsl` `vertices`, a thread per *active* cell: one record per new vertex, its
//!    block-local edge id, cell by cell and within a cell in the order of
//!    [`tables::case_edges`]: the CPU kernel's order of first use.
//! 5. `emit.wgsl` `triangles`, a thread per active cell: its triangles in the order of the
//!    case table, as indices into the records, found in each edge's first cell.
//!
//! Only the records (4 bytes a vertex) and the triangles (12 bytes each) are read back.
//!
//! # Blended tiles: the field built on the device
//!
//! [`GpuExtractor::extract_blend`] takes a tile as a partition-of-unity blend
//! ([`super::field`]) instead of node values. The leaves' detail grids go to a pool of slots
//! in one device buffer, least recently used replaced first, so a leaf shared by neighbouring
//! tiles crosses the bus once while it stays resident; with them go the coarse values around
//! the tile, per-axis tables and a lookup box from leaf cell to slot. Pass 0 (`field.wgsl`, a
//! thread per node) blends the values into the buffer pass 1 reads, in exact 64-bit integer
//! arithmetic, so they are [`Blend::eval`]'s bit for bit. As the host then has no node values,
//! pass 4 also writes the bits of each vertex's two node values (8 more bytes a vertex read
//! back) for the host's position formula. Adapters without 64-bit integers in shaders
//! (`wgpu::Features::SHADER_INT64`), and tiles whose leaves exceed the pool's limit, are
//! blended on the host and uploaded as above.
//!
//! Whether it pays depends on the bytes: a leaf grid is `(1.5·E + 1)³` values of 16 bits
//! ([`crate::types::Detail`]) for a cell of `E³` nodes of 32 bits, 1.7 times the
//! cell's dense values, so it pays where leaves cover less than about 60% of a tile (a
//! surface through a large tile) and where leaves are already resident
//! (`benches/extract.rs` prints the bytes sent against the dense tile's); it also saves the
//! host's blend.
//!
//! # Why the host finishes the job
//!
//! The GPU decides the topology and the numbering: cases, which edges carry vertices, in
//! which order, triangles. Classification compares bit patterns (`classify.wgsl`), so no
//! float mode of the GPU can change a case. Positions are computed on the host (in parallel,
//! with rayon) from the record and the two node values with the one `f64` formula the CPU
//! kernel uses (`cpu::edge_vertex`), so they are bitwise the same; no GPU float division is
//! involved.
//!
//! # Sub-blocks
//!
//! The device is opened with the adapter's own limits (not wgpu's defaults). A tile whose node
//! counts (16 bytes a node) would exceed the largest buffer or storage binding is cut into
//! sub-blocks that share a face of nodes: slabs of whole z-layers of cells; if one layer is too
//! large, bands of whole rows of one layer; if one row is too large, runs of one row. A
//! sub-block whose triangles turn out too large (known after pass 2) is halved the same way
//! and redone. In that order the sub-blocks' triangle lists concatenate to the tile's cell
//! order; records of edges on shared faces are flagged, and matched by edge to the vertex an
//! earlier sub-block made, so the mesh is the one of the whole tile.
//! [`GpuExtractor::set_max_buffer_bytes`] lowers the limit (tests use it to force many
//! sub-blocks).
//!
//! # Failures
//!
//! Out of memory, validation or internal errors, a lost device or a panic inside wgpu on a
//! tile: the tile is extracted on the CPU instead, with a `log::warn!`, and the output is the
//! same. After a lost device or a panic, later tiles go to the CPU directly.

use std::collections::{HashMap, VecDeque};
use std::fmt;
use std::str::FromStr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::time::Instant;

use rayon::prelude::*;
use wgpu::util::DeviceExt;

use super::cpu::{self, McWorkspace};
use super::field::BlendEval;
use super::tables;
use crate::error::{Error, Result};
use crate::types::{Blend, EdgeKey, GridGeom, TileMesh};

/// Whether marching cubes runs on a GPU (`--gpu`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum GpuMode {
    /// A discrete or integrated GPU when wgpu finds one, else the CPU.
    #[default]
    Auto,
    /// The GPU path on any adapter, software ones (Mesa lavapipe) included; an error if none.
    On,
    /// The CPU only; wgpu is never initialised.
    Off,
}

impl FromStr for GpuMode {
    type Err = Error;

    fn from_str(s: &str) -> Result<GpuMode> {
        match s {
            "auto" => Ok(GpuMode::Auto),
            "on" => Ok(GpuMode::On),
            "off" => Ok(GpuMode::Off),
            _ => Err(Error::Usage(format!(
                "--gpu {s:?}: expected one of auto, on, off"
            ))),
        }
    }
}

impl fmt::Display for GpuMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            GpuMode::Auto => "auto",
            GpuMode::On => "on",
            GpuMode::Off => "off",
        })
    }
}

/// What one [`GpuExtractor::extract`] did, and where its time went.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct GpuStats {
    /// Wall time uploading node values, in seconds.
    pub upload_secs: f64,
    /// Wall time of the compute passes (submission to completion, totals read-back
    /// included), in seconds.
    pub kernel_secs: f64,
    /// Wall time reading back vertex records and triangles, in seconds.
    pub download_secs: f64,
    /// Wall time on the host turning them into the [`TileMesh`] (seams, keys, positions), in
    /// seconds; 0 when the tile fell back to the CPU.
    pub host_secs: f64,
    /// Cells of the block (with all 8 corners in it).
    pub cells: u64,
    /// Cells whose case is neither 0 nor 255.
    pub active_cells: u64,
    /// Sub-blocks the tile was cut into (0 when it had no cell or fell back).
    pub sub_blocks: u64,
    /// True when a GPU failure sent the tile to the CPU.
    pub fell_back: bool,
    /// Bytes sent to the device: node values, or for a blended tile
    /// ([`GpuExtractor::extract_blend`]) the leaf grids not yet resident and the tables.
    pub upload_bytes: u64,
    /// Leaf grids sent to the device (not resident yet) for a blended tile.
    pub leaves_sent: u64,
    /// True when a blended tile's field was built on the device.
    pub field_on_gpu: bool,
}

/// The names of the adapters wgpu finds (Vulkan, Metal, DirectX 12, or the backends named by
/// `WGPU_BACKEND`), with their type, for diagnostics and tests.
pub fn adapter_names() -> Vec<String> {
    let instance = make_instance();
    pollster::block_on(instance.enumerate_adapters(backends()))
        .iter()
        .map(|a| describe(&a.get_info()))
        .collect()
}

fn backends() -> wgpu::Backends {
    wgpu::Backends::from_env().unwrap_or(wgpu::Backends::PRIMARY)
}

fn make_instance() -> wgpu::Instance {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = backends();
    desc.flags = wgpu::InstanceFlags::empty().with_env();
    wgpu::Instance::new(desc)
}

fn describe(info: &wgpu::AdapterInfo) -> String {
    format!(
        "{} ({:?}, {:?}, {} {})",
        info.name, info.device_type, info.backend, info.driver, info.driver_info
    )
}

/// Preference among adapters: lower is better; `None` when `mode` does not take it.
fn rank(mode: GpuMode, t: wgpu::DeviceType) -> Option<u8> {
    use wgpu::DeviceType as T;
    match (mode, t) {
        (_, T::DiscreteGpu) => Some(0),
        (_, T::IntegratedGpu) => Some(1),
        (GpuMode::On, T::VirtualGpu) => Some(2),
        (GpuMode::On, T::Other) => Some(3),
        (GpuMode::On, T::Cpu) => Some(4),
        _ => None,
    }
}

/// Largest node count of a sub-block: keeps `3·nodes` edge ids below bit 30 (bit 31 flags
/// seams).
const MAX_BLOCK_NODES: u64 = 1 << 28;
/// Largest buffer used: `u32` indices address it in 4-byte words, and `3·triangles` fits.
const MAX_BUFFER_BYTES: u64 = (1 << 32) - 16;
/// Bytes one thread copies at a time to or from mapped memory.
const COPY_CHUNK: usize = 8 << 20;
/// Items one workgroup of `scan.wgsl` scans.
const SCAN_BLOCK: u64 = 1024;
/// Threads per workgroup of every shader.
const WG: u64 = 256;
/// Bit 31 of a vertex record: the edge lies on a face shared with another sub-block.
const SEAM: u32 = 1 << 31;
/// A record replaced by this matched a vertex of an earlier sub-block (no valid record is
/// this large).
const MATCHED: u32 = u32::MAX;
/// Layout of the tables buffer (`common.wgsl`): triangle-edge starts at 0, crossing-edge
/// starts at `USED_START`, case info at `CASE_INFO`, the edge lists from `TABLE_HEAD` on.
const USED_START: usize = 257;
const CASE_INFO: usize = 514;
const TABLE_HEAD: usize = 770;

/// A sub-block of a tile: node offset in the tile and node counts (at least 2 per axis).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct SubBlock {
    at: [usize; 3],
    dims: [usize; 3],
}

impl SubBlock {
    /// Faces shared with the rest of a tile of `tile` nodes: bit `2·axis` lower, `2·axis + 1`
    /// upper.
    fn seam_mask(&self, tile: [usize; 3]) -> u32 {
        (0..3).fold(0, |m, d| {
            m | (((self.at[d] > 0) as u32) << (2 * d))
                | (((self.at[d] + self.dims[d] < tile[d]) as u32) << (2 * d + 1))
        })
    }

    /// Halves along the outermost axis with more than one cell (z, then y, then x): a slab
    /// into slabs, a layer into bands, a band into bands, a row into runs, so that the halves
    /// keep the tile's cell order. `None` for a single cell.
    fn halve(&self) -> Option<(SubBlock, SubBlock)> {
        let d = (0..3).rev().find(|&d| self.dims[d] > 2)?;
        let cells = self.dims[d] - 1;
        let mut lo = *self;
        let mut hi = *self;
        lo.dims[d] = cells / 2 + 1;
        hi.at[d] += cells / 2;
        hi.dims[d] = cells - cells / 2 + 1;
        Some((lo, hi))
    }
}

/// Nodes of a sub-block of `c` cells per axis, and the bytes of its largest buffer known
/// before it runs: the counts, 16 bytes a node.
fn block_bytes(c: [usize; 3]) -> (u64, u64) {
    let nodes = c.iter().map(|&v| v as u64 + 1).product::<u64>();
    (nodes, 16 * nodes)
}

fn fits(c: [usize; 3], limit: u64) -> bool {
    let (nodes, bytes) = block_bytes(c);
    nodes <= MAX_BLOCK_NODES && bytes <= limit
}

/// The largest `k` in `1..=max` with `ok(k)`, given `ok(1)` and `ok` monotone.
fn largest(max: usize, ok: impl Fn(usize) -> bool) -> usize {
    let (mut lo, mut hi) = (1, max);
    while lo < hi {
        let mid = lo + (hi - lo).div_ceil(2);
        if ok(mid) { lo = mid } else { hi = mid - 1 }
    }
    lo
}

/// Cut a tile of `dims` nodes (at least 2 per axis) into sub-blocks whose counts fit `limit`
/// bytes, in an order whose concatenated cell orders give the tile's cell order (see the
/// [module docs](self)).
fn plan(dims: [usize; 3], limit: u64) -> std::result::Result<Vec<SubBlock>, String> {
    let c = dims.map(|d| d - 1);
    let mut out = Vec::new();
    if !fits([1, 1, 1], limit) {
        return Err(format!(
            "a buffer limit of {limit} bytes cannot hold one cell"
        ));
    }
    let sub = |at: [usize; 3], cells: [usize; 3]| SubBlock {
        at,
        dims: cells.map(|v| v + 1),
    };
    if fits([c[0], c[1], 1], limit) {
        let bz = largest(c[2], |k| fits([c[0], c[1], k], limit));
        for z in (0..c[2]).step_by(bz) {
            out.push(sub([0, 0, z], [c[0], c[1], bz.min(c[2] - z)]));
        }
    } else if fits([c[0], 1, 1], limit) {
        let by = largest(c[1], |k| fits([c[0], k, 1], limit));
        for z in 0..c[2] {
            for y in (0..c[1]).step_by(by) {
                out.push(sub([0, y, z], [c[0], by.min(c[1] - y), 1]));
            }
        }
    } else {
        let bx = largest(c[0], |k| fits([k, 1, 1], limit));
        for z in 0..c[2] {
            for y in 0..c[1] {
                for x in (0..c[0]).step_by(bx) {
                    out.push(sub([x, y, z], [bx.min(c[0] - x), 1, 1]));
                }
            }
        }
    }
    Ok(out)
}

/// The case tables as one array of words (layout in `common.wgsl`).
fn table_words() -> Vec<u32> {
    let (tri_start, tri_edges) = tables::flat_table();
    let mut used = Vec::new();
    let mut used_start = Vec::with_capacity(257);
    for case in 0..=255u8 {
        used_start.push(used.len());
        used.extend(tables::case_edges(case).iter().map(|&e| e as u32));
    }
    used_start.push(used.len());
    let tri_base = TABLE_HEAD;
    let used_base = tri_base + tri_edges.len();
    let mut w = Vec::with_capacity(used_base + used.len());
    w.extend(tri_start.iter().map(|&s| (tri_base + s as usize) as u32));
    debug_assert_eq!(w.len(), USED_START);
    w.extend(used_start.iter().map(|&s| (used_base + s) as u32));
    debug_assert_eq!(w.len(), CASE_INFO);
    for case in 0..=255u8 {
        let c = case as usize;
        let tris = (tri_start[c + 1] - tri_start[c]) / 3;
        w.push(tris | (tables::crossing_edges(case) as u32) << 4);
    }
    debug_assert_eq!(w.len(), TABLE_HEAD);
    w.extend(tri_edges.iter().map(|&e| e as u32));
    w.extend(used);
    w
}

/// `(groups_x, groups_y)` of a 2D dispatch grid with at least `groups` workgroups, each
/// dimension at most `max_dim`.
fn grid(groups: u64, max_dim: u32) -> (u32, u32) {
    let gx = groups.clamp(1, max_dim as u64);
    (gx as u32, groups.div_ceil(gx).max(1) as u32)
}

/// The order-preserving key of `classify.wgsl` for the iso-value (NaN: 0, so nothing is
/// inside, as on the CPU).
fn iso_key(iso: f32) -> u32 {
    if iso.is_nan() {
        return 0;
    }
    let b = if iso == 0.0 { 0 } else { iso.to_bits() };
    if b & 0x8000_0000 != 0 {
        !b
    } else {
        b | 0x8000_0000
    }
}

/// The compute pipelines, created once.
struct Pipelines {
    /// `None` without 64-bit integers in shaders: blended tiles are blended on the host.
    field: Option<wgpu::ComputePipeline>,
    classify: wgpu::ComputePipeline,
    scan: wgpu::ComputePipeline,
    add: wgpu::ComputePipeline,
    compact: wgpu::ComputePipeline,
    vertices: wgpu::ComputePipeline,
    triangles: wgpu::ComputePipeline,
}

/// Grow-only device buffers, reused from tile to tile.
#[derive(Default)]
struct Buffers {
    upload: Option<wgpu::Buffer>,
    values: Option<wgpu::Buffer>,
    counts: Option<wgpu::Buffer>,
    sums: [Option<wgpu::Buffer>; 3],
    totals: Option<wgpu::Buffer>,
    totals_read: Option<wgpu::Buffer>,
    cells: Option<wgpu::Buffer>,
    records: Option<wgpu::Buffer>,
    ends: Option<wgpu::Buffer>,
    tris: Option<wgpu::Buffer>,
    records_read: Option<wgpu::Buffer>,
    ends_read: Option<wgpu::Buffer>,
    tris_read: Option<wgpu::Buffer>,
    axes: Option<wgpu::Buffer>,
    coarse: Option<wgpu::Buffer>,
    own: Option<wgpu::Buffer>,
    slots: Option<wgpu::Buffer>,
}

/// A buffer of at least `need` bytes from `slot`, replaced by one a quarter larger (within
/// `cap`) when smaller.
fn ensure(
    device: &wgpu::Device,
    slot: &mut Option<wgpu::Buffer>,
    label: &str,
    need: u64,
    usage: wgpu::BufferUsages,
    cap: u64,
) -> wgpu::Buffer {
    let need = need.max(16).next_multiple_of(16);
    match slot {
        Some(b) if b.size() >= need => b.clone(),
        _ => {
            let size = (need + need / 4)
                .next_multiple_of(1 << 16)
                .min(cap / 16 * 16)
                .max(need);
            let b = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: false,
            });
            *slot = Some(b.clone());
            b
        }
    }
}

/// Copy `src` into the mapped memory `dst` (of the same length) on all cores: one thread is
/// far from filling the bus for a big tile.
fn copy_parallel(dst: wgpu::WriteOnly<'_, [u8]>, src: &[u8]) {
    let (chunks, mut rest) = dst.into_chunks::<COPY_CHUNK>();
    let (head, tail) = src.split_at(chunks.len() * COPY_CHUNK);
    // `WriteOnly<[u8; N]>` is `Send` where `WriteOnly<[u8]>` is not.
    let chunks: Vec<_> = chunks.into_iter().collect();
    chunks
        .into_par_iter()
        .zip(head.par_chunks(COPY_CHUNK))
        .for_each(|(d, s)| wgpu::WriteOnly::<[u8]>::from(d).copy_from_slice(s));
    rest.copy_from_slice(tail);
}

/// Where a tile's node values come from.
#[derive(Clone, Copy)]
enum Source<'a> {
    /// The host has them: they are uploaded.
    Dense(&'a [f32]),
    /// The device blends them from leaf grids ([`GpuExtractor::extract_blend`]).
    Blend(&'a Blend<'a>),
}

/// Where one sub-block's node values come from.
#[derive(Clone, Copy)]
enum BlockValues<'a> {
    /// Uploaded from the host.
    Host(&'a [f32]),
    /// Computed by `field.wgsl`: the sub-block's offset in the tile, and the tile's words of
    /// the shader's parameters (from `lox` on).
    Device([usize; 3], &'a [u32; 20]),
}

/// Bytes of the leaf pool on a discrete GPU, an integrated one, and other adapters (at most
/// the buffer limit, at least twice a tile's leaves).
const POOL_DISCRETE: u64 = 1 << 30;
const POOL_INTEGRATED: u64 = 256 << 20;
const POOL_OTHER: u64 = 32 << 20;

/// Most slots of the leaf pool: a lookup entry is the slot in 24 bits and the leaf's exponent
/// above them.
const MAX_SLOTS: usize = (1 << 24) - 1;

/// No leaf in this cell of a blended tile's lookup box (`field.wgsl`).
const NO_LEAF: u32 = u32::MAX;

/// The device's cache of leaf detail grids: `slots` grids of `dm³` values in one buffer,
/// replaced least recently used first. A leaf shared by neighbouring tiles crosses the bus
/// once while it stays resident.
#[derive(Default)]
struct LeafPool {
    buf: Option<wgpu::Buffer>,
    dm: usize,
    slots: usize,
    slot_of: HashMap<u64, usize>,
    key_of: Vec<Option<u64>>,
    used: Vec<u64>,
    clock: u64,
}

/// The lowest of the (at most two) leaf cells whose grids reach node `g` with a non-zero
/// weight (detail offset `1..=dm−2`), and the highest (`field.wgsl`, `candidates`).
fn leaf_cells(g: i64, e: i64, ov: i64, dm: i64) -> (i64, i64) {
    let hi = (g + ov - 1).div_euclid(e);
    let lo = if g - (e * (hi - 1) - ov) <= dm - 2 {
        hi - 1
    } else {
        hi
    };
    (lo, hi)
}

/// Errors that wgpu reports outside an error scope, and the reason a device was lost.
#[derive(Default)]
struct Trouble {
    uncaptured: Option<String>,
    lost: Option<String>,
}

/// What [`GpuExtractor::assemble`] needs of a sub-block besides the records.
struct Assembly<'a> {
    /// The tile's node values when the host has them.
    values: &'a [f32],
    /// Else the two node values of each record's edge, from the device.
    ends: Option<&'a [[u32; 2]]>,
    dims: [usize; 3],
    origin_node: [u64; 3],
    iso: f32,
    block: SubBlock,
}

/// What one sub-block gave.
enum BlockOutcome {
    /// Its records are in `GpuExtractor::records`, its triangles (record indices) appended
    /// to the mesh.
    Done,
    /// Its triangles would exceed the buffer limit: halve it and redo.
    TooBig,
}

/// Marching cubes on a GPU; see the [module docs](self). Holds the device, queue, pipelines
/// and reusable buffers; call [`GpuExtractor::extract`] tile after tile from one thread.
pub struct GpuExtractor {
    device: wgpu::Device,
    queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    max_dim: u32,
    /// Largest buffer the device allows (the smaller of buffer and storage binding sizes).
    device_max_bytes: u64,
    /// The limit sub-blocks are planned for: at most `device_max_bytes`.
    max_bytes: u64,
    pipelines: Pipelines,
    tables: wgpu::Buffer,
    bufs: Buffers,
    trouble: Arc<Mutex<Trouble>>,
    /// Why the GPU is no longer used (lost device, panic in wgpu).
    broken: Option<String>,
    cpu: McWorkspace,
    pool: LeafPool,
    gather: Vec<f32>,
    /// Vertex records of the last sub-block (block-local edge ids, bit 31 on seams).
    records: Vec<u32>,
    /// The bits of the two node values of each record's edge, for fields built on the
    /// device.
    ends: Vec<[u32; 2]>,
    /// Vertex index of each record of the sub-block, where seams matched earlier vertices.
    map: Vec<u32>,
    /// Vertex of each seam edge made so far in the tile, by tile-local edge id.
    seam: HashMap<u64, u32>,
    /// Test hooks: a validation error, or a panic, in the next sub-block.
    #[cfg(test)]
    fail_next: bool,
    #[cfg(test)]
    panic_next: bool,
}

impl fmt::Debug for GpuExtractor {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("GpuExtractor")
            .field("adapter", &describe(&self.info))
            .field("max_bytes", &self.max_bytes)
            .field("broken", &self.broken)
            .finish_non_exhaustive()
    }
}

/// Why a tile could not be done on the GPU.
type GpuResult<T> = std::result::Result<T, String>;

impl GpuExtractor {
    /// Open a GPU for marching cubes.
    ///
    /// [`GpuMode::Off`]: `Ok(None)` without touching wgpu. [`GpuMode::Auto`]: `Some` for a
    /// discrete or integrated GPU (the best one wgpu finds), `None` for none or for CPU and
    /// software adapters, or when opening it fails (logged). [`GpuMode::On`]: any adapter,
    /// Mesa lavapipe included; [`Error::Usage`] when there is none or it cannot be opened.
    /// The adapter used is logged (`log::info!`).
    pub fn new(mode: GpuMode) -> Result<Option<GpuExtractor>> {
        if mode == GpuMode::Off {
            return Ok(None);
        }
        let instance = make_instance();
        let adapters = pollster::block_on(instance.enumerate_adapters(backends()));
        let found: Vec<String> = adapters.iter().map(|a| describe(&a.get_info())).collect();
        let best = adapters
            .into_iter()
            .filter(|a| {
                a.get_downlevel_capabilities()
                    .flags
                    .contains(wgpu::DownlevelFlags::COMPUTE_SHADERS)
            })
            .filter_map(|a| rank(mode, a.get_info().device_type).map(|r| (r, a)))
            .min_by_key(|(r, _)| *r)
            .map(|(_, a)| a);
        let found = if found.is_empty() {
            "none".to_string()
        } else {
            found.join("; ")
        };
        let Some(adapter) = best else {
            if mode == GpuMode::On {
                return Err(Error::Usage(format!(
                    "--gpu on: wgpu found no GPU adapter with compute shaders (adapters: \
                     {found}); install a Vulkan driver (Mesa's lavapipe is in \
                     mesa-vulkan-drivers) or use --gpu auto or off"
                )));
            }
            log::info!(
                "marching cubes on the CPU: no discrete or integrated GPU (adapters: {found})"
            );
            return Ok(None);
        };
        match GpuExtractor::open(adapter) {
            Ok(g) => {
                log::info!(
                    "marching cubes on the GPU: {}, buffers up to {} MiB",
                    describe(&g.info),
                    g.device_max_bytes >> 20
                );
                Ok(Some(g))
            }
            Err(e) if mode == GpuMode::On => Err(Error::Usage(format!("--gpu on: {e}"))),
            Err(e) => {
                log::warn!("marching cubes on the CPU: {e}");
                Ok(None)
            }
        }
    }

    fn open(adapter: wgpu::Adapter) -> GpuResult<GpuExtractor> {
        let info = adapter.get_info();
        let limits = adapter.limits();
        // 64-bit integers build blended fields on the device (`field.rs`).
        let int64 = adapter.features().contains(wgpu::Features::SHADER_INT64);
        let required_features = if int64 {
            wgpu::Features::SHADER_INT64
        } else {
            wgpu::Features::empty()
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("scanflow marching cubes"),
            required_features,
            required_limits: limits.clone(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| format!("could not open {}: {e}", describe(&info)))?;
        let trouble = Arc::new(Mutex::new(Trouble::default()));
        let t = Arc::clone(&trouble);
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut t) = t.lock() {
                t.uncaptured.get_or_insert_with(|| e.to_string());
            }
        }));
        let t = Arc::clone(&trouble);
        device.set_device_lost_callback(move |reason, msg| {
            if let Ok(mut t) = t.lock() {
                t.lost
                    .get_or_insert_with(|| format!("device lost ({reason:?}): {msg}"));
            }
        });
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let pipeline = |label: &str, src: &str, entry: &str| {
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(src.into()),
            });
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: None,
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        const COMMON: &str = include_str!("shaders/common.wgsl");
        let with_common = |s: &str| format!("{COMMON}\n{s}");
        let classify = with_common(include_str!("shaders/classify.wgsl"));
        let scan = include_str!("shaders/scan.wgsl");
        let compact = with_common(include_str!("shaders/compact.wgsl"));
        let emit = with_common(include_str!("shaders/emit.wgsl"));
        let pipelines = Pipelines {
            field: int64
                .then(|| pipeline("field.wgsl", include_str!("shaders/field.wgsl"), "main")),
            classify: pipeline("classify.wgsl", &classify, "main"),
            scan: pipeline("scan.wgsl", scan, "scan_blocks"),
            add: pipeline("scan.wgsl", scan, "add_block_sums"),
            compact: pipeline("compact.wgsl", &compact, "main"),
            vertices: pipeline("emit.wgsl", &emit, "vertices"),
            triangles: pipeline("emit.wgsl", &emit, "triangles"),
        };
        let tables = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("case tables"),
            contents: bytemuck::cast_slice(&table_words()),
            usage: wgpu::BufferUsages::STORAGE,
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(format!(
                "could not build the compute pipelines on {}: {e}",
                describe(&info)
            ));
        }
        let device_max_bytes = limits
            .max_buffer_size
            .min(limits.max_storage_buffer_binding_size)
            .min(MAX_BUFFER_BYTES);
        Ok(GpuExtractor {
            device,
            queue,
            info,
            max_dim: limits.max_compute_workgroups_per_dimension,
            device_max_bytes,
            max_bytes: device_max_bytes,
            pipelines,
            tables,
            bufs: Buffers::default(),
            trouble,
            broken: None,
            cpu: McWorkspace::new(),
            pool: LeafPool::default(),
            gather: Vec::new(),
            records: Vec::new(),
            ends: Vec::new(),
            map: Vec::new(),
            seam: HashMap::new(),
            #[cfg(test)]
            fail_next: false,
            #[cfg(test)]
            panic_next: false,
        })
    }

    /// The adapter's name, as the driver reports it (e.g. "NVIDIA H100 80GB HBM3" or
    /// "llvmpipe (LLVM 15.0.6, 256 bits)").
    pub fn adapter_name(&self) -> String {
        self.info.name.clone()
    }

    /// The largest buffer, in bytes, that sub-blocks are planned for: the device's limit
    /// unless lowered by [`GpuExtractor::set_max_buffer_bytes`].
    pub fn max_buffer_bytes(&self) -> u64 {
        self.max_bytes
    }

    /// Plan sub-blocks for buffers of at most `bytes` (at most the device's limit, at least
    /// 128 bytes, one cell), to bound device memory or to test sub-blocks; the output does
    /// not change.
    pub fn set_max_buffer_bytes(&mut self, bytes: u64) {
        self.max_bytes = bytes.clamp(128, self.device_max_bytes);
    }

    /// Extract the iso-surface of a block of nodes into `out` (cleared first): the same
    /// contract and the same output as [`McWorkspace::extract`] (and
    /// [`cpu::marching_cubes`]). A GPU failure sends the tile to the CPU, with a
    /// `log::warn!` and [`GpuStats::fell_back`] set; the output is the same.
    ///
    /// Errors: those of [`McWorkspace::extract`], for the same inputs.
    pub fn extract(
        &mut self,
        values: &[f32],
        dims: [usize; 3],
        origin_node: [u64; 3],
        iso: f32,
        geom: &GridGeom,
        out: &mut TileMesh,
    ) -> Result<GpuStats> {
        self.extract_from(Source::Dense(values), dims, origin_node, iso, geom, out)
    }

    /// Extract the iso-surface of a blended field ([`Blend`]) into `out`, building the field
    /// on the device from the leaf grids, which stay resident from tile to tile: the mesh
    /// [`McWorkspace::extract`] gives on [`Blend::eval`], bit for bit. A tile whose leaves do
    /// not fit the device's buffers is blended on the host and uploaded; a GPU failure sends
    /// it to the CPU (logged, [`GpuStats::fell_back`]).
    ///
    /// Errors: [`Error::Internal`] for inconsistent tables ([`Blend::validate`]), and those of
    /// [`McWorkspace::extract`].
    pub fn extract_blend(
        &mut self,
        blend: &Blend<'_>,
        iso: f32,
        geom: &GridGeom,
        out: &mut TileMesh,
    ) -> Result<GpuStats> {
        blend
            .validate()
            .map_err(|e| Error::Internal(format!("blended tile at {:?}: {e}", blend.lo)))?;
        let origin = blend.lo.map(|v| v as u64);
        self.extract_from(Source::Blend(blend), blend.dims, origin, iso, geom, out)
    }

    /// Forget the resident leaf grids: call it before reusing leaf ids for other data.
    pub fn forget_leaves(&mut self) {
        self.pool = LeafPool::default();
    }

    fn extract_from(
        &mut self,
        src: Source<'_>,
        dims: [usize; 3],
        origin_node: [u64; 3],
        iso: f32,
        geom: &GridGeom,
        out: &mut TileMesh,
    ) -> Result<GpuStats> {
        out.clear();
        fn host_values<'a>(src: Source<'a>) -> std::borrow::Cow<'a, [f32]> {
            match src {
                Source::Dense(v) => std::borrow::Cow::Borrowed(v),
                Source::Blend(b) => std::borrow::Cow::Owned(b.eval()),
            }
        }
        let nodes = match src {
            Source::Dense(v) => v.len(),
            Source::Blend(b) => b.nodes(),
        };
        if !gpu_applicable(nodes, dims, origin_node, geom) {
            // Bad shapes give the CPU kernel's errors; blocks without cells its empty mesh.
            let values = host_values(src);
            let s = self
                .cpu
                .extract(&values, dims, origin_node, iso, geom, out)?;
            return Ok(GpuStats {
                cells: s.cells,
                active_cells: s.active_cells,
                ..GpuStats::default()
            });
        }
        if self.broken.is_none()
            && let Ok(t) = self.trouble.lock()
            && let Some(lost) = &t.lost
        {
            self.broken = Some(lost.clone());
            log::warn!(
                "GPU marching cubes: {lost} ({}); this and later tiles run on the CPU",
                self.info.name
            );
        } else if let Some(why) = &self.broken {
            log::debug!("tile at node {origin_node:?} on the CPU: the GPU is unusable ({why})");
        } else {
            let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                self.try_extract(src, dims, origin_node, iso, geom, out)
            }));
            let reason = match run {
                Ok(Ok(stats)) => return Ok(stats),
                Ok(Err(e)) => e,
                Err(panic) => {
                    let msg = panic
                        .downcast_ref::<String>()
                        .cloned()
                        .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                        .unwrap_or_else(|| "unknown panic".to_string());
                    let why = format!("panic in the GPU path: {msg}");
                    self.broken = Some(why.clone());
                    why
                }
            };
            let later = if self.broken.is_some() {
                "this and later tiles run on the CPU"
            } else {
                "extracting it on the CPU"
            };
            log::warn!(
                "GPU marching cubes failed on the tile of {}×{}×{} nodes at node \
                 {origin_node:?} ({}): {reason}; {later}",
                dims[0],
                dims[1],
                dims[2],
                self.info.name
            );
        }
        let values = host_values(src);
        let s = self
            .cpu
            .extract(&values, dims, origin_node, iso, geom, out)?;
        Ok(GpuStats {
            cells: s.cells,
            active_cells: s.active_cells,
            fell_back: true,
            ..GpuStats::default()
        })
    }

    /// Make a blended tile's leaf grids resident and upload its tables. The parameter words
    /// of `field.wgsl` from `lox` on; `None` when its leaves do not fit the pool.
    fn prepare_blend(
        &mut self,
        b: &Blend<'_>,
        stats: &mut GpuStats,
    ) -> GpuResult<Option<[u32; 20]>> {
        use wgpu::BufferUsages as U;
        if self.pipelines.field.is_none() {
            return Ok(None);
        }
        let dm = b.dm();
        // Two 16-bit details a word (`quantise_detail`).
        let slot_words = (dm * dm * dm).div_ceil(2);
        let slot_bytes = 4 * slot_words as u64;
        let max_slots = ((self.max_bytes / slot_bytes) as usize).min(MAX_SLOTS);
        let (e, ov) = (b.e, b.ov);
        let cells = |a: usize| {
            (
                leaf_cells(b.lo[a], e, ov, dm as i64).0,
                leaf_cells(b.lo[a] + b.dims[a] as i64 - 1, e, ov, dm as i64).1,
            )
        };
        let [(x0, x1), (y0, y1), (z0, z1)] = [cells(0), cells(1), cells(2)];
        let box_dims = [x1 - x0 + 1, y1 - y0 + 1, z1 - z0 + 1].map(|v| v as usize);
        let within = |c: [i64; 3]| {
            (x0..=x1).contains(&c[0]) && (y0..=y1).contains(&c[1]) && (z0..=z1).contains(&c[2])
        };
        let leaves: Vec<_> = b.leaves.iter().filter(|l| within(l.cell)).collect();
        if leaves.len() > max_slots {
            return Ok(None);
        }
        let pool = &mut self.pool;
        if pool.dm != dm || pool.slots < leaves.len() || pool.buf.is_none() {
            // Room for the leaves of many tiles: a leaf serves up to 8 tiles, not all close
            // in Morton order. Device memory of its own on a discrete GPU; host memory on
            // integrated and software adapters, so less there.
            let target = match self.info.device_type {
                wgpu::DeviceType::DiscreteGpu => POOL_DISCRETE,
                wgpu::DeviceType::IntegratedGpu => POOL_INTEGRATED,
                _ => POOL_OTHER,
            };
            let slots = (2 * leaves.len())
                .max((target / slot_bytes) as usize)
                .max(1)
                .min(max_slots);
            *pool = LeafPool {
                buf: Some(self.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("leaf grids"),
                    size: slots as u64 * slot_bytes,
                    usage: U::STORAGE | U::COPY_DST,
                    mapped_at_creation: false,
                })),
                dm,
                slots,
                slot_of: HashMap::new(),
                key_of: vec![None; slots],
                used: vec![0; slots],
                clock: 0,
            };
        }
        pool.clock += 1;
        let buf = pool.buf.clone().ok_or("no leaf pool")?;
        let mut table = vec![NO_LEAF; box_dims.iter().product()];
        for l in leaves {
            let slot = match pool.slot_of.get(&l.id) {
                Some(&s) => s,
                None => {
                    // A free slot, else the least recently used one not used by this tile.
                    let s = (0..pool.slots)
                        .filter(|&s| pool.used[s] < pool.clock)
                        .min_by_key(|&s| (pool.key_of[s].is_some(), pool.used[s]))
                        .ok_or("the leaf pool is full")?;
                    if let Some(old) = pool.key_of[s].replace(l.id) {
                        pool.slot_of.remove(&old);
                    }
                    pool.slot_of.insert(l.id, s);
                    self.queue.write_buffer(
                        &buf,
                        s as u64 * slot_bytes,
                        bytemuck::cast_slice(l.detail),
                    );
                    stats.upload_bytes += slot_bytes;
                    stats.leaves_sent += 1;
                    s
                }
            };
            pool.used[slot] = pool.clock;
            let c = [l.cell[0] - x0, l.cell[1] - y0, l.cell[2] - z0].map(|v| v as usize);
            table[(c[2] * box_dims[1] + c[1]) * box_dims[0] + c[0]] = slot as u32 | l.shift << 24;
        }
        let mut axes: Vec<[u32; 4]> = Vec::with_capacity(b.dims.iter().sum());
        for ax in &b.axes {
            for i in 0..ax.c0.len() {
                axes.push([ax.c0[i], ax.w0[i] as u32, ax.w1[i] as u32, 0]);
            }
        }
        let cap = self.device_max_bytes;
        let dev = self.device.clone();
        let bufs = &mut self.bufs;
        let usage = U::STORAGE | U::COPY_DST;
        let uploads: [(&mut Option<wgpu::Buffer>, &str, &[u8]); 4] = [
            (&mut bufs.axes, "axis tables", bytemuck::cast_slice(&axes)),
            (
                &mut bufs.coarse,
                "coarse values",
                bytemuck::cast_slice(&b.coarse),
            ),
            (&mut bufs.own, "bump weights", bytemuck::cast_slice(&b.own)),
            (&mut bufs.slots, "leaf lookup", bytemuck::cast_slice(&table)),
        ];
        for (slot, label, bytes) in uploads {
            let buf = ensure(&dev, slot, label, bytes.len() as u64, usage, cap);
            self.queue.write_buffer(&buf, 0, bytes);
            stats.upload_bytes += bytes.len() as u64;
        }
        let lo = b.lo.map(|v| v as i32 as u32);
        let i = |v: i64| v as i32 as u32;
        Ok(Some([
            lo[0],
            lo[1],
            lo[2],
            i(e),
            i(ov),
            dm as u32,
            i(x0),
            i(y0),
            i(z0),
            box_dims[0] as u32,
            box_dims[1] as u32,
            box_dims[2] as u32,
            b.coarse_dims[0] as u32,
            b.coarse_dims[1] as u32,
            b.dims[0] as u32,
            (b.dims[0] + b.dims[1]) as u32,
            b.unit.to_bits(),
            b.coarse_shift(),
            slot_words as u32,
            0,
        ]))
    }

    fn try_extract(
        &mut self,
        src: Source<'_>,
        dims: [usize; 3],
        origin_node: [u64; 3],
        iso: f32,
        geom: &GridGeom,
        out: &mut TileMesh,
    ) -> GpuResult<GpuStats> {
        out.clear();
        let mut stats = GpuStats {
            cells: dims.iter().map(|&d| d as u64 - 1).product(),
            ..GpuStats::default()
        };
        // A blended tile: on the device when its leaves fit, else blended here.
        let mut blended = None;
        let mut tile_words = None;
        let values: &[f32] = match src {
            Source::Dense(v) => v,
            Source::Blend(b) => {
                let t0 = Instant::now();
                tile_words = self.prepare_blend(b, &mut stats)?;
                stats.upload_secs += t0.elapsed().as_secs_f64();
                if tile_words.is_none() {
                    log::debug!(
                        "tile at node {origin_node:?} blended on the host: {}",
                        if self.pipelines.field.is_none() {
                            "the device has no 64-bit integers in shaders"
                        } else {
                            "its leaves exceed the device's buffers"
                        }
                    );
                    blended.insert(b.eval())
                } else {
                    stats.field_on_gpu = true;
                    &[]
                }
            }
        };
        let key = iso_key(iso);
        let l = dims[0] * dims[1];
        self.seam.clear();
        let mut todo: VecDeque<SubBlock> = plan(dims, self.max_bytes)?.into();
        while let Some(b) = todo.pop_front() {
            let mut gather = std::mem::take(&mut self.gather);
            let block_values = if let Some(w) = &tile_words {
                BlockValues::Device(b.at, w)
            } else if b.dims[0] == dims[0] && b.dims[1] == dims[1] {
                BlockValues::Host(&values[b.at[2] * l..(b.at[2] + b.dims[2]) * l])
            } else {
                gather.clear();
                for z in b.at[2]..b.at[2] + b.dims[2] {
                    for y in b.at[1]..b.at[1] + b.dims[1] {
                        let r = z * l + y * dims[0] + b.at[0];
                        gather.extend_from_slice(&values[r..r + b.dims[0]]);
                    }
                }
                BlockValues::Host(&gather[..])
            };
            let seam_mask = b.seam_mask(dims);
            let tri_start = out.triangles.len();
            let res = self.run_block(
                block_values,
                b.dims,
                key,
                seam_mask,
                &mut stats,
                &mut out.triangles,
            );
            self.gather = gather;
            if let BlockOutcome::TooBig = res? {
                let (lo, hi) = b
                    .halve()
                    .ok_or("the triangles of one cell exceed the buffer limit")?;
                todo.push_front(hi);
                todo.push_front(lo);
                continue;
            }
            stats.sub_blocks += 1;
            let t0 = Instant::now();
            let ends = std::mem::take(&mut self.ends);
            let at = Assembly {
                values,
                ends: tile_words.is_some().then_some(&ends[..]),
                dims,
                origin_node,
                iso,
                block: b,
            };
            let r = self.assemble(at, geom, out, tri_start);
            self.ends = ends;
            r?;
            stats.host_secs += t0.elapsed().as_secs_f64();
        }
        Ok(stats)
    }

    /// Add the vertices of sub-block `b` (records in `self.records`) to `out`, matching seam
    /// edges to the vertices earlier sub-blocks made, and turn its triangles
    /// (`out.triangles[tri_start..]`, record indices) into vertex indices.
    fn assemble(
        &mut self,
        at: Assembly<'_>,
        geom: &GridGeom,
        out: &mut TileMesh,
        tri_start: usize,
    ) -> GpuResult<()> {
        let Assembly {
            values,
            ends,
            dims,
            origin_node,
            iso,
            block: b,
        } = at;
        let n_records = self.records.len();
        let base = out.keys.len();
        if base + n_records >= u32::MAX as usize {
            return Err("more than 2^32 vertices in a tile".to_string());
        }
        let bd = b.dims.map(|d| d as u32);
        // Block-local edge id -> (tile node, axis), or None if it is not an edge of the block.
        let decode = move |r: u32| -> Option<([usize; 3], usize)> {
            let n = r / 3;
            let axis = (r % 3) as usize;
            let local = [n % bd[0], (n / bd[0]) % bd[1], n / bd[0] / bd[1]];
            (local[2] < bd[2] && local[axis] + 1 < bd[axis])
                .then(|| ([0, 1, 2].map(|d| b.at[d] + local[d] as usize), axis))
        };
        let tile_index = move |p: [usize; 3]| (p[2] * dims[1] + p[1]) * dims[0] + p[0];
        // Seam records whose edge an earlier sub-block already gave a vertex: (record, vertex).
        // A new vertex's index is `base + record − (matched records before it)`.
        let mut matched: Vec<(usize, u32)> = Vec::new();
        if b.seam_mask(dims) != 0 {
            let on_seam: Vec<usize> = self
                .records
                .par_iter()
                .enumerate()
                .filter(|(_, r)| *r & SEAM != 0)
                .map(|(j, _)| j)
                .collect();
            for j in on_seam {
                let (p, axis) = decode(self.records[j] & !SEAM)
                    .ok_or("a vertex record is not an edge of the block")?;
                let k = (tile_index(p) * 3 + axis) as u64;
                match self.seam.entry(k) {
                    std::collections::hash_map::Entry::Occupied(o) => matched.push((j, *o.get())),
                    std::collections::hash_map::Entry::Vacant(v) => {
                        v.insert((base + j - matched.len()) as u32);
                    }
                }
            }
            for &(j, _) in &matched {
                self.records[j] = MATCHED;
            }
        }
        let fresh = &self.records;

        // Keys and positions, vertex by vertex, as the CPU kernel computes them.
        let stride = [1, dims[0], dims[0] * dims[1]];
        let iso64 = iso as f64;
        let bad = AtomicBool::new(false);
        let mut both = (
            std::mem::take(&mut out.keys),
            std::mem::take(&mut out.positions),
        );
        let vertex = |j: usize| {
            let Some((p, axis)) = decode(fresh[j] & !SEAM) else {
                bad.store(true, Ordering::Relaxed);
                return (EdgeKey(0), [0.0; 3]);
            };
            let (va, vb) = match ends {
                Some(e) => (f32::from_bits(e[j][0]), f32::from_bits(e[j][1])),
                None => {
                    let a = tile_index(p);
                    (values[a], values[a + stride[axis]])
                }
            };
            let g = [0, 1, 2].map(|d| origin_node[d] + p[d] as u64);
            (
                geom.edge_key(g, axis as u8),
                cpu::edge_vertex(geom, g, axis, va, vb, iso64),
            )
        };
        let all = (0..fresh.len()).into_par_iter().with_min_len(1 << 12);
        if matched.is_empty() {
            both.par_extend(all.map(vertex));
        } else {
            both.par_extend(all.filter(|&j| fresh[j] != MATCHED).map(vertex));
        }
        (out.keys, out.positions) = both;
        if bad.load(Ordering::Relaxed) {
            return Err("a vertex record is not an edge of the block".to_string());
        }

        // Triangles: record indices to vertex indices.
        let tris = &mut out.triangles[tri_start..];
        let n = n_records as u32;
        let ok = if matched.is_empty() {
            let off = base as u32;
            tris.par_iter_mut().with_min_len(1 << 12).all(|t| {
                let ok = t.iter().all(|&v| v < n);
                *t = t.map(|v| v.wrapping_add(off));
                ok
            })
        } else {
            const RUN: usize = 1 << 16;
            let matched = &matched;
            self.map.clear();
            self.map.par_extend(
                (0..n_records.div_ceil(RUN))
                    .into_par_iter()
                    .flat_map_iter(|c| {
                        let j0 = c * RUN;
                        let mut before = matched.partition_point(|m| m.0 < j0);
                        (j0..n_records.min(j0 + RUN)).map(move |j| match matched.get(before) {
                            Some(&(m, v)) if m == j => {
                                before += 1;
                                v
                            }
                            _ => (base + j - before) as u32,
                        })
                    }),
            );
            let map = &self.map;
            tris.par_iter_mut().with_min_len(1 << 12).all(|t| {
                let ok = t.iter().all(|&v| v < n);
                *t = t.map(|v| map.get(v as usize).copied().unwrap_or(0));
                ok
            })
        };
        if !ok {
            return Err(format!("a triangle index exceeds the {n} vertex records"));
        }
        Ok(())
    }

    /// Passes 1 to 5 on one sub-block of `dims` nodes, under error scopes: fills
    /// `self.records` and appends its triangles (record indices) to `tris`.
    fn run_block(
        &mut self,
        values: BlockValues<'_>,
        dims: [usize; 3],
        iso_key: u32,
        seam_mask: u32,
        stats: &mut GpuStats,
        tris: &mut Vec<[u32; 3]>,
    ) -> GpuResult<BlockOutcome> {
        let scopes = [
            self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory),
            self.device.push_error_scope(wgpu::ErrorFilter::Validation),
            self.device.push_error_scope(wgpu::ErrorFilter::Internal),
        ];
        let res = self.run_block_scoped(values, dims, iso_key, seam_mask, stats, tris);
        let mut errors = Vec::new();
        for s in scopes.into_iter().rev() {
            if let Some(e) = pollster::block_on(s.pop()) {
                errors.push(e.to_string());
            }
        }
        if let Ok(mut t) = self.trouble.lock() {
            errors.extend(t.uncaptured.take());
            if let Some(lost) = &t.lost {
                self.broken = Some(lost.clone());
                errors.push(lost.clone());
            }
        }
        if res.is_err() || !errors.is_empty() {
            // A buffer may be left mapped or invalid: start the next tile with fresh ones,
            // the leaf pool included (its slots may not hold what the map says).
            self.bufs = Buffers::default();
            self.pool = LeafPool::default();
        }
        match res {
            Ok(o) if errors.is_empty() => Ok(o),
            Ok(_) => Err(errors.join("; ")),
            Err(e) => {
                errors.insert(0, e);
                Err(errors.join("; "))
            }
        }
    }

    fn wait(&self) -> GpuResult<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| format!("waiting for the GPU: {e}"))
    }

    /// Map the first `bytes` bytes of `buf` (`what`, for errors) and wait for it.
    fn map(
        &self,
        buf: &wgpu::Buffer,
        mode: wgpu::MapMode,
        bytes: u64,
        what: &str,
    ) -> GpuResult<()> {
        let (tx, rx) = mpsc::channel();
        buf.map_async(mode, 0..bytes, move |r| {
            let _ = tx.send(r);
        });
        self.wait()?;
        match rx.try_recv() {
            Ok(Ok(())) => Ok(()),
            Ok(Err(e)) => Err(format!("mapping {what}: {e}")),
            Err(_) => Err(format!("{what} was not mapped")),
        }
    }

    /// Append the first `bytes` bytes of the read-back buffer `buf` to `out`.
    fn read<T: bytemuck::Pod + Send + Sync>(
        &self,
        buf: &wgpu::Buffer,
        bytes: u64,
        out: &mut Vec<T>,
    ) -> GpuResult<()> {
        if bytes == 0 {
            return Ok(());
        }
        self.map(buf, wgpu::MapMode::Read, bytes, "a read-back buffer")?;
        {
            let view = buf
                .get_mapped_range(0..bytes)
                .map_err(|e| format!("reading back: {e}"))?;
            let data: &[T] = bytemuck::cast_slice(&view);
            out.par_extend(data.par_iter().with_min_len(COPY_CHUNK / 16).copied());
        }
        buf.unmap();
        Ok(())
    }

    fn run_block_scoped(
        &mut self,
        values: BlockValues<'_>,
        dims: [usize; 3],
        iso_key: u32,
        seam_mask: u32,
        stats: &mut GpuStats,
        out_tris: &mut Vec<[u32; 3]>,
    ) -> GpuResult<BlockOutcome> {
        use wgpu::BufferUsages as U;
        let n = (dims[0] * dims[1] * dims[2]) as u64;
        let cells = dims.iter().map(|&d| d as u64 - 1).product::<u64>();
        let cap = self.device_max_bytes;
        let dev = self.device.clone();
        let b = &mut self.bufs;
        #[cfg(test)]
        if std::mem::take(&mut self.panic_next) {
            panic!("injected panic");
        }
        #[cfg(test)]
        if std::mem::take(&mut self.fail_next) {
            // An invalid buffer (MAP_READ only goes with COPY_DST): a validation error,
            // caught by the scopes like a real one.
            let _ = dev.create_buffer(&wgpu::BufferDescriptor {
                label: Some("injected failure"),
                size: 16,
                usage: U::STORAGE | U::MAP_READ,
                mapped_at_creation: false,
            });
        }

        let values_buf = ensure(
            &dev,
            &mut b.values,
            "values",
            4 * n,
            U::STORAGE | U::COPY_DST,
            cap,
        );
        if let BlockValues::Host(values) = values {
            // Upload through a staging buffer filled on all cores.
            let t0 = Instant::now();
            let bytes: &[u8] = bytemuck::cast_slice(values);
            let len = bytes.len() as u64;
            let write_usage = U::MAP_WRITE | U::COPY_SRC;
            let upload = ensure(&dev, &mut b.upload, "values upload", len, write_usage, cap);
            self.map(&upload, wgpu::MapMode::Write, len, "the upload buffer")?;
            {
                let mut view = upload
                    .get_mapped_range_mut(0..len)
                    .map_err(|e| format!("writing the upload buffer: {e}"))?;
                copy_parallel(view.slice(..), bytes);
            }
            upload.unmap();
            let mut enc = dev.create_command_encoder(&Default::default());
            enc.copy_buffer_to_buffer(&upload, 0, &values_buf, 0, len);
            self.queue.submit([enc.finish()]);
            self.wait()?;
            stats.upload_secs += t0.elapsed().as_secs_f64();
            stats.upload_bytes += len;
        }

        // Passes 1 and 2: classify, scan; read back the totals.
        let t0 = Instant::now();
        let b = &mut self.bufs;
        let counts = ensure(&dev, &mut b.counts, "counts", 16 * n, U::STORAGE, cap);
        let mut levels = vec![(n, counts.clone())];
        while levels.last().expect("non-empty").0 > SCAN_BLOCK {
            let i = levels.len() - 1;
            if i >= b.sums.len() {
                return Err(format!("{n} nodes need too many scan levels"));
            }
            let m = levels[i].0.div_ceil(SCAN_BLOCK);
            let sums = ensure(&dev, &mut b.sums[i], "block sums", 16 * m, U::STORAGE, cap);
            levels.push((m, sums));
        }
        let totals = ensure(
            &dev,
            &mut b.totals,
            "totals",
            16,
            U::STORAGE | U::COPY_SRC,
            cap,
        );
        let read_usage = U::MAP_READ | U::COPY_DST;
        let totals_read = ensure(
            &dev,
            &mut b.totals_read,
            "totals read-back",
            16,
            read_usage,
            cap,
        );
        let node_grid = grid(n.div_ceil(WG), self.max_dim);
        let uniform = |words: &[u32]| {
            dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("parameters"),
                contents: bytemuck::cast_slice(words),
                usage: U::UNIFORM,
            })
        };
        let block_params = |threads: u64, gx: u32| {
            uniform(&[
                dims[0] as u32,
                dims[1] as u32,
                dims[2] as u32,
                threads as u32,
                gx,
                iso_key,
                seam_mask,
                0,
            ])
        };
        let bind = |p: &wgpu::ComputePipeline, bufs: &[&wgpu::Buffer]| {
            let entries: Vec<wgpu::BindGroupEntry<'_>> = bufs
                .iter()
                .enumerate()
                .map(|(i, buf)| wgpu::BindGroupEntry {
                    binding: i as u32,
                    resource: buf.as_entire_binding(),
                })
                .collect();
            dev.create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &p.get_bind_group_layout(0),
                entries: &entries,
            })
        };
        let p = &self.pipelines;
        let node_params = block_params(n, node_grid.0);
        let classify = bind(
            &p.classify,
            &[&node_params, &values_buf, &self.tables, &counts],
        );
        let mut scans = Vec::new();
        for (i, (m, data)) in levels.iter().enumerate() {
            let g = grid(m.div_ceil(SCAN_BLOCK), self.max_dim);
            let prm = uniform(&[*m as u32, g.0, 0, 0]);
            let sums = levels.get(i + 1).map_or(&totals, |l| &l.1);
            let scan = bind(&p.scan, &[&prm, data, sums]);
            let add = bind(&p.add, &[&prm, data, sums]);
            scans.push((g, scan, add));
        }
        let field = match values {
            BlockValues::Device(at, words) => {
                let mut w = vec![
                    dims[0] as u32,
                    dims[1] as u32,
                    dims[2] as u32,
                    n as u32,
                    node_grid.0,
                    at[0] as u32,
                    at[1] as u32,
                    at[2] as u32,
                ];
                w.extend_from_slice(words);
                let prm = uniform(&w);
                let b = &self.bufs;
                let need = |o: &Option<wgpu::Buffer>| o.clone().ok_or("blend tables missing");
                let pool = self.pool.buf.clone().ok_or("no leaf pool")?;
                let (axes, coarse, own, slots) = (
                    need(&b.axes)?,
                    need(&b.coarse)?,
                    need(&b.own)?,
                    need(&b.slots)?,
                );
                let pipeline = p.field.as_ref().ok_or("no field pipeline")?;
                Some((
                    pipeline,
                    bind(
                        pipeline,
                        &[&prm, &axes, &coarse, &own, &slots, &pool, &values_buf],
                    ),
                ))
            }
            BlockValues::Host(_) => None,
        };
        let mut enc = dev.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            if let Some((pipeline, field)) = &field {
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, field, &[]);
                pass.dispatch_workgroups(node_grid.0, node_grid.1, 1);
            }
            pass.set_pipeline(&p.classify);
            pass.set_bind_group(0, &classify, &[]);
            pass.dispatch_workgroups(node_grid.0, node_grid.1, 1);
            pass.set_pipeline(&p.scan);
            for (g, scan, _) in &scans {
                pass.set_bind_group(0, scan, &[]);
                pass.dispatch_workgroups(g.0, g.1, 1);
            }
            pass.set_pipeline(&p.add);
            for (g, _, add) in scans[..scans.len() - 1].iter().rev() {
                pass.set_bind_group(0, add, &[]);
                pass.dispatch_workgroups(g.0, g.1, 1);
            }
        }
        enc.copy_buffer_to_buffer(&totals, 0, &totals_read, 0, 16);
        self.queue.submit([enc.finish()]);
        let mut tot: Vec<u32> = Vec::new();
        self.read(&totals_read, 16, &mut tot)?;
        let [n_vertices, n_active, n_tris] = [tot[0] as u64, tot[1] as u64, tot[2] as u64];
        if n_active > cells || n_tris > 5 * n_active || n_vertices > 12 * n_active {
            return Err(format!(
                "inconsistent totals: {n_vertices} vertices, {n_active} active cells, {n_tris} \
                 triangles for {cells} cells"
            ));
        }
        self.records.clear();
        if n_active == 0 {
            stats.kernel_secs += t0.elapsed().as_secs_f64();
            return Ok(BlockOutcome::Done);
        }
        if (12 * n_tris).max(4 * n_vertices) > self.max_bytes {
            stats.kernel_secs += t0.elapsed().as_secs_f64();
            return Ok(BlockOutcome::TooBig);
        }
        stats.active_cells += n_active;

        // Passes 3 to 5: active cells, vertex records, triangles.
        let b = &mut self.bufs;
        let cells_buf = ensure(
            &dev,
            &mut b.cells,
            "active cells",
            4 * n_active,
            U::STORAGE,
            cap,
        );
        let out_usage = U::STORAGE | U::COPY_SRC;
        let records = ensure(
            &dev,
            &mut b.records,
            "vertex records",
            4 * n_vertices,
            out_usage,
            cap,
        );
        let ends = ensure(
            &dev,
            &mut b.ends,
            "edge ends",
            8 * n_vertices,
            out_usage,
            cap,
        );
        let tris = ensure(&dev, &mut b.tris, "triangles", 12 * n_tris, out_usage, cap);
        let records_read = ensure(
            &dev,
            &mut b.records_read,
            "record read-back",
            4 * n_vertices,
            read_usage,
            cap,
        );
        let tris_read = ensure(
            &dev,
            &mut b.tris_read,
            "triangle read-back",
            12 * n_tris,
            read_usage,
            cap,
        );
        let p = &self.pipelines;
        let compact = bind(&p.compact, &[&node_params, &counts, &cells_buf]);
        let cell_grid = grid(n_active.div_ceil(WG), self.max_dim);
        let cell_params = block_params(n_active, cell_grid.0);
        let vertices = bind(
            &p.vertices,
            &[
                &cell_params,
                &counts,
                &cells_buf,
                &self.tables,
                &records,
                &values_buf,
                &ends,
            ],
        );
        let triangles = bind(
            &p.triangles,
            &[&cell_params, &counts, &cells_buf, &self.tables, &tris],
        );
        let mut enc = dev.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&p.compact);
            pass.set_bind_group(0, &compact, &[]);
            pass.dispatch_workgroups(node_grid.0, node_grid.1, 1);
            pass.set_pipeline(&p.vertices);
            pass.set_bind_group(0, &vertices, &[]);
            pass.dispatch_workgroups(cell_grid.0, cell_grid.1, 1);
            pass.set_pipeline(&p.triangles);
            pass.set_bind_group(0, &triangles, &[]);
            pass.dispatch_workgroups(cell_grid.0, cell_grid.1, 1);
        }
        self.queue.submit([enc.finish()]);
        self.wait()?;
        stats.kernel_secs += t0.elapsed().as_secs_f64();

        // Read back the compacted outputs only.
        let t0 = Instant::now();
        let device_values = matches!(values, BlockValues::Device(..));
        let ends_read = device_values.then(|| {
            ensure(
                &dev,
                &mut self.bufs.ends_read,
                "edge ends read-back",
                8 * n_vertices,
                read_usage,
                cap,
            )
        });
        let mut enc = dev.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(&records, 0, &records_read, 0, 4 * n_vertices);
        if let Some(er) = &ends_read {
            enc.copy_buffer_to_buffer(&ends, 0, er, 0, 8 * n_vertices);
        }
        if n_tris > 0 {
            enc.copy_buffer_to_buffer(&tris, 0, &tris_read, 0, 12 * n_tris);
        }
        self.queue.submit([enc.finish()]);
        let mut recs = std::mem::take(&mut self.records);
        let r = self.read(&records_read, 4 * n_vertices, &mut recs);
        self.records = recs;
        r?;
        self.ends.clear();
        if let Some(er) = &ends_read {
            let mut e = std::mem::take(&mut self.ends);
            let r = self.read(er, 8 * n_vertices, &mut e);
            self.ends = e;
            r?;
        }
        self.read(&tris_read, 12 * n_tris, out_tris)?;
        stats.download_secs += t0.elapsed().as_secs_f64();
        Ok(BlockOutcome::Done)
    }
}

/// True when [`McWorkspace::extract`] would accept the block and it has cells: the GPU path
/// handles exactly these.
fn gpu_applicable(nodes: usize, dims: [usize; 3], origin_node: [u64; 3], geom: &GridGeom) -> bool {
    let total = dims[0]
        .checked_mul(dims[1])
        .and_then(|v| v.checked_mul(dims[2]));
    total == Some(nodes)
        && geom.n <= GridGeom::MAX_N
        && (0..3).all(|d| {
            origin_node[d]
                .checked_add(dims[d] as u64)
                .is_some_and(|l| l - 1 <= geom.n)
        })
        && dims.iter().all(|&d| d >= 2)
        && nodes.saturating_mul(3) < u32::MAX as usize
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Why GPU tests skip, given the adapters wgpu lists: only when there is none at all.
    fn skip_reason(adapters: &[String]) -> Option<String> {
        adapters.is_empty().then(|| {
            "skipping GPU test: wgpu finds no adapter (no Vulkan driver; \
             `apt-get install mesa-vulkan-drivers` gives Mesa's lavapipe)"
                .to_string()
        })
    }

    /// The GPU path on any adapter (lavapipe included), or `None` with the reason printed
    /// when there is no adapter at all. Any other failure to open one fails the test.
    fn gpu() -> Option<GpuExtractor> {
        if let Some(why) = skip_reason(&adapter_names()) {
            eprintln!("{why}");
            return None;
        }
        let g = GpuExtractor::new(GpuMode::On)
            .expect("an adapter exists, so --gpu on must open one")
            .expect("--gpu on gives an extractor");
        eprintln!(
            "GPU tests on {}, buffers up to {} bytes",
            describe(&g.info),
            g.max_buffer_bytes()
        );
        Some(g)
    }

    fn idx(dims: [usize; 3], x: usize, y: usize, z: usize) -> usize {
        (z * dims[1] + y) * dims[0] + x
    }

    fn random_field(seed: u64, dims: [usize; 3]) -> Vec<f32> {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        (0..dims[0] * dims[1] * dims[2])
            .map(|_| rng.random_range(-1.0f32..1.0))
            .collect()
    }

    fn field(dims: [usize; 3], mut f: impl FnMut(usize, usize, usize) -> f32) -> Vec<f32> {
        let mut v = Vec::with_capacity(dims[0] * dims[1] * dims[2]);
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    v.push(f(x, y, z));
                }
            }
        }
        v
    }

    /// The GPU mesh is the CPU mesh: same keys, bitwise the same positions, same triangles.
    fn assert_same(
        g: &mut GpuExtractor,
        values: &[f32],
        dims: [usize; 3],
        origin: [u64; 3],
        iso: f32,
        geom: &GridGeom,
    ) -> GpuStats {
        let mut want = TileMesh::default();
        let cs = McWorkspace::new()
            .extract(values, dims, origin, iso, geom, &mut want)
            .unwrap();
        let mut got = TileMesh {
            keys: vec![EdgeKey(7)],
            ..TileMesh::default()
        };
        let gs = g
            .extract(values, dims, origin, iso, geom, &mut got)
            .unwrap();
        assert!(!gs.fell_back, "{dims:?}: fell back to the CPU");
        assert_eq!((gs.cells, gs.active_cells), (cs.cells, cs.active_cells));
        assert_eq!(got.keys, want.keys, "{dims:?} iso {iso}: keys");
        let bits = |m: &TileMesh| -> Vec<[u64; 3]> {
            m.positions.iter().map(|p| p.map(f64::to_bits)).collect()
        };
        assert!(bits(&got) == bits(&want), "{dims:?} iso {iso}: positions");
        assert_eq!(
            got.triangles, want.triangles,
            "{dims:?} iso {iso}: triangles"
        );
        gs
    }

    /// The GPU mesh of a blended tile is the CPU mesh of its field, [`Blend::eval`].
    fn assert_same_blend(g: &mut GpuExtractor, b: &Blend, iso: f32, geom: &GridGeom) -> GpuStats {
        let values = b.eval();
        let origin = b.lo.map(|v| v as u64);
        let mut want = TileMesh::default();
        McWorkspace::new()
            .extract(&values, b.dims, origin, iso, geom, &mut want)
            .unwrap();
        let mut got = TileMesh::default();
        let gs = g.extract_blend(b, iso, geom, &mut got).unwrap();
        assert!(!gs.fell_back, "{:?}: fell back to the CPU", b.dims);
        assert!(!want.triangles.is_empty(), "a test tile without surface");
        assert_eq!(got.keys, want.keys, "{:?} at {:?}: keys", b.dims, b.lo);
        let bits = |m: &TileMesh| -> Vec<[u64; 3]> {
            m.positions.iter().map(|p| p.map(f64::to_bits)).collect()
        };
        assert!(bits(&got) == bits(&want), "{:?}: positions", b.dims);
        assert_eq!(got.triangles, want.triangles, "{:?}: triangles", b.dims);
        gs
    }

    #[test]
    fn blended_fields_match_the_cpu() {
        use crate::extract::field::tests::RandomBlend;
        let Some(mut g) = gpu() else { return };
        let geom = GridGeom::new([0.0, 0.0, 0.0], 0.01, 1024).unwrap();
        for (seed, lo, dims, e, fill) in [
            (1, [0, 0, 0], [33, 33, 33], 32, 0.7),
            (2, [64, 32, 96], [65, 17, 40], 32, 0.5),
            (3, [40, 8, 0], [20, 30, 50], 16, 1.0),
            (4, [8, 16, 24], [9, 9, 9], 8, 0.3),
        ] {
            let rb = RandomBlend::new(seed, lo, dims, e, fill);
            // Each random blend names its leaves 0, 1, ...
            g.forget_leaves();
            for iso in [0.0, 0.3] {
                let s = assert_same_blend(&mut g, &rb.blend(), iso, &geom);
                assert!(s.field_on_gpu, "seed {seed}: blended on the host");
            }
        }
    }

    #[test]
    fn gpu_errors_on_blended_tiles_fall_back_to_the_cpu() {
        use crate::extract::field::tests::RandomBlend;
        let Some(mut g) = gpu() else { return };
        let geom = GridGeom::new([0.0, 0.0, 0.0], 0.01, 1024).unwrap();
        let rb = RandomBlend::new(21, [32, 0, 64], [33, 20, 25], 32, 0.8);
        let b = rb.blend();
        let mut want = TileMesh::default();
        McWorkspace::new()
            .extract(&b.eval(), b.dims, [32, 0, 64], 0.1, &geom, &mut want)
            .unwrap();
        // A validation error on the device: this tile on the CPU, the next on the GPU.
        g.fail_next = true;
        let mut got = TileMesh::default();
        let s = g.extract_blend(&b, 0.1, &geom, &mut got).unwrap();
        assert!(s.fell_back);
        assert_eq!(got, want);
        let s = assert_same_blend(&mut g, &b, 0.1, &geom);
        assert!(s.field_on_gpu);
        // Inconsistent tables are the caller's error, not a fallback.
        let mut bad = rb.blend();
        bad.axes[0].w0.pop();
        let e = g.extract_blend(&bad, 0.1, &geom, &mut got).unwrap_err();
        assert!(e.to_string().contains("axis 0"), "{e}");
    }

    #[test]
    fn resident_leaves_are_not_sent_again() {
        use crate::extract::field::tests::RandomBlend;
        let Some(mut g) = gpu() else { return };
        let geom = GridGeom::new([0.0, 0.0, 0.0], 0.01, 1024).unwrap();
        let rb = RandomBlend::new(9, [32, 32, 32], [33, 33, 33], 32, 1.0);
        let b = rb.blend();
        let first = assert_same_blend(&mut g, &b, 0.0, &geom);
        let again = assert_same_blend(&mut g, &b, 0.1, &geom);
        let slot = 4 * (b.dm() as u64).pow(3);
        assert!(
            first.upload_bytes >= 8 * slot,
            "{} bytes",
            first.upload_bytes
        );
        assert!(
            again.upload_bytes < slot,
            "{} bytes sent again",
            again.upload_bytes
        );
        // Other data under the same ids needs forget_leaves.
        g.forget_leaves();
        let other = RandomBlend::new(10, [32, 32, 32], [33, 33, 33], 32, 1.0);
        assert_same_blend(&mut g, &other.blend(), 0.0, &geom);
    }

    #[test]
    fn blended_sub_blocks_and_host_blending_give_the_same_mesh() {
        use crate::extract::field::tests::RandomBlend;
        let Some(mut g) = gpu() else { return };
        let geom = GridGeom::new([0.0, 0.0, 0.0], 0.01, 1024).unwrap();
        let rb = RandomBlend::new(12, [16, 8, 0], [33, 17, 41], 8, 0.1);
        let b = rb.blend();
        // Several slabs, the leaves on the device.
        g.set_max_buffer_bytes(200_000);
        let s = assert_same_blend(&mut g, &b, 0.0, &geom);
        assert!(s.sub_blocks > 1 && s.field_on_gpu, "{s:?}");
        // Too small a pool for the tile's leaves: blended on the host, same mesh.
        g.set_max_buffer_bytes(4 * 13 * 13 * 13);
        let s = assert_same_blend(&mut g, &b, 0.0, &geom);
        assert!(!s.field_on_gpu, "{s:?}");
    }

    #[test]
    fn gpu_mode_parses_and_names_the_options() {
        assert_eq!("auto".parse::<GpuMode>().unwrap(), GpuMode::Auto);
        assert_eq!("on".parse::<GpuMode>().unwrap(), GpuMode::On);
        assert_eq!("off".parse::<GpuMode>().unwrap(), GpuMode::Off);
        let e = "yes".parse::<GpuMode>().unwrap_err().to_string();
        assert!(e.contains("\"yes\"") && e.contains("auto, on, off"), "{e}");
        for m in [GpuMode::Auto, GpuMode::On, GpuMode::Off] {
            assert_eq!(m.to_string().parse::<GpuMode>().unwrap(), m);
        }
        assert!(GpuExtractor::new(GpuMode::Off).unwrap().is_none());
    }

    #[test]
    fn no_adapter_is_a_skip_with_a_reason() {
        let why = skip_reason(&[]).unwrap();
        assert!(why.contains("no adapter") && why.contains("mesa-vulkan-drivers"));
        assert_eq!(skip_reason(&["llvmpipe".to_string()]), None);
    }

    /// The tables buffer holds exactly the case tables the CPU kernel uses.
    #[test]
    fn table_words_match_the_case_tables() {
        let w = table_words();
        for case in 0..=255u8 {
            let c = case as usize;
            let tris = &w[w[c] as usize..w[c + 1] as usize];
            let want: Vec<u32> = tables::case_triangles(case)
                .iter()
                .flatten()
                .map(|&e| e as u32)
                .collect();
            assert_eq!(tris, &want[..], "case {case}");
            let used = &w[w[USED_START + c] as usize..w[USED_START + c + 1] as usize];
            let want: Vec<u32> = tables::case_edges(case).iter().map(|&e| e as u32).collect();
            assert_eq!(used, &want[..], "case {case}");
            let info = w[CASE_INFO + c];
            assert_eq!(info & 15, tables::case_triangles(case).len() as u32);
            assert_eq!(info >> 4, tables::crossing_edges(case) as u32);
        }
    }

    #[test]
    fn extractor_is_send() {
        fn send<T: Send>() {}
        send::<GpuExtractor>();
    }

    #[test]
    fn iso_keys_order_like_floats() {
        let vals = [
            f32::NEG_INFINITY,
            -1e30,
            -1.0,
            -f32::MIN_POSITIVE,
            -1e-45,
            -0.0,
            0.0,
            1e-45,
            f32::MIN_POSITIVE,
            0.5,
            1.0,
            f32::INFINITY,
        ];
        for &a in &vals {
            for &b in &vals {
                assert_eq!(iso_key(a) < iso_key(b), a < b, "{a} < {b}");
            }
        }
        assert_eq!(iso_key(f32::NAN), 0);
    }

    /// The cells of `blocks` (tile cell indices), in block order, each block in cell order.
    fn cell_order(blocks: &[SubBlock], dims: [usize; 3]) -> Vec<usize> {
        let mut order = Vec::new();
        for b in blocks {
            assert!(b.dims.iter().all(|&d| d >= 2));
            for z in 0..b.dims[2] - 1 {
                for y in 0..b.dims[1] - 1 {
                    for x in 0..b.dims[0] - 1 {
                        order.push(idx(dims, b.at[0] + x, b.at[1] + y, b.at[2] + z));
                    }
                }
            }
        }
        order
    }

    /// Sub-blocks, planned or halved down to single cells, cover every cell once, share
    /// faces, fit the limit, and list cells in the tile's cell order.
    #[test]
    fn sub_blocks_keep_the_tile_cell_order() {
        let dims = [7, 6, 5];
        let want: Vec<usize> = (0..6 * 5 * 4)
            .map(|i| idx(dims, i % 6, (i / 6) % 5, i / 30))
            .collect();
        for limit in [128u64, 300, 500, 1500, 2100, 1 << 40] {
            let mut blocks = plan(dims, limit).unwrap();
            for b in &blocks {
                assert!(block_bytes(b.dims.map(|d| d - 1)).1 <= limit);
            }
            assert_eq!(cell_order(&blocks, dims), want, "limit {limit}");
            // Halve the first halvable block until all are single cells.
            while let Some(i) = blocks.iter().position(|b| b.halve().is_some()) {
                let (lo, hi) = blocks[i].halve().unwrap();
                blocks.splice(i..=i, [lo, hi]);
                assert_eq!(cell_order(&blocks, dims), want, "limit {limit}");
            }
            assert_eq!(blocks.len(), want.len());
        }
        assert_eq!(plan(dims, 1 << 40).unwrap().len(), 1);
        assert_eq!(plan(dims, 1 << 40).unwrap()[0].seam_mask(dims), 0);
        assert_eq!(plan(dims, 128).unwrap().len(), 6 * 5 * 4);
        assert!(plan(dims, 127).is_err());
        let b = SubBlock {
            at: [0, 2, 1],
            dims: [7, 2, 4],
        };
        assert_eq!(b.seam_mask(dims), 0b01_1100);
    }

    #[test]
    fn random_fields_match_the_cpu() {
        let Some(mut g) = gpu() else { return };
        let geom = GridGeom::new([0.5, -2.0, 7.0], 0.25, 200).unwrap();
        for (seed, dims) in [
            [2, 2, 2],
            [3, 2, 2],
            [4, 5, 6],
            [17, 9, 33],
            [33, 17, 9],
            [70, 70, 70],
        ]
        .into_iter()
        .enumerate()
        {
            let v = random_field(seed as u64, dims);
            for iso in [0.0, 0.37, -0.9] {
                assert_same(&mut g, &v, dims, [3, 1, 4], iso, &geom);
            }
        }
    }

    /// More than 1024² nodes: three levels of block sums.
    #[test]
    fn three_scan_levels_match_the_cpu() {
        let Some(mut g) = gpu() else { return };
        let dims = [130, 101, 81];
        let geom = GridGeom::new([0.0; 3], 1.0, 300).unwrap();
        let v = random_field(77, dims);
        let s = assert_same(&mut g, &v, dims, [0; 3], 0.1, &geom);
        assert_eq!(s.sub_blocks, 1);
    }

    #[test]
    fn checkerboards_of_ambiguous_cases_match_the_cpu() {
        let Some(mut g) = gpu() else { return };
        let geom = GridGeom::new([-1.0, 0.0, 1.0], 0.5, 100).unwrap();
        for parity in 0..2 {
            for dims in [[9, 8, 7], [40, 33, 20]] {
                let v = field(
                    dims,
                    |x, y, z| {
                        if (x + y + z) % 2 == parity { -1.0 } else { 1.0 }
                    },
                );
                let s = assert_same(&mut g, &v, dims, [1, 2, 3], 0.0, &geom);
                assert_eq!(s.active_cells, s.cells);
            }
        }
        // Checkerboards of planes and lines: other ambiguous faces.
        let dims = [21, 22, 23];
        let v = field(dims, |x, y, _| if (x + y) % 2 == 0 { -1.0 } else { 1.0 });
        assert_same(&mut g, &v, dims, [0; 3], 0.0, &geom);
        let v = field(
            dims,
            |x, _, z| if (x / 2 + z) % 2 == 0 { -1.0 } else { 1.0 },
        );
        assert_same(&mut g, &v, dims, [0; 3], 0.0, &geom);
    }

    #[test]
    fn sphere_matches_the_cpu() {
        let Some(mut g) = gpu() else { return };
        let dims = [48, 41, 45];
        let geom = GridGeom::new([-3.0, 1.0, 2.5], 0.3, 100).unwrap();
        let origin = [2, 3, 4];
        let c = geom.node_position([26, 23, 27]);
        let v = field(dims, |x, y, z| {
            let p = geom.node_position([x as u64 + 2, y as u64 + 3, z as u64 + 4]);
            let d = ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt();
            (d - 5.3) as f32
        });
        let s = assert_same(&mut g, &v, dims, origin, 0.0, &geom);
        assert!(s.active_cells > 1000 && s.active_cells < s.cells / 4);
        // A sphere cut by the block's border, and one that misses it.
        assert_same(&mut g, &v, dims, origin, 4.0, &geom);
        let s = assert_same(&mut g, &v, dims, origin, -100.0, &geom);
        assert_eq!(s.active_cells, 0);
    }

    /// Values at iso (both zeros), NaN, infinities and subnormals classify as on the CPU.
    #[test]
    fn special_values_match_the_cpu() {
        let Some(mut g) = gpu() else { return };
        let specials = [
            0.0,
            -0.0,
            f32::NAN,
            -f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            1e-45,
            -1e-45,
            f32::MIN_POSITIVE,
            -1.0,
            1.0,
        ];
        let dims = [15, 14, 13];
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        let v = field(dims, |_, _, _| {
            specials[rng.random_range(0..specials.len())]
        });
        let geom = GridGeom::new([0.0; 3], 1.0, 50).unwrap();
        for iso in [0.0, -0.0, 1e-45, -1e-45, 1.0, f32::INFINITY, f32::NAN] {
            assert_same(&mut g, &v, dims, [0; 3], iso, &geom);
        }
    }

    /// A tiny buffer limit cuts the tile into slabs, bands or runs; the mesh is the same.
    #[test]
    fn sub_blocks_give_the_same_mesh() {
        let Some(mut g) = gpu() else { return };
        let geom = GridGeom::new([0.0, 1.0, 2.0], 0.5, 100).unwrap();
        let dims = [17, 9, 33];
        let rand = random_field(11, dims);
        let checker = field(
            dims,
            |x, y, z| if (x + y + z) % 2 == 0 { -1.0 } else { 1.0 },
        );
        let sphere = field(dims, |x, y, z| {
            let d = [x as f32 - 8.3, y as f32 - 4.1, z as f32 - 15.2];
            (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() - 6.0
        });
        // Whole, slabs of several layers, one layer, bands of rows, single rows, runs.
        for limit in [u64::MAX, 40_000, 8_000, 4_000, 1_500, 600, 200] {
            g.set_max_buffer_bytes(limit);
            let planned = plan(dims, g.max_buffer_bytes()).unwrap().len() as u64;
            for v in [&rand, &checker, &sphere] {
                let s = assert_same(&mut g, v, dims, [5, 6, 7], 0.0, &geom);
                // Sub-blocks whose triangles overflow are halved: more than planned.
                assert!(s.sub_blocks >= planned, "limit {limit}");
            }
            let want = planned;
            if limit < 40_000 {
                assert!(want > 1, "limit {limit}");
            }
        }
    }

    /// A GPU error on a tile sends it to the CPU: same mesh, `fell_back` set, and the next
    /// tile runs on the GPU again; after a panic, all later tiles run on the CPU.
    #[test]
    fn gpu_errors_fall_back_to_the_cpu() {
        let Some(mut g) = gpu() else { return };
        let dims = [12, 11, 10];
        let v = random_field(3, dims);
        let geom = GridGeom::new([0.0; 3], 1.0, 20).unwrap();
        let mut want = TileMesh::default();
        McWorkspace::new()
            .extract(&v, dims, [0; 3], 0.0, &geom, &mut want)
            .unwrap();
        g.fail_next = true;
        let mut got = TileMesh::default();
        let s = g.extract(&v, dims, [0; 3], 0.0, &geom, &mut got).unwrap();
        assert!(s.fell_back);
        assert_eq!(got, want);
        assert_same(&mut g, &v, dims, [0; 3], 0.0, &geom);
        // A panic inside the GPU path: this and later tiles go to the CPU, same mesh.
        g.panic_next = true;
        for _ in 0..2 {
            let s = g.extract(&v, dims, [0; 3], 0.0, &geom, &mut got).unwrap();
            assert!(s.fell_back);
            assert_eq!(got, want);
        }
        assert!(g.broken.is_some());
    }

    /// Bad shapes are the CPU kernel's errors; blocks without cells are empty.
    #[test]
    fn bad_shapes_are_the_cpu_errors() {
        let Some(mut g) = gpu() else { return };
        let geom = GridGeom::new([0.0; 3], 1.0, 4).unwrap();
        let mut m = TileMesh::default();
        let e = g.extract(&[0.0; 7], [2, 2, 2], [0; 3], 0.0, &geom, &mut m);
        assert!(matches!(e, Err(Error::Internal(_))));
        let e = g.extract(&[0.0; 8], [2, 2, 2], [4, 0, 0], 0.0, &geom, &mut m);
        assert!(matches!(e, Err(Error::Internal(_))));
        let s = g
            .extract(&[-1.0; 4], [2, 2, 1], [0; 3], 0.0, &geom, &mut m)
            .unwrap();
        assert_eq!((s.cells, s.fell_back), (0, false));
        assert!(m.triangles.is_empty());
    }
}
