//! The leaves' fine solves on a GPU (`--gpu-solve`): the screened FFT Poisson solve of
//! [`super::fft_solve`] (Kazhdan 2005, §4; Kazhdan & Hoppe 2013, §4) run on the device for a
//! batch of leaves at once (WGSL in `shaders/solve.wgsl`).
//!
//! # What runs where
//!
//! A worker splats its leaf's normals, takes their divergence and builds the screening
//! operator on the host, as the CPU solve does ([`Solver::divergence`], [`Screen`]), adds the
//! transposed lists the device's scatter needs (per touched node, its aggregates' entries in
//! aggregate order), and hands the leaf to the one thread that owns the device. That thread
//! takes every leaf waiting (up to a batch that fits the device's buffers) and runs, with one
//! dispatch per step for the whole batch:
//!
//! 1. the Poisson solve: the divergence transformed along x, y and z (complex FFTs of lines
//!    of a power of two or three times one, as a leaf's `1.5E` nodes are: radix-2 stages,
//!    then one radix-3 stage; `max(1, 512/n)` lines per workgroup in workgroup memory, the
//!    twiddles tabulated in f64 on the host),
//!    multiplied by the solver's filter table `−G_σ(k)/|k|²`, transformed back;
//! 2. the screening's start: the solution gathered at the aggregates, per leaf `Σγ`, the
//!    constant `c` and the shift `μ`, the residual `Sᵀ(−γ(Sx − c))`, the preconditioned
//!    residual `z = (L + μ)⁻¹ r` (the same transforms, multiplier `1/(|k|² + μ)`);
//! 3. conjugate-gradient iterations, each: `S p`, `pᵀ(Lp) + Σγ(Sp)²`, the step, the updates of
//!    `x` and `r`, `Sᵀ` of the step's screening term, `z`, `rᵀz`, `β`, the updates of `p`
//!    and `Lp` — the recurrences of [`Solver::solve_screened`] — until every leaf's
//!    preconditioned residual has fallen by [`SCREEN_TOLERANCE`] (a per-leaf flag on the
//!    device; a leaf that has stopped skips the work of the others' later iterations);
//! 4. the solutions read back and handed to their workers, which go on with the coarse local
//!    solve and the detail on the host.
//!
//! Only the divergence and the aggregates go up and only the solution comes down: a leaf's
//! vectors stay on the device through its iterations, and the host reads 16 scalars a leaf
//! every two iterations to learn which leaves still run.
//!
//! Measured on an H200 with 16 host cores (1M-point bumpy sphere, depth 11, leaves of 64³
//! nodes): the leaf stage 27.8 s against 38.2 s on the CPU, batches of 4.3 leaves on average;
//! for a 100M-point sphere's larger plan 51 against 48 leaves a second. The host's share of
//! each leaf (splat, divergence, screen, the coarse local solve, the detail) and the one
//! device thread bound it; see `scripts/bench_gpu.sh`. Measured again on an H200 with the
//! leaf pass running twice `--threads` workers (a worker waits for its batch) and mimalloc:
//! depth 10, 5.6 s against 10.3 s; depth 11, 16.5 s against 27.1 s (batches of 5.4 leaves;
//! the device thread busy 11.2 s, of which 6.7 s submissions and flag reads, 1.9 s uploads,
//! 2.6 s read-backs; the workers wait 34% of their time). [`GpuSolveStats`] splits the
//! device thread's time so the log shows which part bounds a run. All of these were measured
//! with leaves of 64³ nodes; the leaves' grids are now 48³ (2.2–2.8× less CPU time a leaf,
//! `recon::plan`), where the device's share has not been measured yet.
//!
//! # What differs from the CPU solve
//!
//! The device's arithmetic is float32 throughout: the transforms are full complex mixed-radix
//! FFTs (not rustfft's real-to-complex plans), and the sums (`rᵀz`, `pᵀLp`, `Σγs`) are
//! float32 tree sums of fixed chunks, then of the chunks in order, where the host sums
//! float64 in slabs. So the solution differs from the CPU's by rounding (2.5–3.4·10⁻⁷ of
//! the field's range in the tests on lavapipe), the iteration count can differ by one
//! where a leaf's residual sits at the tolerance, and the mesh differs from the CPU run's
//! by a small fraction of a voxel (bounded in `tests/suite/recon.rs`). `--gpu-solve off`
//! (the default) keeps the CPU path's bytes. On the device every leaf's arithmetic is independent of which leaves share
//! its batch, and each sum has a fixed order, so the output is the same for any thread
//! count and batch: the same bytes run to run on one device.
//!
//! # Failures
//!
//! A device error (validation, out of memory, a lost device) fails the batch: its leaves are
//! solved on the CPU instead, with a warning, and after a lost device every later leaf is.

use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Instant;

use crossbeam_channel::{Receiver, Sender};
use wgpu::BufferUsages as U;

