//! Which leaves reach a block of fine nodes: those whose detail support (cell plus overlap)
//! meets it. The blend itself reads a level's coarse field, so it lives with that field
//! ([`super::coarse::blend_block`]).

use std::collections::BTreeSet;

use super::plan::Plan;
use crate::types::CellKey;

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
