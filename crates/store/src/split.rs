//! Pass 4, split: a cell still over the point limit after the scatter (all its points in one
//! cell of the counting grid) is counted again on a finer grid of its own, and its file is
//! scattered into its sub-cells; a sub-cell still over the limit is split in turn, down to
//! the octree's finest level.

use std::path::Path;

use rayon::prelude::*;

use crate::cell_file::{CellReader, RecordLayout};
use crate::count::grid_bytes;
use crate::error::{Error, IoContext, Result};
use crate::exec::Ctx;
use crate::octree::{GridMap, Hierarchy, count_levels};
use crate::scatter::{CellOut, Grouped, Scatter, group_batch};
use crate::types::{CellKey, Cube, MAX_LEVEL, PointBatch};
use crate::{CHUNK_BYTES_PER_POINT, Sizes};

/// What the split pass needs to know about the store being built.
pub struct Splitter<'a> {
    /// The root cube.
    pub cube: &'a Cube,
    /// Layout of the records.
    pub layout: RecordLayout,
    /// Cells are split until they hold at most this many points.
    pub max_cell_points: u64,
    /// zstd level of the new cell files.
    pub zstd_level: i32,
    /// Chunk and wave sizes.
    pub sizes: &'a Sizes,
    /// The directory of the cell files.
    pub dir: &'a Path,
    /// Bytes the cell buffers hold before they are flushed ([`Scatter::new`]).
    pub cap: usize,
}

impl Splitter<'_> {
    /// Split every cell of `cells` that `oversized` marks (the leaves of the hierarchy over
    /// the limit) until each holds at most the limit or lies at the finest level. Returns the
    /// cells, the split ones replaced by their sub-cells (appended), and how many stay over
    /// the limit.
    pub fn run(
        &self,
        mut cells: Vec<CellOut>,
        oversized: &[bool],
        ctx: &Ctx,
    ) -> Result<(Vec<CellOut>, usize)> {
        let mut oversized: Vec<usize> = (0..cells.len())
            .filter(|&i| oversized.get(i).copied().unwrap_or(false))
            .collect();
        if oversized.is_empty() {
            return Ok((cells, 0));
        }
        // The sub-cells' buffers, as the scatter's (one split at a time).
        let _permit = ctx
            .budget
            .acquire(2 * self.cap as u64, "the cell buffers")?;
        let mut stuck = 0;
        let stage = ctx
            .progress
            .stage("split", Some(oversized.len() as u64), "cells");
        let mut done: Vec<bool> = vec![false; cells.len()];
        while let Some(i) = oversized.pop() {
            let key = cells[i].key;
            let n = cells[i].count;
            let room = MAX_LEVEL.saturating_sub(key.level());
            let r = count_levels(n, self.max_cell_points, room.min(self.sizes.max_levels));
            if room == 0 {
                log::warn!(
                    "cell {} holds {} points within one finest cell; kept over the limit",
                    key.file_name(),
                    n
                );
                stuck += 1;
                continue;
            }
            let new = self.split_cell(&cells[i], r, ctx)?;
            std::fs::remove_file(&cells[i].file).with_path(&cells[i].file)?;
            done[i] = true;
            for (c, over) in new {
                cells.push(c);
                done.push(false);
                if over {
                    oversized.push(cells.len() - 1);
                }
            }
            stage.inc(1);
        }
        stage.finish(None);
        let mut k = 0;
        cells.retain(|_| {
            k += 1;
            !done[k - 1]
        });
        Ok((cells, stuck))
    }

    /// Count a cell's points on a grid `r` levels finer and scatter them into its sub-cells.
    /// Returns the new cells, each with whether it is still over the limit.
    fn split_cell(&self, cell: &CellOut, r: u32, ctx: &Ctx) -> Result<Vec<(CellOut, bool)>> {
        let grid = 1usize << (3 * r);
        let _grid_permit = ctx
            .budget
            .acquire(grid_bytes(grid as u64), "the counting grid")?;
        let counts = self.count_cell(cell, r, grid)?;
        let h = Hierarchy::build(cell.key, r, &counts, self.max_cell_points);
        drop(counts);
        let keys: Vec<CellKey> = h.leaves.iter().map(|l| l.key).collect();
        let mut sc = Scatter::new(self.dir, &keys, self.layout, self.cap, self.zstd_level)?;
        let mut rd = CellReader::open(&cell.file, self.layout)?;
        let n = self.sizes.chunk_points as usize;
        let mut buf = Vec::new();
        loop {
            let mut batches = Vec::with_capacity(self.sizes.wave);
            for _ in 0..self.sizes.wave {
                let mut b = PointBatch::default();
                if rd.read(n, &mut b, &mut buf)? == 0 {
                    break;
                }
                batches.push(b);
            }
            if batches.is_empty() {
                break;
            }
            let _permit = ctx.budget.acquire(
                batches.len() as u64 * self.sizes.chunk_points * CHUNK_BYTES_PER_POINT,
                "a chunk of points",
            )?;
            let outs: Vec<Result<Grouped>> = ctx.pool.install(|| {
                batches
                    .par_iter()
                    .map(|b| group_batch(b, self.cube, &h, &self.layout))
                    .collect()
            });
            for o in outs {
                sc.push(&ctx.pool, &o?)?;
            }
        }
        let crc = rd.finish_crc();
        if crc != cell.crc32() {
            return Err(Error::Internal(format!(
                "{}: checksum changed while splitting",
                cell.file.display()
            )));
        }
        let cells = sc.finish(&ctx.pool)?.cells;
        Ok(cells
            .into_iter()
            .zip(&h.leaves)
            .map(|(c, l)| (c, l.oversized))
            .collect())
    }

    /// The points of `cell` counted on the grid of `grid` cells `r` levels below it.
    fn count_cell(&self, cell: &CellOut, r: u32, grid: usize) -> Result<Vec<u64>> {
        let mut counts = vec![0u64; grid];
        let n = self.sizes.chunk_points as usize;
        let mut batch = PointBatch::default();
        let mut buf = Vec::new();
        let mut rd = CellReader::open(&cell.file, self.layout)?;
        let map = GridMap::new(self.cube, cell.key, r);
        loop {
            batch.clear();
            if rd.read(n, &mut batch, &mut buf)? == 0 {
                break;
            }
            for p in &batch.pos {
                counts[map.index(*p) as usize] += 1;
            }
        }
        Ok(counts)
    }
}
