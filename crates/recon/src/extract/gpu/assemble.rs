//! Host-side assembly of a sub-block's vertex records and triangles into the tile's mesh:
//! seam edges matched to the vertices earlier sub-blocks made, keys and positions computed
//! with the CPU kernel's `f64` formula ([`cpu::edge_vertex`]), triangles renumbered from
//! record indices to vertex indices.

use std::collections::HashMap;
use std::collections::hash_map::Entry;
use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use super::GpuResult;
use super::plan::SubBlock;
use crate::extract::cpu;
use crate::types::{EdgeKey, GridGeom, TileMesh};

/// Bit 31 of a vertex record: the edge lies on a face shared with another sub-block.
const SEAM: u32 = 1 << 31;
/// A record replaced by this matched a vertex of an earlier sub-block (no valid record is
/// this large).
const MATCHED: u32 = u32::MAX;
/// Items a rayon task takes at least, so that small sub-blocks are not split into tiny tasks.
const MIN_TASK: usize = 1 << 12;
/// Records a task renumbers at once, each finding its first matched record by bisection.
const RENUMBER_RUN: usize = 1 << 16;

/// What [`assemble`] needs of a sub-block besides the records.
pub(super) struct Assembly<'a> {
    /// The tile's node values when the host has them.
    pub(super) values: &'a [f32],
    /// Else the two node values of each record's edge, from the device.
    pub(super) ends: Option<&'a [[u32; 2]]>,
    /// The tile's nodes per axis.
    pub(super) dims: [usize; 3],
    /// The tile's lowest node in the global grid.
    pub(super) origin_node: [u64; 3],
    pub(super) iso: f32,
    pub(super) block: SubBlock,
}

/// Reusable state of the assembly of one tile.
#[derive(Default)]
pub(super) struct Seams {
    /// Vertex of each seam edge made so far in the tile, by tile-local edge id.
    seam: HashMap<u64, u32>,
    /// Vertex index of each record of the sub-block, where seams matched earlier vertices.
    map: Vec<u32>,
}

impl Seams {
    /// Forget the seam edges of the last tile.
    pub(super) fn clear(&mut self) {
        self.seam.clear();
    }
}

/// Block-local edge ids of a sub-block, decoded to tile nodes.
#[derive(Clone, Copy)]
struct Edges {
    block: SubBlock,
    tile: [usize; 3],
}

impl Edges {
    /// Block-local edge id -> (tile node, axis), or `None` if it is not an edge of the block.
    fn decode(&self, r: u32) -> Option<([usize; 3], usize)> {
        let bd = self.block.dims.map(|d| d as u32);
        let n = r / 3;
        let axis = (r % 3) as usize;
        let local = [n % bd[0], (n / bd[0]) % bd[1], n / bd[0] / bd[1]];
        (local[2] < bd[2] && local[axis] + 1 < bd[axis]).then(|| {
            (
                [0, 1, 2].map(|d| self.block.at[d] + local[d] as usize),
                axis,
            )
        })
    }

    /// The index of tile node `p`, x fastest.
    fn tile_index(&self, p: [usize; 3]) -> usize {
        (p[2] * self.tile[1] + p[1]) * self.tile[0] + p[0]
    }
}

/// Add the vertices of a sub-block (its vertex `records`) to `out`, matching seam edges to
/// the vertices earlier sub-blocks of the tile made, and turn its triangles
/// (`out.triangles[tri_start..]`, record indices) into vertex indices.
pub(super) fn assemble(
    at: Assembly<'_>,
    records: &mut [u32],
    seams: &mut Seams,
    geom: &GridGeom,
    out: &mut TileMesh,
    tri_start: usize,
) -> GpuResult<()> {
    let n_records = records.len();
    let base = out.keys.len();
    if base + n_records >= u32::MAX as usize {
        return Err("more than 2^32 vertices in a tile".to_string());
    }
    let edges = Edges {
        block: at.block,
        tile: at.dims,
    };
    let matched = if at.block.seam_mask(at.dims) != 0 {
        match_seams(records, &mut seams.seam, edges, base)?
    } else {
        Vec::new()
    };
    add_vertices(&at, records, !matched.is_empty(), edges, geom, out)?;
    let tris = &mut out.triangles[tri_start..];
    renumber(tris, &matched, &mut seams.map, base, n_records)
}

