//! Pass 2, count: every point's cell on a counting grid over the root cube, with the exact
//! bounds measured on the way.

use std::sync::atomic::{AtomicU64, Ordering};

use rayon::prelude::*;

use crate::error::Result;
use crate::exec::Ctx;
use crate::io::ChunkSpec;
use crate::store::CUBE_MARGIN;
use crate::store::bounds::within;
use crate::store::cell_file::batch_bounds;
use crate::store::input::Inputs;
use crate::store::octree::GridMap;
use crate::types::{Aabb, CellKey, Cube, PointBatch};

/// Bytes of one counting grid cell: a `u64` count.
const GRID_CELL_BYTES: u64 = 8;

/// Levels the counting grid never exceeds: `8^7` cells (2 M), 36 MiB with the hierarchy.
const MAX_GRID_LEVELS: u32 = 7;

/// Bytes of one copy of a counting grid of `cells` cells with the coarser levels that
/// [`crate::store::octree::Hierarchy::build`] sums from it (at most an eighth more).
fn grid_copy_bytes(cells: u64) -> u64 {
    cells * GRID_CELL_BYTES * 9 / 8
}

/// Bytes admitted for a counting grid of `cells` cells: two copies, the counts being
/// collected and the hierarchy's finest level copied from them.
pub fn grid_bytes(cells: u64) -> u64 {
    grid_copy_bytes(cells) * 2
}

/// The most levels a counting grid may have for its (single) copy to fit `slice` bytes, the
/// budget's [`crate::exec::budget::Share::CountingGrid`]; at least 1.
pub fn max_levels(slice: u64) -> u32 {
    let mut l = MAX_GRID_LEVELS;
    while l > 1 && grid_copy_bytes(1u64 << (3 * l)) > slice {
        l -= 1;
    }
    l
}

/// What the count pass found.
pub struct Counted {
    /// The root cube the counts are laid over.
    pub cube: Cube,
    /// Points per grid cell, in Morton order (empty when there are no valid points).
    pub counts: Vec<u64>,
    /// The exact bounds of the valid points.
    pub bounds: Aabb,
    /// Points skipped as invalid.
    pub skipped: u64,
}

/// Count on the cube around `provisional`. Only when the exact bounds leave that cube with
/// less than half its margin is the count repeated on the cube around the exact bounds, so
/// that typical inputs are read twice (count, scatter), not three times. When the sample held
/// no valid point, a first count only measures the exact bounds.
pub fn count_pass(
    inputs: &Inputs,
    chunks: &[(usize, ChunkSpec)],
    chunk_bytes: u64,
    provisional: &Aabb,
    levels: u32,
    ctx: &Ctx,
) -> Result<Counted> {
    let count = |cube: &Cube| count_on(inputs, chunks, chunk_bytes, cube, levels, ctx);
    let mut cube = Cube::around(provisional, CUBE_MARGIN);
    let (mut counts, mut bounds, mut skipped) = if provisional.is_empty() {
        (Vec::new(), Aabb::EMPTY, 0)
    } else {
        count(&cube)?
    };
    if !bounds.is_empty() && !within(&bounds, &Cube::around(provisional, CUBE_MARGIN / 2.0)) {
        log::info!("the points reach beyond the sampled bounds; counting again on the exact cube");
        cube = Cube::around(&bounds, CUBE_MARGIN);
        (counts, bounds, skipped) = count(&cube)?;
    } else if provisional.is_empty() {
        // Every sampled point was invalid: count on the exact bounds found by a full pass.
        let unit = Aabb {
            min: [0.0; 3],
            max: [1.0; 3],
        };
        let (_, b, _) = count(&Cube::around(&unit, 0.0))?;
        if !b.is_empty() {
            cube = Cube::around(&b, CUBE_MARGIN);
            (counts, bounds, skipped) = count(&cube)?;
        }
    }
    Ok(Counted {
        cube,
        counts,
        bounds,
        skipped,
    })
}

/// One full read of the inputs, counting each point on the grid of `8^levels` cells over
/// `cube`; returns the counts, the exact bounds and the points skipped as invalid.
fn count_on(
    inputs: &Inputs,
    chunks: &[(usize, ChunkSpec)],
    chunk_bytes: u64,
    cube: &Cube,
    levels: u32,
    ctx: &Ctx,
) -> Result<(Vec<u64>, Aabb, u64)> {
    let grid_cells = 1usize << (3 * levels);
    let counts: Vec<AtomicU64> = (0..grid_cells).map(|_| AtomicU64::new(0)).collect();
    let root_map = GridMap::new(cube, CellKey::ROOT, levels);
    let stage = ctx.progress.stage("count", Some(inputs.total), "points");
    let res: Vec<Result<(Aabb, u64)>> = ctx.pool.install(|| {
        chunks
            .par_iter()
            .map_init(PointBatch::default, |batch, (ri, spec)| {
                let _permit = ctx.budget.acquire(chunk_bytes, "a chunk of points")?;
                let skipped = inputs.load(batch, *ri, spec)?;
                for p in &batch.pos {
                    counts[root_map.index(*p) as usize].fetch_add(1, Ordering::Relaxed);
                }
                stage.inc(spec.count);
                Ok((batch_bounds(batch), skipped))
            })
            .collect()
    });
    let mut bounds = Aabb::EMPTY;
    let mut skipped = 0;
    for r in res {
        let (bb, sk) = r?;
        bounds = bounds.union(&bb);
        skipped += sk;
    }
    stage.finish(None);
    Ok((
        counts.into_iter().map(|c| c.into_inner()).collect(),
        bounds,
        skipped,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_sizes_match_the_budget_slice() {
        // 8^7 cells fit a slice of 18 MiB + a bit; one level less below that.
        let full = grid_copy_bytes(1 << 21);
        assert_eq!(full, (8u64 << 21) * 9 / 8);
        assert_eq!(max_levels(full), 7);
        assert_eq!(max_levels(full - 1), 6);
        assert_eq!(max_levels(0), 1);
        assert_eq!(grid_bytes(1 << 21), 2 * full);
    }
}
