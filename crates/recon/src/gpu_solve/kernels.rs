//! What the host shares with `shaders/solve.wgsl`: the uniform block of a dispatch
//! ([`Params`]), the scalar slots of a leaf and the vectors of `vecs`, the kernels and their
//! pipelines (built once a device, [`Pipelines::build`]), and the plan of a batch's
//! dispatches in their order ([`Plan::batch`]).

/// Scalars per leaf (`solve.wgsl`: slots).
pub(super) const SLOTS: usize = 16;
pub(super) const SLOT_ACTIVE: usize = 8;
pub(super) const SLOT_ITER: usize = 9;
pub(super) const SLOT_RZ: usize = 3;
pub(super) const SLOT_RZ0: usize = 4;
/// Vectors in `vecs`.
pub(super) const X: u32 = 0;
pub(super) const R: u32 = 1;
pub(super) const Z: u32 = 2;
pub(super) const P: u32 = 3;
pub(super) const LP: u32 = 4;
pub(super) const DIV: u32 = 5;
/// Nodes a workgroup of a dot product sums (`vdot`; at most 64 workgroups a leaf).
pub(super) const DOT_NODES: usize = 8192;
/// Scalar slots a dot product goes to.
pub(super) const SLOT_PLP: u32 = 5;
pub(super) const SLOT_RZNEW: u32 = 13;

/// The uniform block of one dispatch (`solve.wgsl`: `Params`).
#[repr(C)]
#[derive(Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct Params {
    pub(super) n: u32,
    /// log2 of `n`'s power-of-two factor `m` (`n = radix·m`).
    pub(super) log2n: u32,
    pub(super) nn: u32,
    pub(super) batch: u32,
    pub(super) axis: u32,
    pub(super) inverse: u32,
    pub(super) ends: u32,
    pub(super) all: u32,
    pub(super) src: u32,
    pub(super) dst: u32,
    pub(super) va: u32,
    pub(super) vb: u32,
    pub(super) mode: u32,
    pub(super) slot: u32,
    pub(super) count: u32,
    pub(super) gx: u32,
    pub(super) stride: u32,
    pub(super) s_node: u32,
    pub(super) s_leaf: u32,
    pub(super) t_node: u32,
    pub(super) t_start: u32,
    pub(super) t_ent: u32,
    pub(super) tw: u32,
    pub(super) k2: u32,
    pub(super) filt: u32,
    pub(super) h1: u32,
    pub(super) tol2: f32,
    pub(super) shift: f32,
    pub(super) max_iter: f32,
    /// 1, or 3 where `n = 3m` (a radix-3 stage after the radix-2 ones).
    pub(super) radix: u32,
    pub(super) pad: [u32; 2],
}

/// The pipelines of `solve.wgsl`.
pub(super) struct Pipelines {
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

impl Pipelines {
    /// The bind group layout (binding 0: the uniform block at a dynamic offset; 1–7: the
    /// storage buffers) and the pipelines of `solve.wgsl`'s entry points, on `device`.
    pub(super) fn build(device: &wgpu::Device) -> (wgpu::BindGroupLayout, Pipelines) {
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
            source: wgpu::ShaderSource::Wgsl(include_str!("../shaders/solve.wgsl").into()),
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
        (layout, pipes)
    }

