//! What the host shares with `shaders/solve.wgsl`: the uniform block of a dispatch
//! ([`Params`]), the scalar slots of a leaf and the vectors of `vecs`, the kernels and their
//! pipelines, and the plan of a batch's dispatches ([`Plan`]).

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
    pub(super) fft: wgpu::ComputePipeline,
    pub(super) mul: wgpu::ComputePipeline,
    pub(super) vop: wgpu::ComputePipeline,
    pub(super) gather: wgpu::ComputePipeline,
    pub(super) coef: wgpu::ComputePipeline,
    pub(super) scatter: wgpu::ComputePipeline,
    pub(super) dot: wgpu::ComputePipeline,
    pub(super) vsum: wgpu::ComputePipeline,
    pub(super) ssum: wgpu::ComputePipeline,
    pub(super) scalars: wgpu::ComputePipeline,
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

impl Pipelines {
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

/// One dispatch: its kernel, workgroups and uniform block.
pub(super) struct Op {
    pub(super) kernel: Kernel,
    pub(super) groups: (u32, u32, u32),
    pub(super) block: usize,
}

/// The dispatches of a batch and their uniform blocks.
pub(super) struct Plan {
    pub(super) blocks: Vec<Params>,
    pub(super) ops: Vec<Op>,
}

impl Plan {
    pub(super) fn push(&mut self, kernel: Kernel, groups: (u32, u32, u32), p: Params) {
        self.blocks.push(p);
        self.ops.push(Op {
            kernel,
            groups,
            block: self.blocks.len() - 1,
        });
    }
}
