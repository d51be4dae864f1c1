//! Pass 2, count: every point's cell on a counting grid over the root cube, with the exact
//! bounds measured on the way.

use std::sync::atomic::{AtomicU64, Ordering};

use rayon::prelude::*;

use crate::CUBE_MARGIN;
use crate::bounds::within;
use crate::cell_file::batch_bounds;
use crate::error::Result;
use crate::exec::Ctx;
use crate::exec::progress::Stage;
use crate::fs::le::{LeReader, LeWriter};
use crate::input::Inputs;
use crate::io::ChunkSpec;
use crate::octree::GridMap;
use crate::types::{Aabb, CellKey, Cube, PointBatch};

/// Bytes of one counting grid cell: a `u64` count.
const GRID_CELL_BYTES: u64 = 8;

/// Levels the counting grid never exceeds: `8^7` cells (2 M), 36 MiB with the hierarchy.
const MAX_GRID_LEVELS: u32 = 7;

/// Bytes of one copy of a counting grid of `cells` cells with the coarser levels that
/// [`crate::octree::Hierarchy::build`] sums from it (at most an eighth more).
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

/// The cube the first count is laid over: around `provisional`, or, when the sample held no
/// valid point, the unit cube (that count only measures the exact bounds).
pub fn first_cube(provisional: &Aabb) -> Cube {
    if provisional.is_empty() {
        let unit = Aabb {
            min: [0.0; 3],
            max: [1.0; 3],
        };
        Cube::around(&unit, 0.0)
    } else {
        Cube::around(provisional, CUBE_MARGIN)
    }
}

/// After the first count found the exact `bounds`: the cube to count again on, if any. Only
/// when the exact bounds leave the first cube with less than half its margin (or the sample
/// held no valid point) is the count repeated, on the cube around the exact bounds, so that
/// typical inputs are read twice (count, scatter), not three times.
pub fn recount_cube(provisional: &Aabb, bounds: &Aabb) -> Option<Cube> {
    if bounds.is_empty() {
        return None;
    }
    if provisional.is_empty() || !within(bounds, &Cube::around(provisional, CUBE_MARGIN / 2.0)) {
        log::info!("the points reach beyond the sampled bounds; counting again on the exact cube");
        return Some(Cube::around(bounds, CUBE_MARGIN));
    }
    None
}

/// Count on [`first_cube`], and again on [`recount_cube`] when it says so.
pub fn count_pass(
    inputs: &Inputs,
    chunks: &[(usize, ChunkSpec)],
    chunk_bytes: u64,
    provisional: &Aabb,
    levels: u32,
    ctx: &Ctx,
) -> Result<Counted> {
    let count = |cube: &Cube| -> Result<Partial> {
        let stage = ctx.progress.stage("count", Some(inputs.total), "points");
        let p = count_chunks(inputs, chunks, chunk_bytes, cube, levels, &stage, ctx)?;
        stage.finish(None);
        Ok(p)
    };
    let mut cube = first_cube(provisional);
    let mut p = count(&cube)?;
    if let Some(c) = recount_cube(provisional, &p.bounds) {
        cube = c;
        p = count(&cube)?;
    }
    if p.bounds.is_empty() {
        p.counts.clear();
    }
    Ok(Counted {
        cube,
        counts: p.counts,
        bounds: p.bounds,
        skipped: p.skipped,
    })
}

/// What counting some of the chunks found: points per grid cell, exact bounds, points skipped.
#[derive(Debug, Clone, PartialEq)]
pub struct Partial {
    /// Points per grid cell, in Morton order.
    pub counts: Vec<u64>,
    /// The exact bounds of the valid points.
    pub bounds: Aabb,
    /// Points skipped as invalid.
    pub skipped: u64,
    /// Per input, the largest colour channel seen (a lower bound of it: the count of other
    /// chunks may have raised it).
    pub max_color: Vec<u16>,
}

/// The first bytes of a count file.
const PARTIAL_MAGIC: &[u8; 8] = b"SFCOUNT1";

impl Partial {
    /// Nothing counted yet, on a grid of `8^levels` cells, for `inputs` inputs.
    pub fn empty(levels: u32, inputs: usize) -> Partial {
        Partial {
            counts: vec![0; 1usize << (3 * levels)],
            bounds: Aabb::EMPTY,
            skipped: 0,
            max_color: vec![0; inputs],
        }
    }

