//! The compute passes: the pipelines, built once from `shaders/`, the case tables they read,
//! and the dispatches of one sub-block (passes 0 to 5 of the [parent module's
//! docs](super)) with the read-back of their outputs.

use std::time::Instant;

use wgpu::BufferUsages as U;
use wgpu::util::DeviceExt;

use super::buffers::{self, Buffers, ensure};
use super::leaf_pool::LeafPool;
use super::{BlockValues, GpuExtractor, GpuResult, GpuStats, adapter};
use crate::extract::tables;

/// Items one workgroup of `scan.wgsl` scans.
const SCAN_BLOCK: u64 = 1024;
/// Threads per workgroup of every shader.
const WG: u64 = 256;
/// Layout of the tables buffer (`common.wgsl`): triangle-edge starts at 0, crossing-edge
/// starts at `USED_START`, case info at `CASE_INFO`, the edge lists from `TABLE_HEAD` on.
pub(super) const USED_START: usize = 257;
pub(super) const CASE_INFO: usize = 514;
const TABLE_HEAD: usize = 770;
/// Bytes of one node's counts (`classify.wgsl`: vertices, active, triangles, padding) and of
/// one block sum of `scan.wgsl`.
const COUNT_BYTES: u64 = 16;
/// Bytes of the totals read back after pass 2: vertices, active cells, triangles, padding.
const TOTALS_BYTES: u64 = 16;
/// Bytes of a vertex record (block-local edge id, bit 31 on seams).
const RECORD_BYTES: u64 = 4;
/// Bytes of the bits of a record's two node values (fields built on the device).
const ENDS_BYTES: u64 = 8;
/// Bytes of a triangle: three `u32` record indices.
const TRIANGLE_BYTES: u64 = 12;
/// Bytes of an active cell's entry in the compacted list: its node index.
const CELL_BYTES: u64 = 4;

/// The compute pipelines, created once.
pub(super) struct Pipelines {
    /// `None` without 64-bit integers in shaders: blended tiles are blended on the host.
    pub(super) field: Option<wgpu::ComputePipeline>,
    classify: wgpu::ComputePipeline,
    scan: wgpu::ComputePipeline,
    add: wgpu::ComputePipeline,
    compact: wgpu::ComputePipeline,
    vertices: wgpu::ComputePipeline,
    triangles: wgpu::ComputePipeline,
}

impl Pipelines {
    /// Compile the shaders (`field.wgsl` only with 64-bit integers, `int64`). Errors are
    /// reported through the device's error scopes.
    pub(super) fn new(device: &wgpu::Device, int64: bool) -> Pipelines {
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
        Pipelines {
            field: int64
                .then(|| pipeline("field.wgsl", include_str!("shaders/field.wgsl"), "main")),
            classify: pipeline("classify.wgsl", &classify, "main"),
            scan: pipeline("scan.wgsl", scan, "scan_blocks"),
            add: pipeline("scan.wgsl", scan, "add_block_sums"),
            compact: pipeline("compact.wgsl", &compact, "main"),
            vertices: pipeline("emit.wgsl", &emit, "vertices"),
            triangles: pipeline("emit.wgsl", &emit, "triangles"),
        }
    }
}

/// The case tables on the device ([`table_words`]).
pub(super) fn tables_buffer(device: &wgpu::Device) -> wgpu::Buffer {
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("case tables"),
        contents: bytemuck::cast_slice(&table_words()),
        usage: U::STORAGE,
    })
}

