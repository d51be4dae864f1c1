//! One batch on the device: the batch's index lists and weights, their upload, the plan of
//! dispatches (the Poisson solve, the screening's start, one conjugate-gradient iteration),
//! the submissions until every leaf has stopped, and the solutions read back.

use std::time::Instant;

use wgpu::BufferUsages as U;

use super::device::{Buffers, Device, ensure, entry, mapped, read_back};
use super::fft_radix;
use super::kernels::{
    DIV, DOT_NODES, Kernel, LP, Op, P, Params, Plan, R, SLOT_ACTIVE, SLOT_ITER, SLOT_PLP, SLOT_RZ,
    SLOT_RZ0, SLOT_RZNEW, SLOTS, X, Z,
};
use super::prep::Prepared;
use crate::extract::gpu::adapter;
use crate::fft_solve::{
    Convergence, PRECONDITIONER_SHIFT, SCREEN_MAX_ITERATIONS, SCREEN_TOLERANCE,
};

/// Conjugate-gradient iterations sent in one submission, between reads of the leaves' flags.
const ITERATIONS_PER_SUBMISSION: u32 = 2;

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

pub(super) type Reply0 = (Vec<f32>, Convergence);

/// Where one batch's time went on the device thread.
pub(super) struct Timing {
    pub(super) submissions: u64,
    pub(super) upload_s: f64,
    pub(super) kernel_s: f64,
    pub(super) read_s: f64,
}