/// Seam records whose edge an earlier sub-block already gave a vertex, as (record, vertex),
/// in record order, each replaced by [`MATCHED`] in `records`; the other seam edges are
/// added to `seam` with their new vertex, `base + record − (matched records before it)`.
fn match_seams(
    records: &mut [u32],
    seam: &mut HashMap<u64, u32>,
    edges: Edges,
    base: usize,
) -> GpuResult<Vec<(usize, u32)>> {
    let mut matched: Vec<(usize, u32)> = Vec::new();
    let on_seam: Vec<usize> = records
        .par_iter()
        .enumerate()
        .filter(|(_, r)| *r & SEAM != 0)
        .map(|(j, _)| j)
        .collect();
    for j in on_seam {
        let (p, axis) = edges
            .decode(records[j] & !SEAM)
            .ok_or("a vertex record is not an edge of the block")?;
        let k = (edges.tile_index(p) * 3 + axis) as u64;
        match seam.entry(k) {
            Entry::Occupied(o) => matched.push((j, *o.get())),
            Entry::Vacant(v) => {
                v.insert((base + j - matched.len()) as u32);
            }
        }
    }
    for &(j, _) in &matched {
        records[j] = MATCHED;
    }
    Ok(matched)
}

/// Append the keys and positions of the records' vertices (those not [`MATCHED`], when
/// `any_matched`) to `out`, as the CPU kernel computes them.
fn add_vertices(
    at: &Assembly<'_>,
    fresh: &[u32],
    any_matched: bool,
    edges: Edges,
    geom: &GridGeom,
    out: &mut TileMesh,
) -> GpuResult<()> {
    let (values, ends, dims, origin_node) = (at.values, at.ends, at.dims, at.origin_node);
    let stride = [1, dims[0], dims[0] * dims[1]];
    let iso64 = at.iso as f64;
    let bad = AtomicBool::new(false);
    let mut both = (
        std::mem::take(&mut out.keys),
        std::mem::take(&mut out.positions),
    );
    let vertex = |j: usize| {
        let Some((p, axis)) = edges.decode(fresh[j] & !SEAM) else {
            bad.store(true, Ordering::Relaxed);
            return (EdgeKey(0), [0.0; 3]);
        };
        let (va, vb) = match ends {
            Some(e) => (f32::from_bits(e[j][0]), f32::from_bits(e[j][1])),
            None => {
                let a = edges.tile_index(p);
                (values[a], values[a + stride[axis]])
            }
        };
        let g = [0, 1, 2].map(|d| origin_node[d] + p[d] as u64);
        (
            geom.edge_key(g, axis as u8),
            cpu::edge_vertex(geom, g, axis, va, vb, iso64),
        )
    };
    let all = (0..fresh.len()).into_par_iter().with_min_len(MIN_TASK);
    if any_matched {
        both.par_extend(all.filter(|&j| fresh[j] != MATCHED).map(vertex));
    } else {
        both.par_extend(all.map(vertex));
    }
    (out.keys, out.positions) = both;
    if bad.load(Ordering::Relaxed) {
        return Err("a vertex record is not an edge of the block".to_string());
    }
    Ok(())
}

/// Triangles `tris` of `n_records` records: record indices to vertex indices, the records of
/// `matched` to the earlier vertices, the others to `base + record − (matched before it)`
/// (`map` is scratch).
fn renumber(
    tris: &mut [[u32; 3]],
    matched: &[(usize, u32)],
    map: &mut Vec<u32>,
    base: usize,
    n_records: usize,
) -> GpuResult<()> {
    let n = n_records as u32;
    let ok = if matched.is_empty() {
        let off = base as u32;
        tris.par_iter_mut().with_min_len(MIN_TASK).all(|t| {
            let ok = t.iter().all(|&v| v < n);
            *t = t.map(|v| v.wrapping_add(off));
            ok
        })
    } else {
        map.clear();
        map.par_extend(
            (0..n_records.div_ceil(RENUMBER_RUN))
                .into_par_iter()
                .flat_map_iter(|c| {
                    let j0 = c * RENUMBER_RUN;
                    let mut before = matched.partition_point(|m| m.0 < j0);
                    let end = n_records.min(j0 + RENUMBER_RUN);
                    (j0..end).map(move |j| match matched.get(before) {
                        Some(&(m, v)) if m == j => {
                            before += 1;
                            v
                        }
                        _ => (base + j - before) as u32,
                    })
                }),
        );
        let map = &*map;
        tris.par_iter_mut().with_min_len(MIN_TASK).all(|t| {
            let ok = t.iter().all(|&v| v < n);
            *t = t.map(|v| map.get(v as usize).copied().unwrap_or(0));
            ok
        })
    };
    if !ok {
        return Err(format!("a triangle index exceeds the {n} vertex records"));
    }
    Ok(())
}
