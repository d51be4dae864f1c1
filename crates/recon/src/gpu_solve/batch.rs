//! One batch on the device, in the steps [`Device::run`] takes: the batch's index lists and
//! weights ([`Lists`]), their upload with the divergences ([`Device::upload`]), the plan of
//! dispatches ([`Plan::batch`]) and its uniform blocks ([`Device::bind`]), the submissions
//! until every leaf has stopped ([`Device::iterate`]), and the solutions read back
//! ([`Device::read_solutions`]).

use std::time::Instant;

use wgpu::BufferUsages as U;

use super::device::{Buffers, Device, ensure, entry, mapped, read_back};
use super::fft_radix;
use super::kernels::{
    DIV, DOT_NODES, Op, Params, Plan, SLOT_ACTIVE, SLOT_ITER, SLOT_RZ, SLOT_RZ0, SLOTS, Shape,
};
use super::prep::Prepared;
use crate::extract::gpu::adapter;
use crate::fft_solve::{
    Convergence, PRECONDITIONER_SHIFT, SCREEN_MAX_ITERATIONS, SCREEN_TOLERANCE,
};

/// Conjugate-gradient iterations sent in one submission, between reads of the leaves' flags.
const ITERATIONS_PER_SUBMISSION: u32 = 2;

/// A batch's index lists (global: each leaf's base of `nn` nodes added) and its samples'
/// weights, with where each list starts in `idx`.
struct Lists {
    idx: Vec<u32>,
    sw: Vec<f32>,
    /// Aggregates (samples) of the batch.
    s_total: usize,
    /// Touched nodes of the batch.
    t_total: usize,
    /// Per aggregate its 8 nodes.
    s_node: usize,
    /// Per leaf its first aggregate (one more than leaves).
    s_leaf: usize,
    /// The touched nodes.
    t_node: usize,
    /// Per touched node the start of its entries (one more than touched nodes).
    t_start: usize,
    /// The entries `8a + c`.
    t_ent: usize,
}

impl Lists {
    /// The lists of `leaves`, of `nn` nodes each, in the order the device reads them.
    fn new(leaves: &[&Prepared], nn: usize) -> Lists {
        let b = leaves.len();
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
        Lists {
            idx,
            sw,
            s_total,
            t_total,
            s_node,
            s_leaf,
            t_node,
            t_start,
            t_ent,
        }
    }
}

/// The storage buffers of a batch, written for it.
struct Storage {
    /// The six vectors (`X`, `R`, `Z`, `P`, `LP`, `DIV`), `stride` floats apart.
    vecs: wgpu::Buffer,
    /// The complex spectrum of each leaf.
    cpx: wgpu::Buffer,
    /// [`Lists::idx`].
    idx: wgpu::Buffer,
    /// [`Lists::sw`].
    sw: wgpu::Buffer,
    /// Per sample, the solution gathered there and its screening coefficient.
    sdyn: wgpu::Buffer,
    /// The scalars, then each leaf's partial sums of a dot product (`vdot`).
    scal: wgpu::Buffer,
    /// Bytes of the scalars proper (`SLOTS` a leaf), the part read back.
    scal_bytes: u64,
    /// Partial sums a leaf's dot product takes.
    parts: usize,
}

/// The batch's uniform blocks and bindings, ready to encode.
struct Bound {
    group: wgpu::BindGroup,
    /// Bytes between two uniform blocks (the device's offset alignment).
    stride_b: u64,
    /// Where the scalars are copied to be read.
    read_scal: wgpu::Buffer,
}

