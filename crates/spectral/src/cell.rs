//! A store cell's share of the work: its patches (pass 1), and its points' blended positions
//! or its resampled points (pass 2).
//!
//! **Pass 1** lays out the cell's own points into patches ([`layout`]), frames
//! them ([`patch::frame`]), and fits each one's height field to its members and to every
//! point of the cell or its *halo* that its box admits. The halo is the points of other cells
//! within [`CellPlan::reach`] of the cell's box, the farthest any patch's box reaches out, so
//! a patch sees the same points whatever the cell boundaries: patches do not stop at cell
//! faces, yet each belongs to one cell (the one its members are in), and every point is a
//! member of exactly one patch.
//!
//! **Pass 2** takes a cell's points and every patch, of this cell or another, whose box
//! reaches them. A point's position is the weighted mean of its projections onto the patches
//! that admit it, weighted by their blending functions (§7, [`patch`]); its normal likewise,
//! unless the patches' normals disagree (the weighted mean's length under
//! [`NORMAL_AGREEMENT`]), where the least-squares plane of the heaviest patch's nodes around
//! it gives the normal instead (the paper's fallback). A point no patch admits keeps its
//! position and normal.
//!
//! **Resampling (§6)** replaces pass 2's points by new ones: each patch places candidates on
//! its surface from a progressive Poisson-disk pattern ([`pattern`](super::pattern)) tiled
//! over its members' rectangle at the highest rate among the patches around it; a candidate survives where
//! this patch weighs most among those admitting it (so that each place is sampled by one
//! patch) and where its index in the pattern is below the blended rate's count for a tile
//! (the prefix property thins the pattern to any density). Its position and normal are blended
//! as in pass 2.

use super::buckets::Buckets;
use super::layout::{self, LayoutParams, PatchSeed};
use super::patch::{self, Frame, Overlap, Patch, PatchWork, Treatment};
use super::pattern::poisson_disk;

/// Blended normals whose weighted mean is shorter than this (1 when all agree) take the
/// least-squares fallback.
pub const NORMAL_AGREEMENT: f64 = 0.9;

/// Patches per bucket of the patch index.
const PATCHES_PER_BUCKET: f64 = 2.0;

/// Points per bucket of the admission index.
const POINTS_PER_BUCKET: f64 = 32.0;

/// Pass 1's plan of a cell: its seeds, their frames, and how far beyond the cell's box their
/// boxes reach.
#[derive(Debug, Clone)]
pub struct CellPlan {
    /// Patch seeds from the layout.
    pub seeds: Vec<PatchSeed>,
    /// Each seed's frame; `None` for seeds too small to approximate.
    pub frames: Vec<Option<Frame>>,
    /// Largest distance a frame's world bounds reach beyond `[lo, hi]` of the cell's points.
    pub reach: f64,
}