use super::fft_solve::{
    Convergence, LocalGrid, PRECONDITIONER_SHIFT, SCREEN_MAX_ITERATIONS, SCREEN_TOLERANCE, Solver,
    splat,
};
use super::screen::Screen;
use crate::error::{Error, Result, Setting};
use crate::extract::gpu::GpuMode;
use crate::extract::gpu::adapter::{self, Trouble, describe};

/// Largest grid edge the device solve takes: a leaf of 256³ nodes needs 512 MiB of device
/// memory (`NODE_BYTES` a node), two fit in a batch's `BATCH_BYTES`; 512³ would not fit one.
/// (An FFT line of up to 512 values fits the shader's workgroup memory.)
pub const MAX_N: usize = 256;
/// Bytes of device memory a batch may use at most.
const BATCH_BYTES: u64 = 1 << 30;
/// Leaves in a batch at most.
const MAX_BATCH: usize = 64;
/// Device bytes a node takes: six float vectors and a complex one.
const NODE_BYTES: u64 = 6 * 4 + 8;
/// Threads per workgroup of `solve.wgsl` (but `scalars`).
const WG: u32 = 256;
/// Scalars per leaf (`solve.wgsl`: slots).
const SLOTS: usize = 16;
const SLOT_ACTIVE: usize = 8;
const SLOT_ITER: usize = 9;
const SLOT_RZ: usize = 3;
const SLOT_RZ0: usize = 4;
/// Vectors in `vecs`.
const X: u32 = 0;
const R: u32 = 1;
const Z: u32 = 2;
const P: u32 = 3;
const LP: u32 = 4;
const DIV: u32 = 5;
/// Nodes a workgroup of a dot product sums (`vdot`; at most 64 workgroups a leaf).
const DOT_NODES: usize = 8192;
/// Conjugate-gradient iterations sent in one submission, between reads of the leaves' flags.
const ITERATIONS_PER_SUBMISSION: u32 = 2;
/// Scalar slots a dot product goes to.
const SLOT_PLP: u32 = 5;
const SLOT_RZNEW: u32 = 13;

/// The radix of the device FFT's last stage for lines of `n` nodes: 1 where `n` is a power of
/// two from 4 to [`MAX_N`], 3 where it is three times a power of two from 2 (6 to `MAX_N`; a
/// leaf's grid of `1.5E` nodes); `None` for any other `n`.
fn fft_radix(n: usize) -> Option<u32> {
    if !(4..=MAX_N).contains(&n) {
        return None;
    }
    if n.is_power_of_two() {
        Some(1)
    } else if n.is_multiple_of(3) && (n / 3).is_power_of_two() && n >= 6 {
        Some(3)
    } else {
        None
    }
}

/// The uniform block of one dispatch (`solve.wgsl`: `Params`).
#[repr(C)]
#[derive(Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    n: u32,
    /// log2 of `n`'s power-of-two factor `m` (`n = radix·m`).
    log2n: u32,
    nn: u32,
    batch: u32,
    axis: u32,
    inverse: u32,
    ends: u32,
    all: u32,
    src: u32,
    dst: u32,
    va: u32,
    vb: u32,
    mode: u32,
    slot: u32,
    count: u32,
    gx: u32,
    stride: u32,
    s_node: u32,
    s_leaf: u32,
    t_node: u32,
    t_start: u32,
    t_ent: u32,
    tw: u32,
    k2: u32,
    filt: u32,
    h1: u32,
    tol2: f32,
    shift: f32,
    max_iter: f32,
    /// 1, or 3 where `n = 3m` (a radix-3 stage after the radix-2 ones).
    radix: u32,
    pad: [u32; 2],
}

/// One leaf, ready for the device: its divergence and its screening operator with the
/// transposed lists.
struct Prepared {
    div: Vec<f32>,
    /// Per aggregate, its 8 nodes.
    nodes: Vec<[u32; 8]>,
    /// Per aggregate, its 8 weights and its γ.
    weights: Vec<[f32; 9]>,
    /// Touched nodes, ascending.
    t_node: Vec<u32>,
    /// Start of each touched node's entries (one more than nodes).
    t_start: Vec<u32>,
    /// Entries `8a + c`, in aggregate order per node.
    t_ent: Vec<u32>,
}

impl Prepared {
    fn new(div: Vec<f32>, screen: &Screen) -> Prepared {
        let nodes = screen.nodes().to_vec();
        let weights: Vec<[f32; 9]> = screen
            .weights()
            .iter()
            .zip(screen.gamma())
            .map(|(w, &g)| {
                let mut o = [0f32; 9];
                o[..8].copy_from_slice(w);
                o[8] = g as f32;
                o
            })
            .collect();
        let mut ent: Vec<(u32, u32)> = Vec::with_capacity(nodes.len() * 8);
        for (a, ns) in nodes.iter().enumerate() {
            for (c, &j) in ns.iter().enumerate() {
                ent.push((j, (a * 8 + c) as u32));
            }
        }
        ent.sort_unstable();
        let (mut t_node, mut t_start, mut t_ent) = (Vec::new(), Vec::new(), Vec::new());
        for (j, e) in ent {
            if t_node.last() != Some(&j) {
                t_node.push(j);
                t_start.push(t_ent.len() as u32);
            }
            t_ent.push(e);
        }
        t_start.push(t_ent.len() as u32);
        Prepared {
            div,
            nodes,
            weights,
            t_node,
            t_start,
            t_ent,
        }
    }
}

