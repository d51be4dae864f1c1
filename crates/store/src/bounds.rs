//! Pass 1, bounds: the provisional box the count pass lays its grid over.

use rayon::prelude::*;

use crate::cell_file::batch_bounds;
use crate::error::Result;
use crate::exec::Ctx;
use crate::input::Inputs;
use crate::io::ChunkSpec;
use crate::types::{Aabb, Cube, PointBatch};

/// Points per sample window: the smallest chunk the budget ever sizes, so a window always fits
/// where a chunk does. Fixed, so that the sample, and the cube, never depend on the budget or
/// the number of threads.
pub const SAMPLE_WINDOW_POINTS: u64 = crate::MIN_CHUNK_POINTS;
/// The sample reads about one window in this many...
pub const SAMPLE_ONE_IN: usize = 64;
/// ...and at least this many windows (fewer only when the inputs have fewer).
pub const SAMPLE_MIN_WINDOWS: usize = 64;

/// The provisional bounds: the headers' where every input has them (LAS, no read at all),
/// else the bounds of a deterministic sample of about one window in [`SAMPLE_ONE_IN`] (every
/// `stride`-th window and the last one) of `chunks` (windows of [`SAMPLE_WINDOW_POINTS`]),
/// read in parallel. Each window in flight holds `chunk_bytes` of the budget.
pub fn provisional(
    inputs: &Inputs,
    chunks: &[(usize, ChunkSpec)],
    chunk_bytes: u64,
    ctx: &Ctx,
) -> Result<Aabb> {
    if let Some(b) = inputs.header_bounds() {
        return Ok(b);
    }
    let want = (chunks.len() / SAMPLE_ONE_IN).max(SAMPLE_MIN_WINDOWS);
    let stride = (chunks.len() / want).max(1);
    let sample: Vec<&(usize, ChunkSpec)> = chunks
        .iter()
        .enumerate()
        .filter(|(i, _)| i % stride == 0 || *i + 1 == chunks.len())
        .map(|(_, c)| c)
        .collect();
    let res: Vec<Result<Aabb>> = ctx.pool.install(|| {
        sample
            .par_iter()
            .map_init(PointBatch::default, |batch, (ri, spec)| {
                let _permit = ctx.budget.acquire(chunk_bytes, "a chunk of points")?;
                inputs.load(batch, *ri, spec)?;
                Ok(batch_bounds(batch))
            })
            .collect()
    });
    let mut b = Aabb::EMPTY;
    for r in res {
        b = b.union(&r?);
    }
    Ok(b)
}

/// True when `b` lies inside cube `c`.
pub fn within(b: &Aabb, c: &Cube) -> bool {
    (0..3).all(|a| b.min[a] >= c.origin[a] && b.max[a] <= c.origin[a] + c.size)
}