/// Lay out and frame a cell's own points.
pub fn plan_cell(
    pos: &[[f64; 3]],
    normal: &[[f32; 3]],
    lp: &LayoutParams,
    ov: &Overlap,
    work: &mut PatchWork,
) -> CellPlan {
    let seeds = layout::layout_with(&mut work.layout, pos, normal, lp);
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in pos {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let mut reach = 0f64;
    let frames: Vec<Option<Frame>> = seeds
        .iter()
        .map(|s| {
            let f = patch::frame(pos, s, ov, work)?;
            let (a, b) = f.world_bounds();
            for k in 0..3 {
                reach = reach.max(lo[k] - a[k]).max(b[k] - hi[k]);
            }
            Some(f)
        })
        .collect();
    CellPlan {
        seeds,
        frames,
        reach,
    }
}

/// Pass 1's result for a cell.
#[derive(Debug, Clone, Default)]
pub struct CellPatches {
    /// The cell's patches, in seed order (seeds too small to approximate have none).
    pub patches: Vec<Patch>,
    /// Each own point's patch (index into `patches`), `u32::MAX` for none.
    pub patch_of: Vec<u32>,
    /// Points in seeds too small to approximate.
    pub unpatched: u64,
}

/// Fit every planned patch of a cell to its own points (`pos`, `normal`) and its halo.
/// `keep_raw` is called with each patch's index and the grid before treatment (spectra of
/// chosen patches).
#[allow(clippy::too_many_arguments)]
pub fn fit_cell(
    pos: &[[f64; 3]],
    normal: &[[f32; 3]],
    halo_pos: &[[f64; 3]],
    halo_normal: &[[f32; 3]],
    plan: &CellPlan,
    treat: &Treatment,
    work: &mut PatchWork,
    mut keep_raw: impl FnMut(usize, &mut PatchWork),
) -> CellPatches {
    let own = pos.len();
    let all_pos: Vec<[f64; 3]> = pos.iter().chain(halo_pos).copied().collect();
    let all_n: Vec<[f32; 3]> = normal.iter().chain(halo_normal).copied().collect();
    let grid = Buckets::of_points(&all_pos, POINTS_PER_BUCKET);
    let mut stamp = vec![u32::MAX; all_pos.len()];
    let mut out = CellPatches {
        patches: Vec::with_capacity(plan.seeds.len()),
        patch_of: vec![u32::MAX; own],
        unpatched: 0,
    };
    let mut pts: Vec<[f64; 3]> = Vec::new();
    for (si, (seed, frame)) in plan.seeds.iter().zip(&plan.frames).enumerate() {
        let Some(frame) = frame else {
            out.unpatched += seed.members.len() as u64;
            continue;
        };
        let pi = out.patches.len() as u32;
        pts.clear();
        for &m in &seed.members {
            stamp[m as usize] = si as u32;
            out.patch_of[m as usize] = pi;
            pts.push(frame.local(all_pos[m as usize]));
        }
        let (a, b) = frame.world_bounds();
        grid.in_box(a, b, |i| {
            let iu = i as usize;
            if stamp[iu] == si as u32 {
                return;
            }
            let l = frame.local(all_pos[iu]);
            if frame.admits(l, all_n[iu]) {
                stamp[iu] = si as u32;
                pts.push(l);
            }
        });
        let p = patch::build(*frame, &seed.cone, &pts, seed.members.len(), treat, work);
        keep_raw(pi as usize, work);
        out.patches.push(p);
    }
    out
}

/// The patches that may reach a cell's points in pass 2, with an index over their boxes.
pub struct Around<'a> {
    /// The patches, in a fixed global order (source cell, then patch).
    pub patches: Vec<&'a Patch>,
    index: Buckets,
}

impl<'a> Around<'a> {
    /// Index `patches` by their world bounds.
    pub fn new(patches: Vec<&'a Patch>) -> Around<'a> {
        let boxes: Vec<([f64; 3], [f64; 3])> =
            patches.iter().map(|p| p.frame.world_bounds()).collect();
        Around {
            index: Buckets::of_boxes(&boxes, PATCHES_PER_BUCKET),
            patches,
        }
    }

    /// Blend the patches admitting the world point `p` with normal `n` (see the [module
    /// docs](self)); `None` when none does.
    pub fn blend(&self, p: [f64; 3], n: [f32; 3]) -> Option<Blended> {
        let mut acc = Acc::default();
        for &i in self.index.at(p) {
            if let Some(s) = self.patches[i as usize].sample(p, n) {
                acc.add(i, &s, self.patches[i as usize]);
            }
        }
        acc.finish(p, self)
    }
}

/// A point blended from the patches admitting it.
#[derive(Debug, Clone, Copy)]
pub struct Blended {
    /// Position.
    pub pos: [f64; 3],
    /// Unit normal.
    pub normal: [f64; 3],
    /// Index (in [`Around::patches`]) of the patch weighing most.
    pub heaviest: u32,
    /// Whether the normal is the least-squares fallback.
    pub fallback: bool,
    /// Blended sampling rate (resampling).
    pub rate: f64,
}

#[derive(Default)]
struct Acc {
    w: f64,
    p: [f64; 3],
    n: [f64; 3],
    rate: f64,
    best: Option<(f64, u32)>,
}

impl Acc {
    #[inline]
    fn add(&mut self, i: u32, s: &patch::Sample, patch: &Patch) {
        self.w += s.weight;
        for k in 0..3 {
            self.p[k] += s.weight * s.pos[k];
            self.n[k] += s.weight * s.normal[k];
        }
        self.rate += s.weight * patch.rate as f64;
        if self.best.is_none_or(|(bw, _)| s.weight > bw) {
            self.best = Some((s.weight, i));
        }
    }

