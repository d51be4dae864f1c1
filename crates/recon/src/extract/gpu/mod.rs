//! Marching cubes on the GPU (wgpu compute, WGSL in `shaders/`), one tile at a time, giving
//! exactly the mesh of [`cpu::marching_cubes`](super::cpu::marching_cubes): the same keys in the same order, bitwise the
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
//!    [`tables::case_edges`](super::tables::case_edges): the CPU kernel's order of first use.
//! 5. `emit.wgsl` `triangles`, a thread per active cell: its triangles in the order of the
//!    case table, as indices into the records, found in each edge's first cell.
//!
//! Only the records (4 bytes a vertex) and the triangles (12 bytes each) are read back.
//!
//! # Blended tiles: the field built on the device
//!
//! [`GpuExtractor::extract_blend`] takes a tile as a partition-of-unity blend
//! ([`super::field`]) instead of node values. The leaves' detail grids go to a pool of slots
//! in one device buffer, least recently used replaced first (the crate's one LRU,
//! [`crate::exec::cache::Lru`]), so a leaf shared by neighbouring tiles crosses the bus once
//! while it stays resident; with them go the coarse values around the tile, per-axis tables
//! and a lookup box from leaf cell to slot. Pass 0 (`field.wgsl`, a
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
//!
//! # Code map
//!
//! This file holds the public API and the per-tile driver (fallbacks, sub-blocks in order);
//! `adapter` picks and opens the device and collects its errors, `plan` cuts tiles into
//! sub-blocks, `passes` builds the pipelines and dispatches passes 0 to 5, `buffers` sizes,
//! maps and reads the device buffers, `leaf_pool` keeps the resident leaf grids, and
//! `assemble` turns a sub-block's records into the tile's mesh on the host.

pub(crate) mod adapter;
mod assemble;
mod buffers;
mod leaf_pool;
mod passes;
mod plan;
#[cfg(test)]
mod tests;

use std::collections::VecDeque;
use std::fmt;
use std::str::FromStr;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use self::adapter::{Trouble, describe};
use self::assemble::{Assembly, Seams};
use self::buffers::Buffers;
use self::leaf_pool::{LeafPool, TileWords};
use self::passes::{BlockJob, BlockOutcome, Pipelines};
use self::plan::SubBlock;
use crate::error::{Error, Result, Setting};
use crate::extract::cpu::McWorkspace;
use crate::extract::field::BlendEval;
use crate::types::{Blend, GridGeom, TileMesh};

pub use self::adapter::adapter_names;

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
                "{} {s:?}: expected one of auto, on, off",
                Setting::Gpu
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
    Device([usize; 3], &'a TileWords),
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
    /// Seam edges of the tile so far, and scratch for renumbering.
    seams: Seams,
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
        let (best, found) = adapter::select(mode);
        let Some(adapter) = best else {
            if mode == GpuMode::On {
                return Err(adapter::none_found(Setting::Gpu, &found));
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
            Err(e) if mode == GpuMode::On => Err(Error::Usage(format!("{} on: {e}", Setting::Gpu))),
            Err(e) => {
                log::warn!("marching cubes on the CPU: {e}");
                Ok(None)
            }
        }
    }

    /// Open the device and build the pipelines and the case tables.
    fn open(adapter: wgpu::Adapter) -> GpuResult<GpuExtractor> {
        let info = adapter.get_info();
        let opened = adapter::open_device(&adapter, &info)?;
        let device = opened.device;
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let pipelines = Pipelines::new(&device, opened.int64);
        let tables = passes::tables_buffer(&device);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(format!(
                "could not build the compute pipelines on {}: {e}",
                describe(&info)
            ));
        }
        let limits = opened.limits;
        let device_max_bytes = limits
            .max_buffer_size
            .min(limits.max_storage_buffer_binding_size)
            .min(buffers::MAX_BUFFER_BYTES);
        Ok(GpuExtractor {
            device,
            queue: opened.queue,
            info,
            max_dim: limits.max_compute_workgroups_per_dimension,
            device_max_bytes,
            max_bytes: device_max_bytes,
            pipelines,
            tables,
            bufs: Buffers::default(),
            trouble: opened.trouble,
            broken: None,
            cpu: McWorkspace::new(),
            pool: LeafPool::default(),
            gather: Vec::new(),
            records: Vec::new(),
            ends: Vec::new(),
            seams: Seams::default(),
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
    /// [`super::cpu::marching_cubes`]). A GPU failure sends the tile to the CPU, with a
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
            .and_then(|()| {
                if blend.lo.iter().any(|&v| v < 0) {
                    Err("a tile below the cube's first node".to_string())
                } else {
                    Ok(())
                }
            })
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

    /// The tile on the GPU: its sub-blocks in order, each run (and halved while its
    /// triangles exceed the buffer limit) and assembled into `out`.
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
        let iso_key = passes::iso_key(iso);
        self.seams.clear();
        let mut todo: VecDeque<SubBlock> = plan::plan(dims, self.max_bytes)?.into();
        while let Some(b) = todo.pop_front() {
            let mut gather = std::mem::take(&mut self.gather);
            let job = BlockJob {
                values: match &tile_words {
                    Some(w) => BlockValues::Device(b.at, w),
                    None => BlockValues::Host(block_values(values, dims, b, &mut gather)),
                },
                dims: b.dims,
                iso_key,
                seam_mask: b.seam_mask(dims),
            };
            let tri_start = out.triangles.len();
            let res = self.run_block(job, &mut stats, &mut out.triangles);
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
            let at = Assembly {
                values,
                ends: tile_words.is_some().then_some(&self.ends[..]),
                dims,
                origin_node,
                iso,
                block: b,
            };
            assemble::assemble(at, &mut self.records, &mut self.seams, geom, out, tri_start)?;
            stats.host_secs += t0.elapsed().as_secs_f64();
        }
        Ok(stats)
    }
}

/// The node values of sub-block `b` of a tile of `dims` nodes with `values`: a slice of them
/// for whole layers, else gathered into `gather`.
fn block_values<'a>(
    values: &'a [f32],
    dims: [usize; 3],
    b: SubBlock,
    gather: &'a mut Vec<f32>,
) -> &'a [f32] {
    let l = dims[0] * dims[1];
    if b.dims[0] == dims[0] && b.dims[1] == dims[1] {
        return &values[b.at[2] * l..(b.at[2] + b.dims[2]) * l];
    }
    gather.clear();
    for z in b.at[2]..b.at[2] + b.dims[2] {
        for y in b.at[1]..b.at[1] + b.dims[1] {
            let r = z * l + y * dims[0] + b.at[0];
            gather.extend_from_slice(&values[r..r + b.dims[0]]);
        }
    }
    gather
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