    /// Add what `other` counted (on the same grid, for the same inputs).
    pub fn add(&mut self, other: &Partial) {
        for (a, b) in self.counts.iter_mut().zip(&other.counts) {
            *a += b;
        }
        self.bounds = self.bounds.union(&other.bounds);
        self.skipped += other.skipped;
        for (a, b) in self.max_color.iter_mut().zip(&other.max_color) {
            *a = (*a).max(*b);
        }
    }

    /// As bytes ([`LeWriter`]): the grid's length, bounds, skipped, colours, then each
    /// non-empty grid cell's index and count (sparse: a slice of the inputs touches few
    /// cells).
    pub fn encode(&self) -> Vec<u8> {
        let mut w = LeWriter::new(PARTIAL_MAGIC);
        w.u64(self.counts.len() as u64);
        self.bounds
            .min
            .iter()
            .chain(&self.bounds.max)
            .for_each(|&v| w.f64(v));
        w.u64(self.skipped);
        w.u64(self.max_color.len() as u64);
        self.max_color.iter().for_each(|&m| w.u32(m as u32));
        let nz = self.counts.iter().filter(|c| **c > 0).count();
        w.u64(nz as u64);
        for (i, &c) in self.counts.iter().enumerate().filter(|(_, c)| **c > 0) {
            w.u64(i as u64);
            w.u64(c);
        }
        w.finish()
    }

    /// Read what [`Partial::encode`] wrote to `path` (named in errors), checking it.
    pub fn decode(bytes: &[u8], path: &std::path::Path) -> Result<Partial> {
        let bad = || crate::error::Error::input(path, "damaged count file");
        let mut r = LeReader::open(bytes, PARTIAL_MAGIC).ok_or_else(bad)?;
        let p = (|| {
            let n = usize::try_from(r.u64()?).ok()?;
            let mut b = [0f64; 6];
            for x in &mut b {
                *x = r.f64()?;
            }
            let skipped = r.u64()?;
            let mut max_color = Vec::new();
            for _ in 0..r.u64()? {
                max_color.push(u16::try_from(r.u32()?).ok()?);
            }
            let mut counts = vec![0u64; n];
            for _ in 0..r.u64()? {
                let i = usize::try_from(r.u64()?).ok()?;
                *counts.get_mut(i)? = r.u64()?;
            }
            r.at_end().then_some(Partial {
                counts,
                bounds: Aabb {
                    min: [b[0], b[1], b[2]],
                    max: [b[3], b[4], b[5]],
                },
                skipped,
                max_color,
            })
        })();
        p.ok_or_else(bad)
    }
}

/// Read `chunks` once, counting each point on the grid of `8^levels` cells over `cube`.
pub fn count_chunks(
    inputs: &Inputs,
    chunks: &[(usize, ChunkSpec)],
    chunk_bytes: u64,
    cube: &Cube,
    levels: u32,
    stage: &Stage,
    ctx: &Ctx,
) -> Result<Partial> {
    let grid_cells = 1usize << (3 * levels);
    let counts: Vec<AtomicU64> = (0..grid_cells).map(|_| AtomicU64::new(0)).collect();
    let root_map = GridMap::new(cube, CellKey::ROOT, levels);
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
    Ok(Partial {
        counts: counts.into_iter().map(|c| c.into_inner()).collect(),
        bounds,
        skipped,
        max_color: inputs.max_colors(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_partial_count_reads_back_and_damage_is_caught() {
        let mut p = Partial::empty(2, 2);
        p.counts[3] = 7;
        p.counts[63] = 1;
        p.bounds = Aabb {
            min: [-1.0, 0.5, 2.0],
            max: [3.0, 4.0, 5.0],
        };
        p.skipped = 4;
        p.max_color = vec![255, 65535];
        let path = std::path::Path::new("c0");
        let b = p.encode();
        assert_eq!(Partial::decode(&b, path).unwrap(), p);
        for cut in [0, 3, b.len() - 1] {
            assert!(Partial::decode(&b[..cut], path).is_err(), "cut {cut}");
        }
        let mut flipped = b.clone();
        flipped[20] ^= 1;
        let e = Partial::decode(&flipped, path).unwrap_err().to_string();
        assert!(e.contains("c0") && e.contains("damaged"), "{e}");
        let mut q = Partial::empty(2, 2);
        q.add(&p);
        q.add(&p);
        assert_eq!(q.counts[3], 14);
        assert_eq!(q.skipped, 8);
        assert_eq!(q.bounds, p.bounds);
        assert_eq!(q.max_color, p.max_color);
    }

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