type Reply = std::result::Result<(Vec<f32>, Convergence), String>;

struct Request {
    leaf: Prepared,
    reply: Sender<Reply>,
}

/// What the device thread did, for the log.
#[derive(Debug, Default, Clone, Copy)]
pub struct GpuSolveStats {
    /// Leaves solved on the device.
    pub leaves: u64,
    /// Batches run.
    pub batches: u64,
    /// Submissions (one for the start, one per iteration of the slowest leaf of a batch).
    pub submissions: u64,
    /// Seconds the device thread spent on batches (uploads, kernels, read-backs).
    pub busy_s: f64,
    /// Of `busy_s`: building the batch's lists and dispatch plan and writing them to the
    /// device.
    pub upload_s: f64,
    /// Of `busy_s`: the submissions, each waited for by reading the leaves' flags.
    pub kernel_s: f64,
    /// Of `busy_s`: copying the solutions back.
    pub read_s: f64,
    /// Seconds the device thread waited for leaves.
    pub idle_s: f64,
    /// Seconds the workers spent on a device solve's host side (the divergence, the
    /// screen's transposed lists).
    pub host_s: f64,
    /// Seconds the workers waited for their solutions, summed over workers.
    pub wait_s: f64,
    /// Leaves whose batch failed on the device (solved on the CPU).
    pub failed: u64,
}

/// The device solver: a thread owning the device, fed through a channel. Cheap to share
/// between workers (`solve` takes `&self`).
pub struct GpuSolver {
    tx: Option<Sender<Request>>,
    thread: Option<JoinHandle<()>>,
    name: String,
    n: usize,
    stats: Arc<Mutex<GpuSolveStats>>,
    warned: std::sync::Once,
}

impl std::fmt::Debug for GpuSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuSolver")
            .field("adapter", &self.name)
            .finish_non_exhaustive()
    }
}

impl GpuSolver {
    /// Open a GPU for the solves of `solver`'s grids, as [`GpuMode`] says: `Off` gives
    /// `None`; `Auto` a discrete or integrated GPU if there is one (else `None`, logged);
    /// `On` any adapter, or an error naming the adapters found. Grids whose edge is not a
    /// power of two up to [`MAX_N`] stay on the CPU (`None`, logged).
    pub fn new(mode: GpuMode, solver: &Solver) -> Result<Option<GpuSolver>> {
        if mode == GpuMode::Off {
            return Ok(None);
        }
        let n = solver.n();
        if fft_radix(n).is_none() {
            log::info!(
                "leaf solves on the CPU: their grids of {n}³ nodes are not a power of two from 4 to {MAX_N} nor three times one"
            );
            return Ok(None);
        }
        let (best, found) = adapter::select(mode);
        if let Some(a) = &best
            && batch_cap(&a.limits(), (n * n * n) as u64) == 0
        {
            log::info!(
                "leaf solves on the CPU: a grid of {n}³ nodes exceeds the buffers of {}",
                describe(&a.get_info())
            );
            return Ok(None);
        }
        let Some(ad) = best else {
            if mode == GpuMode::On {
                return Err(adapter::none_found(Setting::GpuSolve, &found));
            }
            log::info!("leaf solves on the CPU: no discrete or integrated GPU (adapters: {found})");
            return Ok(None);
        };
        match Device::open(&ad, solver) {
            Ok(dev) => {
                let name = describe(&dev.info);
                log::info!(
                    "leaf solves on the GPU: {name}, batches of up to {} leaves",
                    dev.max_batch
                );
                Ok(Some(GpuSolver::start(dev, n, name)))
            }
            Err(e) if mode == GpuMode::On => {
                Err(Error::Usage(format!("{} on: {e}", Setting::GpuSolve)))
            }
            Err(e) => {
                log::warn!("leaf solves on the CPU: {e}");
                Ok(None)
            }
        }
    }