/// The case tables as one array of words (layout in `common.wgsl`).
pub(super) fn table_words() -> Vec<u32> {
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
pub(super) fn iso_key(iso: f32) -> u32 {
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

/// One sub-block to run.
#[derive(Clone, Copy)]
pub(super) struct BlockJob<'a> {
    /// Where its node values come from.
    pub(super) values: BlockValues<'a>,
    /// Its nodes per axis.
    pub(super) dims: [usize; 3],
    /// [`iso_key`] of the iso-value.
    pub(super) iso_key: u32,
    /// [`super::plan::SubBlock::seam_mask`].
    pub(super) seam_mask: u32,
}

impl BlockJob<'_> {
    fn nodes(&self) -> u64 {
        self.dims.iter().map(|&d| d as u64).product()
    }

    fn cells(&self) -> u64 {
        self.dims.iter().map(|&d| d as u64 - 1).product()
    }
}

/// What one sub-block gave.
pub(super) enum BlockOutcome {
    /// Its records are in `GpuExtractor::records`, its triangles (record indices) appended
    /// to the mesh.
    Done,
    /// Its triangles would exceed the buffer limit: halve it and redo.
    TooBig,
}

/// A sub-block after passes 0 to 2: its buffers and totals.
struct Counted {
    values: wgpu::Buffer,
    counts: wgpu::Buffer,
    node_params: wgpu::Buffer,
    node_grid: (u32, u32),
    vertices: u64,
    active: u64,
    triangles: u64,
}

/// The outputs of passes 3 to 5 on the device, and their read-back buffers.
struct Emitted {
    records: wgpu::Buffer,
    ends: wgpu::Buffer,
    tris: wgpu::Buffer,
    records_read: wgpu::Buffer,
    tris_read: wgpu::Buffer,
}

fn uniform(dev: &wgpu::Device, words: &[u32]) -> wgpu::Buffer {
    dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("parameters"),
        contents: bytemuck::cast_slice(words),
        usage: U::UNIFORM,
    })
}

/// The `Block` parameters of `common.wgsl` for a pass of `threads` threads.
fn block_params(dev: &wgpu::Device, job: &BlockJob<'_>, threads: u64, gx: u32) -> wgpu::Buffer {
    let d = job.dims;
    let words = [d[0], d[1], d[2]].map(|v| v as u32);
    uniform(
        dev,
        &[
            words[0],
            words[1],
            words[2],
            threads as u32,
            gx,
            job.iso_key,
            job.seam_mask,
            0,
        ],
    )
}

/// A bind group of `bufs` at bindings `0..` of group 0 of `p`.
fn bind(dev: &wgpu::Device, p: &wgpu::ComputePipeline, bufs: &[&wgpu::Buffer]) -> wgpu::BindGroup {
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
}

impl GpuExtractor {
    /// Passes 0 to 5 on one sub-block, under error scopes: fills `self.records` (and
    /// `self.ends` for fields built on the device) and appends its triangles (record indices)
    /// to `tris`. After an error the buffers and the leaf pool are dropped, as they may be
    /// left mapped or invalid.
    pub(super) fn run_block(
        &mut self,
        job: BlockJob<'_>,
        stats: &mut GpuStats,
        tris: &mut Vec<[u32; 3]>,
    ) -> GpuResult<BlockOutcome> {
        let scopes = adapter::push_scopes(&self.device);
        let res = self.run_block_scoped(job, stats, tris);
        let (mut errors, lost) = adapter::pop_scopes(scopes, &self.trouble);
        if lost.is_some() {
            self.broken = lost;
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

    fn run_block_scoped(
        &mut self,
        job: BlockJob<'_>,
        stats: &mut GpuStats,
        out_tris: &mut Vec<[u32; 3]>,
    ) -> GpuResult<BlockOutcome> {
        #[cfg(test)]
        self.inject_failures();
        let values = self.stage_values(&job, stats)?;
        let t0 = Instant::now();
        let c = self.count(&job, values)?;
        self.records.clear();
        if c.active == 0 {
            stats.kernel_secs += t0.elapsed().as_secs_f64();
            return Ok(BlockOutcome::Done);
        }
        if (TRIANGLE_BYTES * c.triangles).max(RECORD_BYTES * c.vertices) > self.max_bytes {
            stats.kernel_secs += t0.elapsed().as_secs_f64();
            return Ok(BlockOutcome::TooBig);
        }
        stats.active_cells += c.active;
        let e = self.emit(&job, &c)?;
        stats.kernel_secs += t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        self.read_back(&job, &c, &e, out_tris)?;
        stats.download_secs += t0.elapsed().as_secs_f64();
        Ok(BlockOutcome::Done)
    }

    /// Test hooks: a panic, or a validation error, in this sub-block.
    #[cfg(test)]
    fn inject_failures(&mut self) {
        if std::mem::take(&mut self.panic_next) {
            panic!("injected panic");
        }
        if std::mem::take(&mut self.fail_next) {
            // An invalid buffer (MAP_READ only goes with COPY_DST): a validation error,
            // caught by the scopes like a real one.
            let _ = self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("injected failure"),
                size: 16,
                usage: U::STORAGE | U::MAP_READ,
                mapped_at_creation: false,
            });
        }
    }