    fn finish(self, p: [f64; 3], around: &Around<'_>) -> Option<Blended> {
        let (_, heaviest) = self.best?;
        let w = self.w;
        let pos = self.p.map(|x| x / w);
        let n = self.n.map(|x| x / w);
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        let (normal, fallback) = if len >= NORMAL_AGREEMENT {
            (n.map(|x| x / len), false)
        } else {
            let hp = around.patches[heaviest as usize];
            let l = hp.frame.local(p);
            (hp.ls_normal(l[0], l[1]), true)
        };
        Some(Blended {
            pos,
            normal,
            heaviest,
            fallback,
            rate: self.rate / w,
        })
    }
}

/// Pass 2's result for a cell's points.
#[derive(Debug, Clone, Default)]
pub struct BlendStats {
    /// Points whose normal took the least-squares fallback.
    pub fallback: u64,
    /// Points no patch admitted (kept as they were).
    pub unblended: u64,
}

/// Blend every point of a cell in place (positions and normals); `heaviest` receives each
/// point's heaviest patch (`u32::MAX` for none).
pub fn blend_cell(
    around: &Around<'_>,
    pos: &mut [[f64; 3]],
    normal: &mut [[f32; 3]],
    heaviest: &mut Vec<u32>,
) -> BlendStats {
    let mut st = BlendStats::default();
    heaviest.clear();
    for (p, n) in pos.iter_mut().zip(normal.iter_mut()) {
        match around.blend(*p, *n) {
            Some(b) => {
                *p = b.pos;
                *n = b.normal.map(|x| x as f32);
                st.fallback += b.fallback as u64;
                heaviest.push(b.heaviest);
            }
            None => {
                st.unblended += 1;
                heaviest.push(u32::MAX);
            }
        }
    }
    st
}

/// Resample the patches `own` (indices into `around.patches`) with their rates multiplied by
/// `scale`; appends positions and normals. Returns the fallback count.
pub fn resample_cell(
    around: &Around<'_>,
    own: &[u32],
    scale: f64,
    pos: &mut Vec<[f64; 3]>,
    normal: &mut Vec<[f32; 3]>,
) -> u64 {
    let pattern = poisson_disk();
    let plen = pattern.len() as f64;
    let mut fallback = 0;
    let mut near: Vec<u32> = Vec::new();
    for &pi in own {
        let patch = around.patches[pi as usize];
        let (a, b) = patch.frame.world_bounds();
        near.clear();
        around.index.in_box(a, b, |i| near.push(i));
        let top = near
            .iter()
            .map(|&i| around.patches[i as usize].rate as f64)
            .fold(patch.rate as f64, f64::max)
            * scale;
        if top.is_nan() || top <= 0.0 {
            continue;
        }
        // Tiles of the pattern: at `top`, one tile holds the whole pattern.
        let t = (plen / top).sqrt();
        // Candidates within the members' rectangle: every place on the surface lies in the
        // rectangle of the patch it is a member of, whose weight there is about 1, and a
        // patch's margin beyond its members is extrapolated.
        let bx = patch.frame.core;
        let (tu, tv) = (
            ((bx[2] - bx[0]) / t).ceil().max(1.0) as usize,
            ((bx[3] - bx[1]) / t).ceil().max(1.0) as usize,
        );
        for tj in 0..tv {
            for ti in 0..tu {
                for (k, q) in pattern.iter().enumerate() {
                    let u = bx[0] + (ti as f64 + q[0]) * t;
                    let v = bx[1] + (tj as f64 + q[1]) * t;
                    if u > bx[2] || v > bx[3] {
                        continue;
                    }
                    let s = patch.sample_at(u, v);
                    if s.weight.is_nan() || s.weight <= 0.0 {
                        continue;
                    }
                    let n = s.normal.map(|x| x as f32);
                    let Some(bl) = around.blend(s.pos, n) else {
                        continue;
                    };
                    if bl.heaviest != pi || (k as f64) >= bl.rate * scale * t * t {
                        continue;
                    }
                    pos.push(bl.pos);
                    normal.push(bl.normal.map(|x| x as f32));
                    fallback += bl.fallback as u64;
                }
            }
        }
    }
    fallback
}