    fn start(mut dev: Device, n: usize, name: String) -> GpuSolver {
        let (tx, rx): (Sender<Request>, Receiver<Request>) = crossbeam_channel::unbounded();
        let stats = Arc::new(Mutex::new(GpuSolveStats::default()));
        let st = Arc::clone(&stats);
        let thread = std::thread::Builder::new()
            .name("scanflow-gpu-solve".into())
            .spawn(move || {
                let mut broken: Option<String> = None;
                let mut waiting = Instant::now();
                while let Ok(first) = rx.recv() {
                    let idle = waiting.elapsed().as_secs_f64();
                    let mut reqs = vec![first];
                    while reqs.len() < dev.max_batch {
                        match rx.try_recv() {
                            Ok(r) => reqs.push(r),
                            Err(_) => break,
                        }
                    }
                    let t0 = Instant::now();
                    let out = match &broken {
                        Some(e) => Err(e.clone()),
                        None => dev.run(reqs.iter().map(|r| &r.leaf).collect()),
                    };
                    let mut s = st.lock().unwrap_or_else(|e| e.into_inner());
                    s.busy_s += t0.elapsed().as_secs_f64();
                    s.idle_s += idle;
                    match out {
                        Ok((sols, t)) => {
                            s.leaves += reqs.len() as u64;
                            s.batches += 1;
                            s.submissions += t.submissions;
                            s.upload_s += t.upload_s;
                            s.kernel_s += t.kernel_s;
                            s.read_s += t.read_s;
                            for (r, sol) in reqs.into_iter().zip(sols) {
                                let _ = r.reply.send(Ok(sol));
                            }
                        }
                        Err(e) => {
                            s.failed += reqs.len() as u64;
                            if dev.lost().is_some() {
                                broken = Some(e.clone());
                            }
                            for r in reqs {
                                let _ = r.reply.send(Err(e.clone()));
                            }
                        }
                    }
                    drop(s);
                    waiting = Instant::now();
                }
            })
            .expect("spawning a thread");
        GpuSolver {
            tx: Some(tx),
            thread: Some(thread),
            name,
            n,
            stats,
            warned: std::sync::Once::new(),
        }
    }

    /// The adapter, as the driver names it.
    pub fn adapter_name(&self) -> &str {
        &self.name
    }

    /// What the device thread has done so far.
    pub fn stats(&self) -> GpuSolveStats {
        *self.stats.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The screened solve of `pos`/`nrm` on `grid` (of `solver`'s shape) with weight
    /// `alpha`, on the device; on a device failure, on the CPU (warned once).
    pub fn solve_points(
        &self,
        solver: &Solver,
        grid: &LocalGrid,
        pos: &[[f64; 3]],
        nrm: &[[f32; 3]],
        alpha: f64,
    ) -> (Vec<f32>, Convergence) {
        let mut v = vec![[0f32; 3]; grid.len()];
        splat(grid, pos, nrm, &mut v);
        self.solve_splatted(solver, grid, v, &Screen::from_points(grid, pos, alpha))
    }

    /// The screened solve of the splatted normals `v` (consumed) on `grid` (of `solver`'s
    /// shape), screened by `screen`, on the device; on a device failure, on the CPU (warned
    /// once).
    pub fn solve_splatted(
        &self,
        solver: &Solver,
        grid: &LocalGrid,
        v: Vec<[f32; 3]>,
        screen: &Screen,
    ) -> (Vec<f32>, Convergence) {
        assert_eq!(grid.n, self.n, "a device solver for another grid size");
        let t0 = Instant::now();
        let div = solver.divergence(grid, v);
        let leaf = Prepared::new(div.clone(), screen);
        let t1 = Instant::now();
        let out = self.solve_prepared(leaf);
        {
            let mut s = self.stats.lock().unwrap_or_else(|e| e.into_inner());
            s.host_s += (t1 - t0).as_secs_f64();
            s.wait_s += t1.elapsed().as_secs_f64();
        }
        match out {
            Ok(r) => r,
            Err(e) => {
                self.warned.call_once(|| {
                    log::warn!("a leaf solve failed on the GPU, solved on the CPU instead: {e}")
                });
                solver.solve_screened_divergence(&div, screen)
            }
        }
    }

    fn solve_prepared(&self, leaf: Prepared) -> Reply {
        let (reply, rx) = crossbeam_channel::bounded(1);
        let tx = self.tx.as_ref().ok_or("the device thread has ended")?;
        tx.send(Request { leaf, reply })
            .map_err(|_| "the device thread has ended".to_string())?;
        rx.recv()
            .map_err(|_| "the device thread has ended".to_string())?
    }
}

impl Drop for GpuSolver {
    fn drop(&mut self) {
        self.tx.take();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// What decides a run's leaf solves under `mode`, for the run's identity (a resumed run or
/// another shard must solve alike): `"cpu"`, or the adapter the solves would run on. Also
/// the early check of `--gpu-solve on`: an error when wgpu finds no adapter.
pub fn device_identity(mode: GpuMode) -> Result<String> {
    if mode == GpuMode::Off {
        return Ok("cpu".into());
    }
    match adapter::select(mode) {
        (Some(a), _) => Ok(describe(&a.get_info())),
        (None, found) if mode == GpuMode::On => Err(adapter::none_found(Setting::GpuSolve, &found)),
        (None, _) => Ok("cpu".into()),
    }
}

/// The pipelines of `solve.wgsl`.
struct Pipelines {
    fft: wgpu::ComputePipeline,
    mul: wgpu::ComputePipeline,
    vop: wgpu::ComputePipeline,
    gather: wgpu::ComputePipeline,
    coef: wgpu::ComputePipeline,
    scatter: wgpu::ComputePipeline,
    dot: wgpu::ComputePipeline,
    vsum: wgpu::ComputePipeline,
    ssum: wgpu::ComputePipeline,
    scalars: wgpu::ComputePipeline,
}

/// Buffers of one batch shape, grown as needed.
#[derive(Default)]
struct Buffers {
    vecs: Option<wgpu::Buffer>,
    cpx: Option<wgpu::Buffer>,
    idx: Option<wgpu::Buffer>,
    sw: Option<wgpu::Buffer>,
    sdyn: Option<wgpu::Buffer>,
    scal: Option<wgpu::Buffer>,
    params: Option<wgpu::Buffer>,
    read_scal: Option<wgpu::Buffer>,
    read_x: Option<wgpu::Buffer>,
}

/// The device side: device, queue, pipelines, the constant tables of the grid shape.
struct Device {
    device: wgpu::Device,
    queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    trouble: Arc<Mutex<Trouble>>,
    layout: wgpu::BindGroupLayout,
    pipes: Pipelines,
    consts: wgpu::Buffer,
    n: usize,
    h1: usize,
    max_batch: usize,
    max_dim: u32,
    align: u64,
    bufs: Buffers,
}

/// Leaves of `nn` nodes a batch may hold on a device with `limits` (0: not one).
fn batch_cap(limits: &wgpu::Limits, nn: u64) -> usize {
    let max_binding = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size);
    let by_bytes = (BATCH_BYTES / (nn * NODE_BYTES))
        .min(max_binding / (nn * 4 * 6))
        .min((u32::MAX as u64) / (nn * 6));
    (by_bytes as usize).min(MAX_BATCH)
}

/// A buffer of at least `size` bytes in `slot` (grown to the next power of two).
fn ensure(
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

impl Device {
    fn open(ad: &wgpu::Adapter, solver: &Solver) -> std::result::Result<Device, String> {
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
        let storage = |binding: u32| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: false },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let mut entries = vec![wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: true,
                min_binding_size: wgpu::BufferSize::new(std::mem::size_of::<Params>() as u64),
            },
            count: None,
        }];
        entries.extend((1..=7).map(storage));
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("solve"),
            entries: &entries,
        });
        let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("solve"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("solve.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("shaders/solve.wgsl").into()),
        });
        let pipe = |entry: &str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(&pl),
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let pipes = Pipelines {
            fft: pipe("fft"),
            mul: pipe("mul"),
            vop: pipe("vop"),
            gather: pipe("gather"),
            coef: pipe("coef"),
            scatter: pipe("scatter"),
            dot: pipe("vdot"),
            vsum: pipe("vsum"),
            ssum: pipe("ssum"),
            scalars: pipe("scalars"),
        };
        // Constants: twiddles exp(−2πik/n) for k < n (pairs: the radix-3 stage reads up to
        // 2(n/3 − 1)), |k|² by folded index, the Poisson filter.
        let mut c = Vec::with_capacity(2 * n + h1 + filter.len());
        for k in 0..n {
            let a = -2.0 * std::f64::consts::PI * k as f64 / n as f64;
            c.push(a.cos() as f32);
            c.push(a.sin() as f32);
        }
        c.extend_from_slice(k2);
        c.extend_from_slice(&filter);
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
    fn lost(&self) -> Option<String> {
        self.trouble.lock().ok().and_then(|t| t.lost.clone())
    }