impl Device {
    /// Solve a batch; returns each leaf's solution and convergence, and where the time went.
    pub(super) fn run(
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

    /// The steps of [`Device::run`], inside its error scopes.
    fn run_inner(
        &mut self,
        leaves: &[&Prepared],
    ) -> std::result::Result<(Vec<Reply0>, Timing), String> {
        let t_begin = Instant::now();
        let nn = self.n * self.n * self.n;
        let stride = (self.max_batch * nn) as u32;
        let lists = Lists::new(leaves, nn);
        let store = self.upload(leaves, &lists, stride);
        let (plan, start_ops) = Plan::batch(&self.shape(&lists, leaves.len(), stride, store.parts));
        let bound = self.bind(&plan, &store);
        let t_kernels = Instant::now();
        let (sc, submissions) =
            self.iterate(&plan, start_ops, lists.s_total > 0, &store, &bound)?;
        let t_read = Instant::now();
        let xs = self.read_solutions(&store.vecs, leaves.len(), nn)?;
        let timing = Timing {
            submissions,
            upload_s: (t_kernels - t_begin).as_secs_f64(),
            kernel_s: (t_read - t_kernels).as_secs_f64(),
            read_s: t_read.elapsed().as_secs_f64(),
        };
        Ok((with_convergence(xs, &sc), timing))
    }

    /// The batch's storage buffers (grown as needed), with each leaf's divergence, the lists
    /// and zeroed scalars written to them.
    fn upload(&mut self, leaves: &[&Prepared], lists: &Lists, stride: u32) -> Storage {
        let nn = self.n * self.n * self.n;
        let b = leaves.len();
        let dev = self.device.clone();
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
        let ib = storage(&mut self.bufs.idx, "solve indices", lists.idx.len() * 4);
        let swb = storage(&mut self.bufs.sw, "solve weights", lists.sw.len() * 4);
        let sdyn = storage(&mut self.bufs.sdyn, "solve samples", lists.s_total * 8);
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
        if !lists.idx.is_empty() {
            q.write_buffer(&ib, 0, bytemuck::cast_slice(&lists.idx));
        }
        if !lists.sw.is_empty() {
            q.write_buffer(&swb, 0, bytemuck::cast_slice(&lists.sw));
        }
        q.write_buffer(&scal, 0, &vec![0u8; scal_bytes as usize]);
        Storage {
            vecs,
            cpx,
            idx: ib,
            sw: swb,
            sdyn,
            scal,
            scal_bytes,
            parts,
        }
    }

    /// What the dispatches of a batch of `b` leaves with `lists` depend on: the uniform
    /// block they start from and their workgroup grids.
    fn shape(&self, lists: &Lists, b: usize, stride: u32, parts: usize) -> Shape {
        let n = self.n;
        let nn = n * n * n;
        let base = Params {
            n: n as u32,
            log2n: n.trailing_zeros(),
            radix: fft_radix(n).expect("a grid the device takes (GpuSolver::new)"),
            nn: nn as u32,
            batch: b as u32,
            stride,
            s_node: lists.s_node as u32,
            s_leaf: lists.s_leaf as u32,
            t_node: lists.t_node as u32,
            t_start: lists.t_start as u32,
            t_ent: lists.t_ent as u32,
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
        Shape {
            base,
            b: b as u32,
            node_groups,
            line_groups,
            s_groups: self.groups(lists.s_total as u64),
            t_groups: self.groups(lists.t_total as u64),
            s_total: lists.s_total,
            t_total: lists.t_total,
            parts,
        }
    }

    /// The uniform blocks of every dispatch of `plan`, written once for the batch, and the
    /// bind group of the batch's buffers.
    fn bind(&mut self, plan: &Plan, store: &Storage) -> Bound {
        let dev = self.device.clone();
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
        self.queue.write_buffer(&params, 0, &bytes);
        let group = dev.create_bind_group(&wgpu::BindGroupDescriptor {
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
                entry(1, &store.vecs),
                entry(2, &store.cpx),
                entry(3, &self.consts),
                entry(4, &store.idx),
                entry(5, &store.sw),
                entry(6, &store.sdyn),
                entry(7, &store.scal),
            ],
        });
        let read_scal = ensure(
            &dev,
            &mut self.bufs.read_scal,
            "solve scalars read-back",
            store.scal_bytes,
            U::MAP_READ | U::COPY_DST,
        );
        Bound {
            group,
            stride_b,
            read_scal,
        }
    }

    /// One submission's commands: the dispatches `ops`, then the scalars copied to be read.
    fn encode(&self, ops: &[&Op], store: &Storage, bound: &Bound) -> wgpu::CommandBuffer {
        let mut enc = self.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            for op in ops {
                pass.set_pipeline(self.pipes.get(op.kernel));
                pass.set_bind_group(
                    0,
                    &bound.group,
                    &[(op.block as u64 * bound.stride_b) as u32],
                );
                pass.dispatch_workgroups(op.groups.0, op.groups.1, op.groups.2);
            }
        }
        enc.copy_buffer_to_buffer(&store.scal, 0, &bound.read_scal, 0, store.scal_bytes);
        enc.finish()
    }

