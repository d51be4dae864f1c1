//! Device buffers: grow-only buffers reused from tile to tile, waiting for the device, mapping
//! and reading back, and the staged upload of node values.

use std::sync::mpsc;

use rayon::prelude::*;

use super::GpuResult;

/// Largest buffer used: `u32` indices address it in 4-byte words, and `3·triangles` fits.
pub(super) const MAX_BUFFER_BYTES: u64 = (1 << 32) - 16;
/// Bytes one thread copies at a time to or from mapped memory.
const COPY_CHUNK: usize = 8 << 20;
/// Buffer sizes are rounded up to this (bytes), so that slowly growing tiles do not make a
/// new buffer each time.
const GROWTH_ROUNDING: u64 = 1 << 16;

/// Grow-only device buffers, reused from tile to tile.
#[derive(Default)]
pub(super) struct Buffers {
    pub(super) upload: Option<wgpu::Buffer>,
    pub(super) values: Option<wgpu::Buffer>,
    pub(super) counts: Option<wgpu::Buffer>,
    pub(super) sums: [Option<wgpu::Buffer>; 3],
    pub(super) totals: Option<wgpu::Buffer>,
    pub(super) totals_read: Option<wgpu::Buffer>,
    pub(super) cells: Option<wgpu::Buffer>,
    pub(super) records: Option<wgpu::Buffer>,
    pub(super) ends: Option<wgpu::Buffer>,
    pub(super) tris: Option<wgpu::Buffer>,
    pub(super) records_read: Option<wgpu::Buffer>,
    pub(super) ends_read: Option<wgpu::Buffer>,
    pub(super) tris_read: Option<wgpu::Buffer>,
    pub(super) axes: Option<wgpu::Buffer>,
    pub(super) coarse: Option<wgpu::Buffer>,
    pub(super) own: Option<wgpu::Buffer>,
    pub(super) slots: Option<wgpu::Buffer>,
}

/// A buffer of at least `need` bytes from `slot`, replaced by one a quarter larger (within
/// `cap`) when smaller.
pub(super) fn ensure(
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
                .next_multiple_of(GROWTH_ROUNDING)
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

/// Wait until the device has done all work submitted.
pub(super) fn wait(device: &wgpu::Device) -> GpuResult<()> {
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map(|_| ())
        .map_err(|e| format!("waiting for the GPU: {e}"))
}

/// Map the first `bytes` bytes of `buf` (`what`, for errors) and wait for it.
fn map(
    device: &wgpu::Device,
    buf: &wgpu::Buffer,
    mode: wgpu::MapMode,
    bytes: u64,
    what: &str,
) -> GpuResult<()> {
    let (tx, rx) = mpsc::channel();
    buf.map_async(mode, 0..bytes, move |r| {
        let _ = tx.send(r);
    });
    wait(device)?;
    match rx.try_recv() {
        Ok(Ok(())) => Ok(()),
        Ok(Err(e)) => Err(format!("mapping {what}: {e}")),
        Err(_) => Err(format!("{what} was not mapped")),
    }
}

/// Append the first `bytes` bytes of the read-back buffer `buf` to `out`.
pub(super) fn read<T: bytemuck::Pod + Send + Sync>(
    device: &wgpu::Device,
    buf: &wgpu::Buffer,
    bytes: u64,
    out: &mut Vec<T>,
) -> GpuResult<()> {
    if bytes == 0 {
        return Ok(());
    }
    map(
        device,
        buf,
        wgpu::MapMode::Read,
        bytes,
        "a read-back buffer",
    )?;
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

/// Upload `values` into `dst` through the staging buffer `upload` (grown within `cap`),
/// filled on all cores; returns the bytes sent.
pub(super) fn upload(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    upload: &mut Option<wgpu::Buffer>,
    dst: &wgpu::Buffer,
    values: &[f32],
    cap: u64,
) -> GpuResult<u64> {
    use wgpu::BufferUsages as U;
    let bytes: &[u8] = bytemuck::cast_slice(values);
    let len = bytes.len() as u64;
    let write_usage = U::MAP_WRITE | U::COPY_SRC;
    let staging = ensure(device, upload, "values upload", len, write_usage, cap);
    map(
        device,
        &staging,
        wgpu::MapMode::Write,
        len,
        "the upload buffer",
    )?;
    {
        let mut view = staging
            .get_mapped_range_mut(0..len)
            .map_err(|e| format!("writing the upload buffer: {e}"))?;
        copy_parallel(view.slice(..), bytes);
    }
    staging.unmap();
    let mut enc = device.create_command_encoder(&Default::default());
    enc.copy_buffer_to_buffer(&staging, 0, dst, 0, len);
    queue.submit([enc.finish()]);
    wait(device)?;
    Ok(len)
}