    /// `(gx, gy)` for `count` threads of 256.
    fn groups(&self, count: u64) -> (u32, u32) {
        let g = count.div_ceil(WG as u64).max(1);
        let gx = g.min(self.max_dim as u64);
        (gx as u32, g.div_ceil(gx) as u32)
    }

    /// Solve a batch; returns each leaf's solution and convergence, and where the time went.
    fn run(
        &mut self,
        leaves: Vec<&Prepared>,
    ) -> std::result::Result<(Vec<Reply0>, Timing), String> {
        let scopes = adapter::push_scopes(&self.device);
        let out =
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| self.run_inner(&leaves)));
        let (errors, _) = adapter::pop_scopes(scopes, &self.trouble);
        let out = match out {
            Ok(r) => r,
            Err(_) => Err("a panic inside wgpu".to_string()),
        };
        if !errors.is_empty() {
            self.bufs = Buffers::default();
            return Err(errors.join("; "));
        }
        out
    }

    fn run_inner(
        &mut self,
        leaves: &[&Prepared],
    ) -> std::result::Result<(Vec<Reply0>, Timing), String> {
        let t_begin = Instant::now();
        let n = self.n;
        let nn = n * n * n;
        let b = leaves.len();
        let stride = (self.max_batch * nn) as u32;
        let dev = self.device.clone();
        // The batch's index lists (global: leaf base added) and weights.
        let s_total: usize = leaves.iter().map(|l| l.nodes.len()).sum();
        let t_total: usize = leaves.iter().map(|l| l.t_node.len()).sum();
        let e_total: usize = leaves.iter().map(|l| l.t_ent.len()).sum();
        let s_node = 0usize;
        let s_leaf = s_node + 8 * s_total;
        let t_node = s_leaf + b + 1;
        let t_start = t_node + t_total;
        let t_ent = t_start + t_total + 1;
        let mut idx: Vec<u32> = Vec::with_capacity(t_ent + e_total);
        let mut sw: Vec<f32> = Vec::with_capacity(9 * s_total);
        let mut leaf_start = Vec::with_capacity(b + 1);
        let mut a0 = 0u32;
        for (i, l) in leaves.iter().enumerate() {
            let base = (i * nn) as u32;
            leaf_start.push(a0);
            for ns in &l.nodes {
                idx.extend(ns.iter().map(|&j| base + j));
            }
            for w in &l.weights {
                sw.extend_from_slice(w);
            }
            a0 += l.nodes.len() as u32;
        }
        leaf_start.push(a0);
        idx.extend_from_slice(&leaf_start);
        for (i, l) in leaves.iter().enumerate() {
            let base = (i * nn) as u32;
            idx.extend(l.t_node.iter().map(|&j| base + j));
        }
        let (mut e0, mut sa) = (0u32, 0u32);
        for l in leaves {
            idx.extend(l.t_start[..l.t_start.len() - 1].iter().map(|&s| e0 + s));
            e0 += l.t_ent.len() as u32;
        }
        idx.push(e0);
        for l in leaves {
            idx.extend(l.t_ent.iter().map(|&e| sa * 8 + e));
            sa += l.nodes.len() as u32;
        }
        debug_assert_eq!(idx.len(), t_ent + e_total);
        let st = U::STORAGE | U::COPY_DST | U::COPY_SRC;
        let storage = |slot: &mut Option<wgpu::Buffer>, label: &str, bytes: usize| {
            ensure(&dev, slot, label, bytes as u64, st)
        };
        let vecs = storage(
            &mut self.bufs.vecs,
            "solve vectors",
            6 * stride as usize * 4,
        );
        let cpx = storage(&mut self.bufs.cpx, "solve spectrum", b * nn * 8);
        let ib = storage(&mut self.bufs.idx, "solve indices", idx.len() * 4);
        let swb = storage(&mut self.bufs.sw, "solve weights", sw.len() * 4);
        let sdyn = storage(&mut self.bufs.sdyn, "solve samples", s_total * 8);
        // The scalars, then each leaf's partial sums of a dot product (`vdot`).
        let parts = (nn / DOT_NODES).clamp(1, 64);
        let scal_bytes = (b * SLOTS * 4) as u64;
        let scal = storage(
            &mut self.bufs.scal,
            "solve scalars",
            b * (SLOTS + parts) * 4,
        );
        let q = &self.queue;
        for (i, l) in leaves.iter().enumerate() {
            let at = ((DIV as usize * stride as usize + i * nn) * 4) as u64;
            q.write_buffer(&vecs, at, bytemuck::cast_slice(&l.div));
        }
        if !idx.is_empty() {
            q.write_buffer(&ib, 0, bytemuck::cast_slice(&idx));
        }
        if !sw.is_empty() {
            q.write_buffer(&swb, 0, bytemuck::cast_slice(&sw));
        }
        q.write_buffer(&scal, 0, &vec![0u8; scal_bytes as usize]);
        // The uniform blocks of every dispatch, written once for the batch.
        let base = Params {
            n: n as u32,
            log2n: n.trailing_zeros(),
            radix: fft_radix(n).expect("a grid the device takes (GpuSolver::new)"),
            nn: nn as u32,
            batch: b as u32,
            stride,
            s_node: s_node as u32,
            s_leaf: s_leaf as u32,
            t_node: t_node as u32,
            t_start: t_start as u32,
            t_ent: t_ent as u32,
            tw: 0,
            k2: 2 * n as u32,
            filt: (2 * n + self.h1) as u32,
            h1: self.h1 as u32,
            tol2: (SCREEN_TOLERANCE * SCREEN_TOLERANCE) as f32,
            shift: PRECONDITIONER_SHIFT as f32,
            max_iter: SCREEN_MAX_ITERATIONS as f32,
            ..Params::default()
        };
        let node_groups = self.groups(nn as u64);
        // fft.wgsl: max(1, 512/n) lines a workgroup (the last one's partly idle where that
        // does not divide n²), n² lines a leaf.
        let line_groups = {
            let g = (n * n).div_ceil((512 / n).max(1)) as u64;
            let gx = g.min(self.max_dim as u64);
            (gx as u32, g.div_ceil(gx) as u32)
        };
        let mut plan = Plan {
            blocks: Vec::new(),
            ops: Vec::new(),
        };
        let spectral = |plan: &mut Plan, src: u32, dst: u32, mode: u32, all: u32| {
            for (axis, inverse) in [(0, 0), (1, 0), (2, 0)] {
                let ends = if axis == 0 { 1 } else { 0 };
                plan.push(
                    Kernel::Fft,
                    (line_groups.0, line_groups.1, b as u32),
                    Params {
                        axis,
                        inverse,
                        ends,
                        src,
                        all,
                        gx: line_groups.0,
                        ..base
                    },
                );
            }
            plan.push(
                Kernel::Mul,
                (node_groups.0, node_groups.1, b as u32),
                Params {
                    mode,
                    all,
                    gx: node_groups.0,
                    ..base
                },
            );
            for axis in [2, 1, 0] {
                let ends = if axis == 0 { 2 } else { 0 };
                plan.push(
                    Kernel::Fft,
                    (line_groups.0, line_groups.1, b as u32),
                    Params {
                        axis,
                        inverse: 1,
                        ends,
                        dst,
                        all,
                        gx: line_groups.0,
                        ..base
                    },
                );
            }
        };
        let per_node = |plan: &mut Plan, kern: Kernel, mode: u32, all: u32| {
            plan.push(
                kern,
                (node_groups.0, node_groups.1, b as u32),
                Params {
                    mode,
                    all,
                    gx: node_groups.0,
                    ..base
                },
            );
        };
        let s_groups = self.groups(s_total as u64);
        let t_groups = self.groups(t_total as u64);
        let samples = |plan: &mut Plan, kern: Kernel, src: u32, mode: u32, all: u32| {
            let (g, count) = if kern == Kernel::Scatter {
                (t_groups, t_total)
            } else {
                (s_groups, s_total)
            };
            plan.push(
                kern,
                (g.0, g.1, 1),
                Params {
                    src,
                    mode,
                    all,
                    count: count as u32,
                    gx: g.0,
                    ..base
                },
            );
        };
        let per_leaf = |plan: &mut Plan, kern: Kernel, va: u32, vb: u32, slot: u32, all: u32| {
            if kern == Kernel::Dot {
                let p = Params {
                    va,
                    vb,
                    slot,
                    all,
                    count: parts as u32,
                    ..base
                };
                plan.push(kern, (parts as u32, 1, b as u32), p);
                plan.push(Kernel::Vsum, ((b as u32).div_ceil(64), 1, 1), p);
            } else {
                plan.push(
                    kern,
                    (b as u32, 1, 1),
                    Params {
                        va,
                        vb,
                        slot,
                        all,
                        ..base
                    },
                );
            }
        };
        let scalars = |plan: &mut Plan, mode: u32| {
            plan.push(
                Kernel::Scalars,
                ((b as u32).div_ceil(64), 1, 1),
                Params { mode, ..base },
            );
        };
        // Start: the Poisson solve of every leaf, then the screening's start.
        spectral(&mut plan, DIV, X, 0, 1);
        let screened = s_total > 0;
        if screened {
            samples(&mut plan, Kernel::Gather, X, 0, 1);
            per_leaf(&mut plan, Kernel::Ssum, 0, 0, 0, 1);
            scalars(&mut plan, 0);
            per_node(&mut plan, Kernel::Vop, 0, 0);
            samples(&mut plan, Kernel::Coef, 0, 0, 0);
            samples(&mut plan, Kernel::Scatter, 0, 0, 0);
            spectral(&mut plan, R, Z, 1, 0);
            per_leaf(&mut plan, Kernel::Dot, R, Z, SLOT_RZNEW, 0);
            scalars(&mut plan, 1);
            per_node(&mut plan, Kernel::Vop, 1, 0);
        }
        let start_ops = plan.ops.len();
        // One iteration.
        samples(&mut plan, Kernel::Gather, P, 0, 0);
        per_leaf(&mut plan, Kernel::Ssum, 0, 0, 0, 0);
        per_leaf(&mut plan, Kernel::Dot, P, LP, SLOT_PLP, 0);
        scalars(&mut plan, 2);
        per_node(&mut plan, Kernel::Vop, 2, 0);
        samples(&mut plan, Kernel::Coef, 0, 1, 0);
        samples(&mut plan, Kernel::Scatter, 0, 0, 0);
        spectral(&mut plan, R, Z, 1, 0);
        per_leaf(&mut plan, Kernel::Dot, R, Z, SLOT_RZNEW, 0);
        scalars(&mut plan, 3);
        per_node(&mut plan, Kernel::Vop, 3, 0);
        let stride_b = (std::mem::size_of::<Params>() as u64).div_ceil(self.align) * self.align;
        let mut bytes = vec![0u8; (plan.blocks.len() as u64 * stride_b) as usize];
        for (i, p) in plan.blocks.iter().enumerate() {
            let at = i * stride_b as usize;
            bytes[at..at + std::mem::size_of::<Params>()].copy_from_slice(bytemuck::bytes_of(p));
        }
        let params = ensure(
            &dev,
            &mut self.bufs.params,
            "solve params",
            bytes.len() as u64,
            U::UNIFORM | U::COPY_DST,
        );
        q.write_buffer(&params, 0, &bytes);
        let bind = dev.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("solve"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &params,
                        offset: 0,
                        size: wgpu::BufferSize::new(std::mem::size_of::<Params>() as u64),
                    }),
                },
                entry(1, &vecs),
                entry(2, &cpx),
                entry(3, &self.consts),
                entry(4, &ib),
                entry(5, &swb),
                entry(6, &sdyn),
                entry(7, &scal),
            ],
        });
        let read_scal = ensure(
            &dev,
            &mut self.bufs.read_scal,
            "solve scalars read-back",
            scal_bytes,
            U::MAP_READ | U::COPY_DST,
        );
        let encode = |ops: &[&Op]| {
            let mut enc = dev.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                for op in ops {
                    pass.set_pipeline(self.pipes.get(op.kernel));
                    pass.set_bind_group(0, &bind, &[(op.block as u64 * stride_b) as u32]);
                    pass.dispatch_workgroups(op.groups.0, op.groups.1, op.groups.2);
                }
            }
            enc.copy_buffer_to_buffer(&scal, 0, &read_scal, 0, scal_bytes);
            enc.finish()
        };
        let mut submissions = 0u64;
        let mut sc: Vec<f32> = Vec::with_capacity(b * SLOTS);
        let t_kernels = Instant::now();
        q.submit([encode(&plan.ops[..start_ops].iter().collect::<Vec<_>>())]);
        submissions += 1;
        read_back(&dev, &read_scal, scal_bytes, &mut sc)?;
        if screened {
            // ITERATIONS_PER_SUBMISSION iterations a submission: a leaf that stops within one
            // skips the rest (the device's flag), so only the waits are saved.
            let iteration = &plan.ops[start_ops..];
            let ops: Vec<&Op> = (0..ITERATIONS_PER_SUBMISSION)
                .flat_map(|_| iteration.iter())
                .collect();
            let mut rounds = 0;
            while sc.chunks(SLOTS).any(|s| s[SLOT_ACTIVE] > 0.5) && rounds <= SCREEN_MAX_ITERATIONS
            {
                q.submit([encode(&ops)]);
                submissions += 1;
                rounds += ITERATIONS_PER_SUBMISSION;
                sc.clear();
                read_back(&dev, &read_scal, scal_bytes, &mut sc)?;
            }
        }
        // The solutions.
        let t_read = Instant::now();
        let x_bytes = (b * nn * 4) as u64;
        let read_x = ensure(
            &dev,
            &mut self.bufs.read_x,
            "solve read-back",
            x_bytes,
            U::MAP_READ | U::COPY_DST,
        );
        let mut enc = dev.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(&vecs, 0, &read_x, 0, x_bytes);
        q.submit([enc.finish()]);
        let mut xs: Vec<Vec<f32>> = Vec::with_capacity(b);
        mapped(&dev, &read_x, x_bytes, |v| {
            xs.extend(v.chunks(nn).map(|x| x.to_vec()));
        })?;
        let out = xs
            .into_iter()
            .zip(sc.chunks(SLOTS))
            .map(|(x, s)| {
                let (rz, rz0) = (s[SLOT_RZ] as f64, s[SLOT_RZ0] as f64);
                let conv = Convergence {
                    iterations: s[SLOT_ITER] as u32,
                    residual: if rz0 > 0.0 { (rz / rz0).sqrt() } else { 0.0 },
                };
                (x, conv)
            })
            .collect();
        let timing = Timing {
            submissions,
            upload_s: (t_kernels - t_begin).as_secs_f64(),
            kernel_s: (t_read - t_kernels).as_secs_f64(),
            read_s: t_read.elapsed().as_secs_f64(),
        };
        Ok((out, timing))
    }
}