    /// The buffer of the sub-block's node values, uploaded when the host has them.
    fn stage_values(
        &mut self,
        job: &BlockJob<'_>,
        stats: &mut GpuStats,
    ) -> GpuResult<wgpu::Buffer> {
        let cap = self.device_max_bytes;
        let values = ensure(
            &self.device,
            &mut self.bufs.values,
            "values",
            4 * job.nodes(),
            U::STORAGE | U::COPY_DST,
            cap,
        );
        if let BlockValues::Host(host) = job.values {
            let t0 = Instant::now();
            let (dev, queue) = (&self.device, &self.queue);
            let sent = buffers::upload(dev, queue, &mut self.bufs.upload, &values, host, cap)?;
            stats.upload_secs += t0.elapsed().as_secs_f64();
            stats.upload_bytes += sent;
        }
        Ok(values)
    }

    /// The scan's levels: the counts, then block sums until one workgroup covers a level.
    fn scan_levels(&mut self, n: u64, counts: wgpu::Buffer) -> GpuResult<Vec<(u64, wgpu::Buffer)>> {
        let mut levels = vec![(n, counts)];
        while let Some(&(m, _)) = levels.last().filter(|l| l.0 > SCAN_BLOCK) {
            let i = levels.len() - 1;
            let Some(slot) = self.bufs.sums.get_mut(i) else {
                return Err(format!("{n} nodes need too many scan levels"));
            };
            let m = m.div_ceil(SCAN_BLOCK);
            let bytes = COUNT_BYTES * m;
            let cap = self.device_max_bytes;
            let sums = ensure(&self.device, slot, "block sums", bytes, U::STORAGE, cap);
            levels.push((m, sums));
        }
        Ok(levels)
    }