    /// The pipeline of kernel `k`.
    pub(super) fn get(&self, k: Kernel) -> &wgpu::ComputePipeline {
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

/// The entry points of `solve.wgsl`, a pipeline each.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(super) enum Kernel {
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

/// One dispatch: its kernel, workgroups and uniform block.
pub(super) struct Op {
    pub(super) kernel: Kernel,
    pub(super) groups: (u32, u32, u32),
    pub(super) block: usize,
}

/// What a batch's dispatches depend on: the uniform block they start from, the leaves, and
/// the workgroup grids of each kind of dispatch (`(gx, gy)`, `Device::groups`).
pub(super) struct Shape {
    /// The uniform block of the batch; each dispatch sets its own fields over it.
    pub(super) base: Params,
    /// Leaves in the batch.
    pub(super) b: u32,
    /// A thread a node of a leaf.
    pub(super) node_groups: (u32, u32),
    /// The FFT's lines of a leaf (`max(1, 512/n)` a workgroup).
    pub(super) line_groups: (u32, u32),
    /// A thread a sample (aggregate) of the batch.
    pub(super) s_groups: (u32, u32),
    /// A thread a touched node of the batch (the scatter).
    pub(super) t_groups: (u32, u32),
    /// Samples of the batch.
    pub(super) s_total: usize,
    /// Touched nodes of the batch.
    pub(super) t_total: usize,
    /// Workgroups of a leaf's dot product (`vdot`), each leaving a partial sum.
    pub(super) parts: usize,
}

/// The dispatches of a batch and their uniform blocks.
pub(super) struct Plan {
    pub(super) blocks: Vec<Params>,
    pub(super) ops: Vec<Op>,
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

    /// The dispatches of a batch of `sh`'s shape and where its start ends: the start (the
    /// Poisson solve of every leaf, then, where the batch has samples, the screening's start:
    /// the gather, `Σγ`, `c` and `μ`, the residual `r`, `z = (L + μ)⁻¹ r`, `rᵀz`), then one
    /// conjugate-gradient iteration (`S p`, `pᵀLp + Σγ(Sp)²`, the step, `Sᵀ`, `z`, `rᵀz`,
    /// `β`), which the host sends as often as the leaves need.
    pub(super) fn batch(sh: &Shape) -> (Plan, usize) {
        let mut plan = Plan {
            blocks: Vec::new(),
            ops: Vec::new(),
        };
        // Start: the Poisson solve of every leaf, then the screening's start.
        plan.spectral(sh, DIV, X, 0, 1);
        let screened = sh.s_total > 0;
        if screened {
            plan.samples(sh, Kernel::Gather, X, 0, 1);
            plan.per_leaf(sh, Kernel::Ssum, 0, 0, 0, 1);
            plan.scalars(sh, 0);
            plan.per_node(sh, Kernel::Vop, 0, 0);
            plan.samples(sh, Kernel::Coef, 0, 0, 0);
            plan.samples(sh, Kernel::Scatter, 0, 0, 0);
            plan.spectral(sh, R, Z, 1, 0);
            plan.per_leaf(sh, Kernel::Dot, R, Z, SLOT_RZNEW, 0);
            plan.scalars(sh, 1);
            plan.per_node(sh, Kernel::Vop, 1, 0);
        }
        let start_ops = plan.ops.len();
        // One iteration.
        plan.samples(sh, Kernel::Gather, P, 0, 0);
        plan.per_leaf(sh, Kernel::Ssum, 0, 0, 0, 0);
        plan.per_leaf(sh, Kernel::Dot, P, LP, SLOT_PLP, 0);
        plan.scalars(sh, 2);
        plan.per_node(sh, Kernel::Vop, 2, 0);
        plan.samples(sh, Kernel::Coef, 0, 1, 0);
        plan.samples(sh, Kernel::Scatter, 0, 0, 0);
        plan.spectral(sh, R, Z, 1, 0);
        plan.per_leaf(sh, Kernel::Dot, R, Z, SLOT_RZNEW, 0);
        plan.scalars(sh, 3);
        plan.per_node(sh, Kernel::Vop, 3, 0);
        (plan, start_ops)
    }

    /// A spectral solve of vector `src` into `dst`: forward transforms along x, y and z, the
    /// multiplier `mode` (0: the Poisson filter, 1: the preconditioner `1/(|k|² + μ)`), the
    /// inverse transforms along z, y and x. `all` (here and below): 1 runs every leaf, 0 only
    /// those whose flag says they still run.
    fn spectral(&mut self, sh: &Shape, src: u32, dst: u32, mode: u32, all: u32) {
        let (line_groups, node_groups, b, base) = (sh.line_groups, sh.node_groups, sh.b, sh.base);
        for (axis, inverse) in [(0, 0), (1, 0), (2, 0)] {
            let ends = if axis == 0 { 1 } else { 0 };
            self.push(
                Kernel::Fft,
                (line_groups.0, line_groups.1, b),
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
        self.push(
            Kernel::Mul,
            (node_groups.0, node_groups.1, b),
            Params {
                mode,
                all,
                gx: node_groups.0,
                ..base
            },
        );
        for axis in [2, 1, 0] {
            let ends = if axis == 0 { 2 } else { 0 };
            self.push(
                Kernel::Fft,
                (line_groups.0, line_groups.1, b),
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
    }

    /// A node-wise kernel (`vop`'s update `mode`), a thread a node of every leaf.
    fn per_node(&mut self, sh: &Shape, kern: Kernel, mode: u32, all: u32) {
        self.push(
            kern,
            (sh.node_groups.0, sh.node_groups.1, sh.b),
            Params {
                mode,
                all,
                gx: sh.node_groups.0,
                ..sh.base
            },
        );
    }

    /// A sample-wise kernel over the batch's samples (`gather` of vector `src`, `coef` of
    /// `mode`), or its touched nodes (`scatter`), a thread each.
    fn samples(&mut self, sh: &Shape, kern: Kernel, src: u32, mode: u32, all: u32) {
        let (g, count) = if kern == Kernel::Scatter {
            (sh.t_groups, sh.t_total)
        } else {
            (sh.s_groups, sh.s_total)
        };
        self.push(
            kern,
            (g.0, g.1, 1),
            Params {
                src,
                mode,
                all,
                count: count as u32,
                gx: g.0,
                ..sh.base
            },
        );
    }

    /// A per-leaf reduction into scalar `slot`: a dot product of vectors `va` and `vb`
    /// (`vdot`'s partial sums, then `vsum` of them in order), or the samples' sums (`ssum`).
    fn per_leaf(&mut self, sh: &Shape, kern: Kernel, va: u32, vb: u32, slot: u32, all: u32) {
        let b = sh.b;
        if kern == Kernel::Dot {
            let p = Params {
                va,
                vb,
                slot,
                all,
                count: sh.parts as u32,
                ..sh.base
            };
            self.push(kern, (sh.parts as u32, 1, b), p);
            self.push(Kernel::Vsum, (b.div_ceil(64), 1, 1), p);
        } else {
            self.push(
                kern,
                (b, 1, 1),
                Params {
                    va,
                    vb,
                    slot,
                    all,
                    ..sh.base
                },
            );
        }
    }

    /// The scalars of every leaf, a thread each (`scalars` mode 0: `Σγ`, `c`, `μ`; 1: the
    /// start; 2: the step; 3: `β` and the stop).
    fn scalars(&mut self, sh: &Shape, mode: u32) {
        self.push(
            Kernel::Scalars,
            (sh.b.div_ceil(64), 1, 1),
            Params { mode, ..sh.base },
        );
    }
}
