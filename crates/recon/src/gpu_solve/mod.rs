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
//! by a small fraction of a voxel (bounded in the CLI's `tests/suite/recon/gpu.rs`). `--gpu-solve off`
//! (the default) keeps the CPU path's bytes. On the device every leaf's arithmetic is independent of which leaves share
//! its batch, and each sum has a fixed order, so the output is the same for any thread
//! count and batch: the same bytes run to run on one device.
//!
//! # Failures
//!
//! A device error (validation, out of memory, a lost device) fails the batch: its leaves are
//! solved on the CPU instead, with a warning, and after a lost device every later leaf is.
//!
//! # Files
//!
//! - `mod.rs`: the public side ([`GpuSolver`], [`GpuSolveStats`], [`device_identity`]) and the
//!   device thread that batches the workers' leaves;
//! - `prep.rs`: a leaf made ready for the device on its worker (its divergence, its screen
//!   with the transposed lists);
//! - `device.rs`: opening the adapter's device, the constant tables, the limits that size a
//!   batch, the buffers, reading buffers back;
//! - `kernels.rs`: what the host shares with `solve.wgsl` (the uniform block, a leaf's scalar
//!   slots, the vectors), the pipelines, and the plan of a batch's dispatches: steps 1–3
//!   above, in their order;
//! - `batch.rs`: one batch in steps: its lists and their upload, the uniform blocks and
//!   bindings, the submissions until every leaf has stopped, the solutions read back (step 4);
//! - `tests.rs`: the device solve against the CPU's, and the same bits in any batch.
//!
//! [`SCREEN_TOLERANCE`]: crate::fft_solve::SCREEN_TOLERANCE

use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Instant;

use crossbeam_channel::{Receiver, Sender};

use super::fft_solve::{Convergence, LocalGrid, Solver, splat};
use super::screen::Screen;
use crate::error::{Error, Result, Setting};
use crate::extract::gpu::GpuMode;
use crate::extract::gpu::adapter::{self, describe};

mod batch;
mod device;
mod kernels;
mod prep;

use device::{Device, batch_cap};
use prep::Prepared;

/// Largest grid edge the device solve takes: a leaf of 256³ nodes needs 512 MiB of device
/// memory (`NODE_BYTES` a node), two fit in a batch's `BATCH_BYTES`; 512³ would not fit one.
/// (An FFT line of up to 512 values fits the shader's workgroup memory.)
pub const MAX_N: usize = 256;

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

#[cfg(test)]
mod tests;