    /// Submit the start (`plan`'s first `start_ops` dispatches), then, where the batch is
    /// `screened`, [`ITERATIONS_PER_SUBMISSION`] iterations a submission while a leaf's flag
    /// says it runs; returns the scalars last read back and the submissions.
    fn iterate(
        &self,
        plan: &Plan,
        start_ops: usize,
        screened: bool,
        store: &Storage,
        bound: &Bound,
    ) -> std::result::Result<(Vec<f32>, u64), String> {
        let (dev, q) = (&self.device, &self.queue);
        let mut submissions = 0u64;
        let mut sc: Vec<f32> = Vec::with_capacity(store.scal_bytes as usize / 4);
        let start: Vec<&Op> = plan.ops[..start_ops].iter().collect();
        q.submit([self.encode(&start, store, bound)]);
        submissions += 1;
        read_back(dev, &bound.read_scal, store.scal_bytes, &mut sc)?;
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
                q.submit([self.encode(&ops, store, bound)]);
                submissions += 1;
                rounds += ITERATIONS_PER_SUBMISSION;
                sc.clear();
                read_back(dev, &bound.read_scal, store.scal_bytes, &mut sc)?;
            }
        }
        Ok((sc, submissions))
    }

    /// The solutions of the batch's `b` leaves of `nn` nodes (`X`, the start of `vecs`),
    /// copied back, a vector a leaf.
    fn read_solutions(
        &mut self,
        vecs: &wgpu::Buffer,
        b: usize,
        nn: usize,
    ) -> std::result::Result<Vec<Vec<f32>>, String> {
        let dev = self.device.clone();
        let x_bytes = (b * nn * 4) as u64;
        let read_x = ensure(
            &dev,
            &mut self.bufs.read_x,
            "solve read-back",
            x_bytes,
            U::MAP_READ | U::COPY_DST,
        );
        let mut enc = dev.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(vecs, 0, &read_x, 0, x_bytes);
        self.queue.submit([enc.finish()]);
        let mut xs: Vec<Vec<f32>> = Vec::with_capacity(b);
        mapped(&dev, &read_x, x_bytes, |v| {
            xs.extend(v.chunks(nn).map(|x| x.to_vec()));
        })?;
        Ok(xs)
    }
}

/// Each leaf's solution with its convergence from its scalars `sc` (`SLOTS` a leaf): the
/// iterations, and the residual `√(rᵀz / r₀ᵀz₀)` (0 where `r₀ᵀz₀` is).
fn with_convergence(xs: Vec<Vec<f32>>, sc: &[f32]) -> Vec<Reply0> {
    xs.into_iter()
        .zip(sc.chunks(SLOTS))
        .map(|(x, s)| {
            let (rz, rz0) = (s[SLOT_RZ] as f64, s[SLOT_RZ0] as f64);
            let conv = Convergence {
                iterations: s[SLOT_ITER] as u32,
                residual: if rz0 > 0.0 { (rz / rz0).sqrt() } else { 0.0 },
            };
            (x, conv)
        })
        .collect()
}

pub(super) type Reply0 = (Vec<f32>, Convergence);

/// Where one batch's time went on the device thread.
pub(super) struct Timing {
    pub(super) submissions: u64,
    pub(super) upload_s: f64,
    pub(super) kernel_s: f64,
    pub(super) read_s: f64,
}