    /// Passes 0 (a blended field), 1 (classify) and 2 (scan), and the totals read back and
    /// checked against the cell count.
    fn count(&mut self, job: &BlockJob<'_>, values: wgpu::Buffer) -> GpuResult<Counted> {
        let n = job.nodes();
        let cap = self.device_max_bytes;
        let dev = self.device.clone();
        let b = &mut self.bufs;
        let counts = ensure(
            &dev,
            &mut b.counts,
            "counts",
            COUNT_BYTES * n,
            U::STORAGE,
            cap,
        );
        let levels = self.scan_levels(n, counts.clone())?;
        let b = &mut self.bufs;
        let totals_usage = U::STORAGE | U::COPY_SRC;
        let totals = ensure(
            &dev,
            &mut b.totals,
            "totals",
            TOTALS_BYTES,
            totals_usage,
            cap,
        );
        let read_usage = U::MAP_READ | U::COPY_DST;
        let totals_read = ensure(
            &dev,
            &mut b.totals_read,
            "totals read-back",
            TOTALS_BYTES,
            read_usage,
            cap,
        );
        let node_grid = grid(n.div_ceil(WG), self.max_dim);
        let node_params = block_params(&dev, job, n, node_grid.0);
        let p = &self.pipelines;
        let classify = bind(
            &dev,
            &p.classify,
            &[&node_params, &values, &self.tables, &counts],
        );
        let mut scans = Vec::new();
        for (i, (m, data)) in levels.iter().enumerate() {
            let g = grid(m.div_ceil(SCAN_BLOCK), self.max_dim);
            let prm = uniform(&dev, &[*m as u32, g.0, 0, 0]);
            let sums = levels.get(i + 1).map_or(&totals, |l| &l.1);
            let scan = bind(&dev, &p.scan, &[&prm, data, sums]);
            let add = bind(&dev, &p.add, &[&prm, data, sums]);
            scans.push((g, scan, add));
        }
        let field = match job.values {
            BlockValues::Device(at, words) => {
                Some(self.field_pass(job, at, words, node_grid, &values)?)
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
        enc.copy_buffer_to_buffer(&totals, 0, &totals_read, 0, TOTALS_BYTES);
        self.queue.submit([enc.finish()]);
        let mut tot: Vec<u32> = Vec::new();
        buffers::read(&dev, &totals_read, TOTALS_BYTES, &mut tot)?;
        let [vertices, active, triangles] = [tot[0] as u64, tot[1] as u64, tot[2] as u64];
        let cells = job.cells();
        if active > cells || triangles > 5 * active || vertices > 12 * active {
            return Err(format!(
                "inconsistent totals: {vertices} vertices, {active} active cells, {triangles} \
                 triangles for {cells} cells"
            ));
        }
        Ok(Counted {
            values,
            counts,
            node_params,
            node_grid,
            vertices,
            active,
            triangles,
        })
    }

    /// Pass 0's pipeline and bind group: `field.wgsl` on a sub-block at node `at` of a
    /// blended tile whose parameter words (from `lox` on) are `words`.
    fn field_pass(
        &self,
        job: &BlockJob<'_>,
        at: [usize; 3],
        words: &[u32; 20],
        node_grid: (u32, u32),
        values: &wgpu::Buffer,
    ) -> GpuResult<(&wgpu::ComputePipeline, wgpu::BindGroup)> {
        let dims = job.dims;
        let mut w = vec![
            dims[0] as u32,
            dims[1] as u32,
            dims[2] as u32,
            job.nodes() as u32,
            node_grid.0,
            at[0] as u32,
            at[1] as u32,
            at[2] as u32,
        ];
        w.extend_from_slice(words);
        let dev = &self.device;
        let prm = uniform(dev, &w);
        let b = &self.bufs;
        let need = |o: &Option<wgpu::Buffer>| o.clone().ok_or("blend tables missing");
        let pool = self.pool.buffer().ok_or("no leaf pool")?;
        let (axes, coarse, own, slots) = (
            need(&b.axes)?,
            need(&b.coarse)?,
            need(&b.own)?,
            need(&b.slots)?,
        );
        let pipeline = self.pipelines.field.as_ref().ok_or("no field pipeline")?;
        let group = bind(
            dev,
            pipeline,
            &[&prm, &axes, &coarse, &own, &slots, &pool, values],
        );
        Ok((pipeline, group))
    }

    /// Passes 3 (compact), 4 (vertex records) and 5 (triangles), waited for.
    fn emit(&mut self, job: &BlockJob<'_>, c: &Counted) -> GpuResult<Emitted> {
        let cap = self.device_max_bytes;
        let dev = self.device.clone();
        let b = &mut self.bufs;
        let cells_bytes = CELL_BYTES * c.active;
        let cells_buf = ensure(
            &dev,
            &mut b.cells,
            "active cells",
            cells_bytes,
            U::STORAGE,
            cap,
        );
        let out_usage = U::STORAGE | U::COPY_SRC;
        let read_usage = U::MAP_READ | U::COPY_DST;
        let (rec_bytes, ends_bytes) = (RECORD_BYTES * c.vertices, ENDS_BYTES * c.vertices);
        let tri_bytes = TRIANGLE_BYTES * c.triangles;
        let e = Emitted {
            records: ensure(
                &dev,
                &mut b.records,
                "vertex records",
                rec_bytes,
                out_usage,
                cap,
            ),
            ends: ensure(&dev, &mut b.ends, "edge ends", ends_bytes, out_usage, cap),
            tris: ensure(&dev, &mut b.tris, "triangles", tri_bytes, out_usage, cap),
            records_read: ensure(
                &dev,
                &mut b.records_read,
                "record read-back",
                rec_bytes,
                read_usage,
                cap,
            ),
            tris_read: ensure(
                &dev,
                &mut b.tris_read,
                "triangle read-back",
                tri_bytes,
                read_usage,
                cap,
            ),
        };
        let p = &self.pipelines;
        let compact = bind(&dev, &p.compact, &[&c.node_params, &c.counts, &cells_buf]);
        let cell_grid = grid(c.active.div_ceil(WG), self.max_dim);
        let cell_params = block_params(&dev, job, c.active, cell_grid.0);
        let vertex_bufs = [
            &cell_params,
            &c.counts,
            &cells_buf,
            &self.tables,
            &e.records,
            &c.values,
            &e.ends,
        ];
        let vertices = bind(&dev, &p.vertices, &vertex_bufs);
        let triangle_bufs = [&cell_params, &c.counts, &cells_buf, &self.tables, &e.tris];
        let triangles = bind(&dev, &p.triangles, &triangle_bufs);
        let mut enc = dev.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&p.compact);
            pass.set_bind_group(0, &compact, &[]);
            pass.dispatch_workgroups(c.node_grid.0, c.node_grid.1, 1);
            pass.set_pipeline(&p.vertices);
            pass.set_bind_group(0, &vertices, &[]);
            pass.dispatch_workgroups(cell_grid.0, cell_grid.1, 1);
            pass.set_pipeline(&p.triangles);
            pass.set_bind_group(0, &triangles, &[]);
            pass.dispatch_workgroups(cell_grid.0, cell_grid.1, 1);
        }
        self.queue.submit([enc.finish()]);
        buffers::wait(&dev)?;
        Ok(e)
    }