type Reply0 = (Vec<f32>, Convergence);

/// Where one batch's time went on the device thread.
struct Timing {
    submissions: u64,
    upload_s: f64,
    kernel_s: f64,
    read_s: f64,
}

fn entry(binding: u32, buf: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: buf.as_entire_binding(),
    }
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Kernel {
    Fft,
    Mul,
    Vop,
    Gather,
    Coef,
    Scatter,
    Dot,
    Vsum,
    Ssum,
    Scalars,
}

impl Pipelines {
    fn get(&self, k: Kernel) -> &wgpu::ComputePipeline {
        match k {
            Kernel::Fft => &self.fft,
            Kernel::Mul => &self.mul,
            Kernel::Vop => &self.vop,
            Kernel::Gather => &self.gather,
            Kernel::Coef => &self.coef,
            Kernel::Scatter => &self.scatter,
            Kernel::Dot => &self.dot,
            Kernel::Vsum => &self.vsum,
            Kernel::Ssum => &self.ssum,
            Kernel::Scalars => &self.scalars,
        }
    }
}

/// One dispatch: its kernel, workgroups and uniform block.
struct Op {
    kernel: Kernel,
    groups: (u32, u32, u32),
    block: usize,
}

/// The dispatches of a batch and their uniform blocks.
struct Plan {
    blocks: Vec<Params>,
    ops: Vec<Op>,
}

impl Plan {
    fn push(&mut self, kernel: Kernel, groups: (u32, u32, u32), p: Params) {
        self.blocks.push(p);
        self.ops.push(Op {
            kernel,
            groups,
            block: self.blocks.len() - 1,
        });
    }
}

/// Read the first `bytes` of the mappable `buf` into `out` (after all submitted work).
fn read_back(
    device: &wgpu::Device,
    buf: &wgpu::Buffer,
    bytes: u64,
    out: &mut Vec<f32>,
) -> std::result::Result<(), String> {
    mapped(device, buf, bytes, |v| out.extend_from_slice(v))
}

/// Map the first `bytes` of `buf` once all submitted work is done and hand them to `f`.
fn mapped(
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

#[cfg(test)]
mod tests;
