//! The device side of the solve: opening the adapter's device with the pipelines of
//! `shaders/solve.wgsl` and the constant tables of the grid shape, the limits that size a
//! batch, the buffers of a batch (grown as needed), and reading buffers back.

use std::sync::mpsc;
use std::sync::{Arc, Mutex};

use wgpu::BufferUsages as U;

use super::kernels::Pipelines;
use crate::extract::gpu::adapter::{self, Trouble, describe};
use crate::fft_solve::Solver;

/// Bytes of device memory a batch may use at most.
const BATCH_BYTES: u64 = 1 << 30;
/// Leaves in a batch at most.
const MAX_BATCH: usize = 64;
/// Device bytes a node takes: six float vectors and a complex one.
const NODE_BYTES: u64 = 6 * 4 + 8;
/// Threads per workgroup of `solve.wgsl` (but `scalars`).
const WG: u32 = 256;

/// Buffers of one batch shape, grown as needed.
#[derive(Default)]
pub(super) struct Buffers {
    pub(super) vecs: Option<wgpu::Buffer>,
    pub(super) cpx: Option<wgpu::Buffer>,
    pub(super) idx: Option<wgpu::Buffer>,
    pub(super) sw: Option<wgpu::Buffer>,
    pub(super) sdyn: Option<wgpu::Buffer>,
    pub(super) scal: Option<wgpu::Buffer>,
    pub(super) params: Option<wgpu::Buffer>,
    pub(super) read_scal: Option<wgpu::Buffer>,
    pub(super) read_x: Option<wgpu::Buffer>,
}

/// The device side: device, queue, pipelines, the constant tables of the grid shape.
pub(super) struct Device {
    pub(super) device: wgpu::Device,
    pub(super) queue: wgpu::Queue,
    pub(super) info: wgpu::AdapterInfo,
    pub(super) trouble: Arc<Mutex<Trouble>>,
    pub(super) layout: wgpu::BindGroupLayout,
    pub(super) pipes: Pipelines,
    pub(super) consts: wgpu::Buffer,
    pub(super) n: usize,
    pub(super) h1: usize,
    pub(super) max_batch: usize,
    pub(super) max_dim: u32,
    pub(super) align: u64,
    pub(super) bufs: Buffers,
}

/// Leaves of `nn` nodes a batch may hold on a device with `limits` (0: not one).
pub(super) fn batch_cap(limits: &wgpu::Limits, nn: u64) -> usize {
    let max_binding = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size);
    let by_bytes = (BATCH_BYTES / (nn * NODE_BYTES))
        .min(max_binding / (nn * 4 * 6))
        .min((u32::MAX as u64) / (nn * 6));
    (by_bytes as usize).min(MAX_BATCH)
}

/// A buffer of at least `size` bytes in `slot` (grown to the next power of two).
pub(super) fn ensure(
    device: &wgpu::Device,
    slot: &mut Option<wgpu::Buffer>,
    label: &str,
    size: u64,
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    let size = size.max(16);
    if let Some(b) = slot
        && b.size() >= size
    {
        return b.clone();
    }
    let b = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.next_power_of_two(),
        usage,
        mapped_at_creation: false,
    });
    *slot = Some(b.clone());
    b
}

/// The constant tables of `n`'s grid shape (`h1 = n/2 + 1`), as `solve.wgsl` reads them:
/// twiddles exp(−2πik/n) for k < n (pairs: the radix-3 stage reads up to 2(n/3 − 1)), |k|²
/// by folded index (`k2`), the Poisson filter.
fn constants(n: usize, h1: usize, k2: &[f32], filter: &[f32]) -> Vec<f32> {
    let mut c = Vec::with_capacity(2 * n + h1 + filter.len());
    for k in 0..n {
        let a = -2.0 * std::f64::consts::PI * k as f64 / n as f64;
        c.push(a.cos() as f32);
        c.push(a.sin() as f32);
    }
    c.extend_from_slice(k2);
    c.extend_from_slice(filter);
    c
}

impl Device {
    /// Open adapter `ad`'s device for `solver`'s grids: its pipelines, the constant tables
    /// written, the batch sized to its limits; an error where a grid exceeds them or the
    /// pipelines do not build.
    pub(super) fn open(ad: &wgpu::Adapter, solver: &Solver) -> std::result::Result<Device, String> {
        let info = ad.get_info();
        let opened = adapter::open_device(ad, &info)?;
        let device = opened.device;
        let limits = opened.limits;
        let (n, k2, filter) = solver.tables();
        let h1 = n / 2 + 1;
        let nn = (n * n * n) as u64;
        let max_batch = batch_cap(&limits, nn);
        if max_batch == 0 {
            return Err(format!(
                "a leaf grid of {n}³ nodes exceeds the buffers of {}",
                describe(&info)
            ));
        }
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let (layout, pipes) = Pipelines::build(&device);
        let c = constants(n, h1, k2, &filter);
        let consts = ensure(
            &device,
            &mut None,
            "solve constants",
            (c.len() * 4) as u64,
            U::STORAGE | U::COPY_DST,
        );
        opened
            .queue
            .write_buffer(&consts, 0, bytemuck::cast_slice(&c));
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(format!(
                "could not build the solve's pipelines on {}: {e}",
                describe(&info)
            ));
        }
        Ok(Device {
            device,
            queue: opened.queue,
            info,
            trouble: opened.trouble,
            layout,
            pipes,
            consts,
            n,
            h1,
            max_batch,
            max_dim: limits.max_compute_workgroups_per_dimension,
            align: limits.min_uniform_buffer_offset_alignment.max(16) as u64,
            bufs: Buffers::default(),
        })
    }

    /// The reason the device was lost, if it was.
    pub(super) fn lost(&self) -> Option<String> {
        self.trouble.lock().ok().and_then(|t| t.lost.clone())
    }

    /// `(gx, gy)` for `count` threads of 256.
    pub(super) fn groups(&self, count: u64) -> (u32, u32) {
        let g = count.div_ceil(WG as u64).max(1);
        let gx = g.min(self.max_dim as u64);
        (gx as u32, g.div_ceil(gx) as u32)
    }
}

pub(super) fn entry(binding: u32, buf: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: buf.as_entire_binding(),
    }
}

/// Read the first `bytes` of the mappable `buf` into `out` (after all submitted work).
pub(super) fn read_back(
    device: &wgpu::Device,
    buf: &wgpu::Buffer,
    bytes: u64,
    out: &mut Vec<f32>,
) -> std::result::Result<(), String> {
    mapped(device, buf, bytes, |v| out.extend_from_slice(v))
}

/// Map the first `bytes` of `buf` once all submitted work is done and hand them to `f`.
pub(super) fn mapped(
    device: &wgpu::Device,
    buf: &wgpu::Buffer,
    bytes: u64,
    f: impl FnOnce(&[f32]),
) -> std::result::Result<(), String> {
    let (tx, rx) = mpsc::channel();
    buf.map_async(wgpu::MapMode::Read, 0..bytes, move |r| {
        let _ = tx.send(r);
    });
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| format!("waiting for the GPU: {e}"))?;
    match rx.try_recv() {
        Ok(Ok(())) => {}
        Ok(Err(e)) => return Err(format!("mapping a read-back buffer: {e}")),
        Err(_) => return Err("a read-back buffer was not mapped".into()),
    }
    {
        let view = buf
            .get_mapped_range(0..bytes)
            .map_err(|e| format!("reading back: {e}"))?;
        f(bytemuck::cast_slice(&view));
    }
    buf.unmap();
    Ok(())
}