    /// Read back the compacted outputs only: the records into `self.records`, for a field
    /// built on the device the node values of their edges into `self.ends`, and the triangles
    /// onto `out_tris`.
    fn read_back(
        &mut self,
        job: &BlockJob<'_>,
        c: &Counted,
        e: &Emitted,
        out_tris: &mut Vec<[u32; 3]>,
    ) -> GpuResult<()> {
        let dev = self.device.clone();
        let (rec_bytes, ends_bytes) = (RECORD_BYTES * c.vertices, ENDS_BYTES * c.vertices);
        let tri_bytes = TRIANGLE_BYTES * c.triangles;
        let device_values = matches!(job.values, BlockValues::Device(..));
        let ends_read = device_values.then(|| {
            ensure(
                &dev,
                &mut self.bufs.ends_read,
                "edge ends read-back",
                ends_bytes,
                U::MAP_READ | U::COPY_DST,
                self.device_max_bytes,
            )
        });
        let mut enc = dev.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(&e.records, 0, &e.records_read, 0, rec_bytes);
        if let Some(er) = &ends_read {
            enc.copy_buffer_to_buffer(&e.ends, 0, er, 0, ends_bytes);
        }
        if c.triangles > 0 {
            enc.copy_buffer_to_buffer(&e.tris, 0, &e.tris_read, 0, tri_bytes);
        }
        self.queue.submit([enc.finish()]);
        buffers::read(&dev, &e.records_read, rec_bytes, &mut self.records)?;
        self.ends.clear();
        if let Some(er) = &ends_read {
            buffers::read(&dev, er, ends_bytes, &mut self.ends)?;
        }
        buffers::read(&dev, &e.tris_read, tri_bytes, out_tris)
    }
}
