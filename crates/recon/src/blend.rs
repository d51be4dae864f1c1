//! A tile's field as a blend of the coarse solution and the leaf details (step 3 of the
//! two-level scheme), and which leaves reach a tile.

use std::collections::BTreeSet;
use std::sync::Arc;

use super::coarse::CoarseField;
use super::plan::Plan;
use crate::error::Result;
use crate::types::{Blend, CellKey, Detail, Leaf};

/// Leaves whose detail support (cell plus overlap) meets fine nodes `lo..=hi`.
pub fn leaves_near(
    plan: &Plan,
    leaves: &BTreeSet<CellKey>,
    lo: [i64; 3],
    hi: [i64; 3],
) -> Vec<CellKey> {
    let e = plan.leaf_voxels as i64;
    let ov = plan.overlap_voxels as i64;
    let side = (plan.fine_cells / plan.leaf_voxels) as i64;
    let c0 = lo.map(|v| ((v - ov - e).div_euclid(e) + 1).max(0));
    let c1 = hi.map(|v| ((v + ov).div_euclid(e)).min(side - 1));
    let mut out = Vec::new();
    for z in c0[2]..=c1[2] {
        for y in c0[1]..=c1[1] {
            for x in c0[0]..=c1[0] {
                let k = CellKey::new(plan.leaf_level, [x as u32, y as u32, z as u32]);
                if leaves.contains(&k) {
                    out.push(k);
                }
            }
        }
    }
    out.sort();
    out
}

/// A tile's `(T+1)³` nodes from fine node `lo` as a blend ([`Blend`]) of the coarse solution
/// and the leaf details `details` (fixed point in `unit`), with per-axis leaf weights `own`
/// ([`super::pou::leaf_weights`]). The extraction stage evaluates it (on the CPU or the GPU).
pub fn tile_blend<'a>(
    plan: &Plan,
    own: &[i32],
    coarse: &CoarseField,
    unit: f32,
    lo: [i64; 3],
    details: &'a [(CellKey, Arc<Detail>)],
) -> Result<Blend<'a>> {
    let dims = [(plan.tile + 1) as usize; 3];
    blend_block(plan, own, coarse, unit, lo, dims, details)
}

/// [`tile_blend`] for any block of `dims` nodes from fine node `lo` (a level of the recursive
/// scheme blends the windows the level below reads, [`CoarseField::local`]). Reading the
/// coarse values of a level above fails only on its leaves' checkpoints.
pub fn blend_block<'a>(
    plan: &Plan,
    own: &[i32],
    coarse: &CoarseField,
    unit: f32,
    lo: [i64; 3],
    dims: [usize; 3],
    details: &'a [(CellKey, Arc<Detail>)],
) -> Result<Blend<'a>> {
    let (cvals, coarse_dims, axes) = coarse.block(lo, dims, unit)?;
    Ok(Blend {
        lo,
        dims,
        axes,
        coarse: cvals,
        coarse_dims,
        coarse_bits: plan.coarse_ratio.trailing_zeros(),
        e: plan.leaf_voxels as i64,
        ov: plan.overlap_voxels as i64,
        own: own.to_vec(),
        unit,
        leaves: details
            .iter()
            .map(|(k, d)| Leaf {
                cell: k.decode().1.map(|v| v as i64),
                id: k.0,
                detail: &d.values,
                shift: d.shift,
            })
            .collect(),
    })
}
