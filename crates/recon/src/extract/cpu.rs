//! Marching cubes on the CPU, one tile (block of nodes) at a time.
//!
//! Conventions (inside is `< iso`, winding, seams, order) are those of the
//! [module docs](super). The kernel makes two passes per slab of cells (the cells between node
//! layers `z` and `z + 1`): it classifies every node of the new layer once (`v < iso`), then
//! builds each cell's case from the 8 bits and skips inactive cells (case 0 or 255) at the cost
//! of one compare. Only active cells do work (Timokhin & Mikhaylyuk 2020).
//!
//! A vertex is created once per crossing grid edge: a slot array per edge direction holds the
//! vertex id of each edge of the current slab (x- and y-edges of the slab's bottom and top
//! layers, z-edges between them), so that the cells sharing an edge find its vertex by index,
//! without hashing. When the scan moves up one slab, the top layer's slots become the bottom's
//! and the slots that were set in the layer below are cleared (only those, from a list).
//! Buffers live in a [`McWorkspace`] and are reused from tile to tile.

use super::tables::{self, CORNER_OFFSETS, EDGE_AXIS, EDGE_CORNERS};
use crate::error::{Error, Result};
use crate::types::{GridGeom, TileMesh};

/// What one extraction did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct McStats {
    /// Cells of the block (with all 8 corners in it).
    pub cells: u64,
    /// Cells whose case is neither 0 nor 255.
    pub active_cells: u64,
}

/// Reusable scratch of the marching-cubes kernel; see the [module docs](self). Keep one per
/// worker and pass it every tile: its buffers grow to the largest tile and are reused.
#[derive(Debug, Default)]
pub struct McWorkspace {
    /// `v < iso` per node of two node layers (`z & 1` selects the layer).
    inside: Vec<u8>,
    /// Cases of one row of cells.
    row: Vec<u8>,
    /// Vertex ids (or [`NONE`]) of the slab's edges, [`SLOT_ARRAYS`] arrays of `nx·ny`:
    /// x-edges of layer parity 0 and 1, y-edges of layer parity 0 and 1, z-edges of the slab.
    slots: Vec<u32>,
    /// Slots set, per group: layer parity 0, layer parity 1 (x and y edges), z-edges.
    touched: [Vec<u32>; 3],
}

/// An empty slot.
const NONE: u32 = u32::MAX;

/// Slot arrays of a slab, each one `u32` per node of a layer: x- and y-edges of both layer
/// parities, and the z-edges between the layers.
const SLOT_ARRAYS: usize = 5;

/// Scratch bytes per node of a layer: two `inside` flags (two layers), a `u32` in each slot
/// array, and at most as many `u32`s in the touched lists.
const LAYER_NODE_BYTES: usize = 2 + 2 * SLOT_ARRAYS * std::mem::size_of::<u32>();

/// The block being extracted, as [`McWorkspace::extract`] was given it.
struct Block<'a> {
    values: &'a [f32],
    /// Nodes per axis.
    dims: [usize; 3],
    /// Global node of the block's node 0.
    origin_node: [u64; 3],
    iso: f32,
    geom: &'a GridGeom,
}

/// Where each of a cell's 12 edges finds its slot, lower node and touched group, relative to
/// the cell's base index `y·nx + x` in slab `k`.
struct SlabEdges {
    slot_off: [usize; 12],
    node_off: [usize; 12],
    group: [usize; 12],
}

impl SlabEdges {
    /// The offsets of slab `k` of a block with layers of `l` nodes and rows of `nx`.
    fn new(k: usize, nx: usize, l: usize) -> SlabEdges {
        let mut s = SlabEdges {
            slot_off: [0; 12],
            node_off: [0; 12],
            group: [0; 12],
        };
        for e in 0..12 {
            let o = CORNER_OFFSETS[EDGE_CORNERS[e][0] as usize].map(|v| v as usize);
            let par = (k + o[2]) & 1;
            let (seg, g) = match EDGE_AXIS[e] {
                0 => (par, par),
                1 => (2 + par, par),
                _ => (4, 2),
            };
            s.slot_off[e] = seg * l + o[1] * nx + o[0];
            s.node_off[e] = o[2] * l + o[1] * nx + o[0];
            s.group[e] = g;
        }
        s
    }
}

impl McWorkspace {
    /// A workspace with no buffer yet.
    pub fn new() -> McWorkspace {
        McWorkspace::default()
    }

    /// An upper bound of the bytes this workspace grows to for blocks of `dims` nodes (the
    /// output [`TileMesh`] not included).
    pub fn scratch_bytes(dims: [usize; 3]) -> usize {
        let l = dims[0].saturating_mul(dims[1]);
        // Plus the row of cases.
        l.saturating_mul(LAYER_NODE_BYTES).saturating_add(dims[0])
    }

    /// Extract the iso-surface of a block of nodes into `out` (cleared first).
    ///
    /// `values` holds the `dims[0]·dims[1]·dims[2]` node values with x fastest:
    /// `values[(z·dims[1] + y)·dims[0] + x]`; the block's first node is global node
    /// `origin_node`. Only cells whose 8 corners lie in the block are processed. Each crossing
    /// edge gets exactly one vertex, at `t = (iso − v_a)/(v_b − v_a)` from its lower node `a`
    /// (clamped to `[0, 1]`; 0.5 where it is NaN, which only infinite values can cause).
    /// Degenerate triangles (a vertex on a node, where a value equals `iso`) are kept, so the
    /// topology stays exact.
    ///
    /// Errors: [`Error::Internal`] when `values` does not hold `dims` nodes or the block leaves
    /// the grid, [`Error::Usage`] when the block has `2³²` edges or more.
    pub fn extract(
        &mut self,
        values: &[f32],
        dims: [usize; 3],
        origin_node: [u64; 3],
        iso: f32,
        geom: &GridGeom,
        out: &mut TileMesh,
    ) -> Result<McStats> {
        out.clear();
        check_block(values.len(), dims, origin_node, geom)?;
        let [nx, ny, nz] = dims;
        if nx < 2 || ny < 2 || nz < 2 {
            return Ok(McStats::default());
        }
        if values.len().saturating_mul(3) >= NONE as usize {
            return Err(Error::Usage(format!(
                "tile of {nx}×{ny}×{nz} nodes is too large: it must have fewer than 2^32 edges"
            )));
        }
        let l = nx * ny;
        self.reset(nx, l);
        classify(&values[..l], iso, &mut self.inside[..l]);
        let block = Block {
            values,
            dims,
            origin_node,
            iso,
            geom,
        };
        let mut stats = McStats {
            cells: ((nx - 1) * (ny - 1) * (nz - 1)) as u64,
            active_cells: 0,
        };
        for k in 0..nz - 1 {
            stats.active_cells += self.slab(&block, k, out);
        }
        Ok(stats)
    }

    /// Size the buffers for layers of `l` nodes in rows of `nx`, all slots empty.
    fn reset(&mut self, nx: usize, l: usize) {
        self.inside.clear();
        self.inside.resize(2 * l, 0);
        self.row.clear();
        self.row.resize(nx - 1, 0);
        self.slots.clear();
        self.slots.resize(SLOT_ARRAYS * l, NONE);
        for t in self.touched.iter_mut() {
            t.clear();
        }
    }

    /// The cells between node layers `k` and `k + 1` (layer `k` classified already): classify
    /// layer `k + 1`, recycle the slots, and emit every active cell into `out`. Returns the
    /// number of active cells.
    fn slab(&mut self, b: &Block, k: usize, out: &mut TileMesh) -> u64 {
        let [nx, ny, _] = b.dims;
        let l = nx * ny;
        let McWorkspace {
            inside,
            row,
            slots,
            touched,
        } = self;
        let p0 = k & 1;
        let p1 = p0 ^ 1;
        classify(
            &b.values[(k + 1) * l..(k + 2) * l],
            b.iso,
            &mut inside[p1 * l..(p1 + 1) * l],
        );
        // Layer k + 1 takes the slots layer k - 1 had; z-edges are new.
        for g in [p1, 2] {
            for &s in &touched[g] {
                slots[s as usize] = NONE;
            }
            touched[g].clear();
        }
        let edges = SlabEdges::new(k, nx, l);
        let (bot, top) = (&inside[p0 * l..(p0 + 1) * l], &inside[p1 * l..(p1 + 1) * l]);
        let mut active = 0;
        for y in 0..ny - 1 {
            let r = y * nx;
            row_cases(
                [
                    &bot[r..r + nx],
                    &bot[r + nx..r + 2 * nx],
                    &top[r..r + nx],
                    &top[r + nx..r + 2 * nx],
                ],
                row,
            );
            for (x, &case) in row.iter().enumerate() {
                if case.wrapping_add(1) <= 1 {
                    continue;
                }
                active += 1;
                let mut ids = [0u32; 12];
                for &e in tables::case_edges(case) {
                    let e = e as usize;
                    let s = r + x + edges.slot_off[e];
                    if slots[s] == NONE {
                        slots[s] = out.keys.len() as u32;
                        touched[edges.group[e]].push(s as u32);
                        push_vertex(b, &edges, [x, y, k], e, out);
                    }
                    ids[e] = slots[s];
                }
                for t in tables::case_triangles(case) {
                    out.triangles.push([
                        ids[t[0] as usize],
                        ids[t[1] as usize],
                        ids[t[2] as usize],
                    ]);
                }
            }
        }
        active
    }
}

/// Check that a block of `dims` nodes holds `len` values and, placed at global node
/// `origin_node`, lies in the grid `geom`.
fn check_block(len: usize, dims: [usize; 3], origin_node: [u64; 3], geom: &GridGeom) -> Result<()> {
    let [nx, ny, nz] = dims;
    let total = nx.checked_mul(ny).and_then(|v| v.checked_mul(nz));
    if total != Some(len) {
        return Err(Error::Internal(format!(
            "marching cubes: {len} values for a block of {nx}×{ny}×{nz} nodes"
        )));
    }
    if geom.n > GridGeom::MAX_N {
        return Err(Error::Internal(format!(
            "marching cubes: grid of {} cells per axis, at most {} supported",
            geom.n,
            GridGeom::MAX_N
        )));
    }
    for d in 0..3 {
        let last = origin_node[d].checked_add(dims[d] as u64);
        if dims[d] > 0 && last.is_none_or(|l| l - 1 > geom.n) {
            return Err(Error::Internal(format!(
                "marching cubes: block of {dims:?} nodes at node {origin_node:?} leaves the \
                 grid of {} cells per axis",
                geom.n
            )));
        }
    }
    Ok(())
}

/// Append the vertex of edge `e` of cell `cell` (block coordinates; `cell[2]` is the slab) to
/// `out`: its key and its position.
#[inline]
fn push_vertex(b: &Block, edges: &SlabEdges, cell: [usize; 3], e: usize, out: &mut TileMesh) {
    let [x, y, k] = cell;
    let [nx, ny, _] = b.dims;
    let l = nx * ny;
    let axis = EDGE_AXIS[e] as usize;
    let a = k * l + y * nx + x + edges.node_off[e];
    let stride = [1, nx, l];
    let o = CORNER_OFFSETS[EDGE_CORNERS[e][0] as usize];
    let g = [
        b.origin_node[0] + (x + o[0] as usize) as u64,
        b.origin_node[1] + (y + o[1] as usize) as u64,
        b.origin_node[2] + (k + o[2] as usize) as u64,
    ];
    let p = edge_vertex(
        b.geom,
        g,
        axis,
        b.values[a],
        b.values[a + stride[axis]],
        b.iso as f64,
    );
    out.keys.push(b.geom.edge_key(g, axis as u8));
    out.positions.push(p);
}

/// World position of the vertex on the grid edge from global node `node` along `axis`, whose
/// lower and upper nodes hold `va` and `vb`: `t = (iso − v_a)/(v_b − v_a)` in `f64`, clamped
/// to `[0, 1]` (0.5 where it is NaN). The one formula of every kernel (CPU and GPU), so a seam
/// vertex is bit for bit the same whichever tile or kernel computes it.
#[inline]
pub(crate) fn edge_vertex(
    geom: &GridGeom,
    node: [u64; 3],
    axis: usize,
    va: f32,
    vb: f32,
    iso: f64,
) -> [f64; 3] {
    let (va, vb) = (va as f64, vb as f64);
    let t = (iso - va) / (vb - va);
    let t = if t.is_nan() { 0.5 } else { t.clamp(0.0, 1.0) };
    let mut p = [0.0; 3];
    for d in 0..3 {
        let c = node[d] as f64 + if d == axis { t } else { 0.0 };
        p[d] = geom.origin[d] + geom.h * c;
    }
    p
}

/// `out[i] = (values[i] < iso)`; NaN is outside.
#[inline]
fn classify(values: &[f32], iso: f32, out: &mut [u8]) {
    for (o, &v) in out.iter_mut().zip(values) {
        *o = (v < iso) as u8;
    }
}

/// Cases of one row of cells from the inside bits of its 4 node rows: `[y, y + 1]` of the
/// bottom layer, then of the top layer. `out` has one entry per cell (`nx − 1`).
#[inline]
fn row_cases(rows: [&[u8]; 4], out: &mut [u8]) {
    let m = out.len();
    let [a, b, c, d] = rows.map(|r| &r[..m + 1]);
    for x in 0..m {
        out[x] = a[x]
            | (a[x + 1] << 1)
            | (b[x] << 2)
            | (b[x + 1] << 3)
            | (c[x] << 4)
            | (c[x + 1] << 5)
            | (d[x] << 6)
            | (d[x + 1] << 7);
    }
}

/// Extract the iso-surface of node values `values` (x fastest:
/// `values[(z·dims[1] + y)·dims[0] + x]`) of a block of `dims[0]×dims[1]×dims[2]` nodes whose
/// first node is global node `origin_node`, into `out` (cleared first), with a fresh
/// workspace: a convenience for one-off blocks. A tile loop keeps one [`McWorkspace`] per
/// worker and calls [`McWorkspace::extract`], which this calls and whose errors it returns.
pub fn marching_cubes(
    values: &[f32],
    dims: [usize; 3],
    origin_node: [u64; 3],
    iso: f32,
    geom: &GridGeom,
    out: &mut TileMesh,
) -> Result<McStats> {
    McWorkspace::new().extract(values, dims, origin_node, iso, geom, out)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::types::EdgeKey;
    use rand::{Rng, SeedableRng};
    use std::collections::{BTreeMap, HashMap};

    /// Check that `tris` is closed and consistently oriented: every directed edge appears
    /// once and its reverse once. Returns the number of undirected edges.
    pub(crate) fn check_closed_oriented<T: Copy + Ord + std::fmt::Debug>(
        tris: &[[T; 3]],
    ) -> std::result::Result<usize, String> {
        let mut directed: BTreeMap<(T, T), u32> = BTreeMap::new();
        for t in tris {
            if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
                return Err(format!("triangle {t:?} repeats a vertex"));
            }
            for i in 0..3 {
                *directed.entry((t[i], t[(i + 1) % 3])).or_default() += 1;
            }
        }
        for (&(a, b), &n) in &directed {
            if n != 1 {
                return Err(format!("directed edge {a:?}->{b:?} used {n} times"));
            }
            if directed.get(&(b, a)) != Some(&1) {
                return Err(format!("edge {a:?}->{b:?} has no opposite"));
            }
        }
        Ok(directed.len() / 2)
    }

    /// The triangles as key triples, each rotated to start at its smallest key, sorted.
    pub(crate) fn key_triangles(m: &TileMesh) -> Vec<[u64; 3]> {
        let mut v: Vec<[u64; 3]> = m
            .triangles
            .iter()
            .map(|t| canonical(t.map(|i| m.keys[i as usize].0)))
            .collect();
        v.sort_unstable();
        v
    }

    pub(crate) fn canonical(t: [u64; 3]) -> [u64; 3] {
        let r = (0..3).min_by_key(|&i| t[i]).unwrap_or(0);
        [t[r], t[(r + 1) % 3], t[(r + 2) % 3]]
    }

    fn idx(dims: [usize; 3], x: usize, y: usize, z: usize) -> usize {
        (z * dims[1] + y) * dims[0] + x
    }

    /// Surround a block with one layer of +1 (outside) so the surface cannot reach its border.
    fn pad(values: &[f32], dims: [usize; 3]) -> (Vec<f32>, [usize; 3]) {
        let pd = dims.map(|d| d + 2);
        let mut out = vec![1.0f32; pd[0] * pd[1] * pd[2]];
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    out[idx(pd, x + 1, y + 1, z + 1)] = values[idx(dims, x, y, z)];
                }
            }
        }
        (out, pd)
    }

    fn random_field(seed: u64, dims: [usize; 3]) -> Vec<f32> {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        (0..dims[0] * dims[1] * dims[2])
            .map(|_| rng.random_range(-1.0f32..1.0))
            .collect()
    }

    fn extract(values: &[f32], dims: [usize; 3], origin: [u64; 3], g: &GridGeom) -> TileMesh {
        let mut m = TileMesh::default();
        McWorkspace::new()
            .extract(values, dims, origin, 0.0, g, &mut m)
            .unwrap();
        m
    }

    /// Number of grid edges of the block whose nodes differ in class: the oracle of the vertex
    /// count, and a check that every vertex sits on its edge at the interpolated point.
    fn check_vertices(
        m: &TileMesh,
        values: &[f32],
        dims: [usize; 3],
        origin: [u64; 3],
        g: &GridGeom,
        iso: f32,
    ) {
        let mut crossing = 0;
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    let va = values[idx(dims, x, y, z)];
                    for (nx, ny, nz) in [(x + 1, y, z), (x, y + 1, z), (x, y, z + 1)] {
                        if nx < dims[0] && ny < dims[1] && nz < dims[2] {
                            let vb = values[idx(dims, nx, ny, nz)];
                            crossing += ((va < iso) != (vb < iso)) as usize;
                        }
                    }
                }
            }
        }
        assert_eq!(m.keys.len(), crossing);
        let mut seen = std::collections::HashSet::new();
        for (k, p) in m.keys.iter().zip(&m.positions) {
            assert!(seen.insert(*k), "key {k:?} twice");
            let (node, axis) = g.decode_edge(*k);
            let l = [0, 1, 2].map(|d| (node[d] - origin[d]) as usize);
            let va = values[idx(dims, l[0], l[1], l[2])] as f64;
            let mut u = l;
            u[axis as usize] += 1;
            let vb = values[idx(dims, u[0], u[1], u[2])] as f64;
            let t = (iso as f64 - va) / (vb - va);
            let want = [0, 1, 2].map(|d| {
                g.origin[d] + g.h * (node[d] as f64 + if d == axis as usize { t } else { 0.0 })
            });
            assert_eq!(*p, want);
        }
    }

    /// A naive marching cubes: every cell on its own, vertices named by key: the oracle of the
    /// slot bookkeeping.
    fn naive(values: &[f32], dims: [usize; 3], g: &GridGeom) -> Vec<[u64; 3]> {
        let mut tris = Vec::new();
        for z in 0..dims[2] - 1 {
            for y in 0..dims[1] - 1 {
                for x in 0..dims[0] - 1 {
                    let mut case = 0u8;
                    for (c, o) in CORNER_OFFSETS.iter().enumerate() {
                        let v = values[idx(
                            dims,
                            x + o[0] as usize,
                            y + o[1] as usize,
                            z + o[2] as usize,
                        )];
                        if v < 0.0 {
                            case |= 1 << c;
                        }
                    }
                    for t in tables::case_triangles(case) {
                        tris.push(t.map(|e| {
                            let o = CORNER_OFFSETS[EDGE_CORNERS[e as usize][0] as usize];
                            let node = [
                                x as u64 + o[0] as u64,
                                y as u64 + o[1] as u64,
                                z as u64 + o[2] as u64,
                            ];
                            g.edge_key(node, EDGE_AXIS[e as usize]).0
                        }));
                    }
                }
            }
        }
        tris
    }

    #[test]
    fn matches_the_naive_oracle_in_order() {
        for seed in 0..20 {
            let dims = [4, 5, 6];
            let g = GridGeom::new([0.0; 3], 1.0, 8).unwrap();
            let v = random_field(seed, dims);
            let m = extract(&v, dims, [0; 3], &g);
            let got: Vec<[u64; 3]> = m
                .triangles
                .iter()
                .map(|t| t.map(|i| m.keys[i as usize].0))
                .collect();
            assert_eq!(got, naive(&v, dims, &g), "seed {seed}");
            check_vertices(&m, &v, dims, [0; 3], &g, 0.0);
            // Vertices in order of first use.
            let mut next = 0;
            for t in &m.triangles {
                for &i in t {
                    assert!(i <= next);
                    if i == next {
                        next += 1;
                    }
                }
            }
        }
    }

    #[test]
    fn sphere_is_closed_accurate_and_outward() {
        let dims = [33; 3];
        let h = 0.5;
        let g = GridGeom::new([-3.0, 1.0, 2.5], h, 40).unwrap();
        let origin_node = [2, 3, 4];
        let c = g.node_position([18, 19, 20]);
        let r = 6.1;
        let mut v = vec![0.0f32; 33 * 33 * 33];
        for z in 0..33 {
            for y in 0..33 {
                for x in 0..33 {
                    let p = g.node_position([x as u64 + 2, y as u64 + 3, z as u64 + 4]);
                    let d = ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2))
                        .sqrt();
                    v[idx(dims, x, y, z)] = (d - r) as f32;
                }
            }
        }
        let m = extract(&v, dims, origin_node, &g);
        assert!(m.triangles.len() > 1000);
        let edges = check_closed_oriented(&m.triangles).unwrap();
        // A sphere: Euler characteristic 2.
        assert_eq!(
            m.keys.len() as i64 - edges as i64 + m.triangles.len() as i64,
            2
        );
        let mut max_err: f64 = 0.0;
        for p in &m.positions {
            let d = ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt();
            max_err = max_err.max((d - r).abs());
        }
        // Linear interpolation of a distance along a chord: error below h²/(2r).
        assert!(max_err < h * h / (2.0 * r), "max |r - R| = {max_err}");
        let mut volume = 0.0;
        for t in &m.triangles {
            let [a, b, q] = t.map(|i| m.positions[i as usize]);
            let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let w = [q[0] - a[0], q[1] - a[1], q[2] - a[2]];
            let nrm = [
                u[1] * w[2] - u[2] * w[1],
                u[2] * w[0] - u[0] * w[2],
                u[0] * w[1] - u[1] * w[0],
            ];
            let ctr = [0, 1, 2].map(|d| (a[d] + b[d] + q[d]) / 3.0 - c[d]);
            let dot = nrm[0] * ctr[0] + nrm[1] * ctr[1] + nrm[2] * ctr[2];
            assert!(dot > 0.0, "inward or degenerate triangle {t:?}");
            let a = [0, 1, 2].map(|d| a[d] - c[d]);
            volume += (a[0] * nrm[0] + a[1] * nrm[1] + a[2] * nrm[2]) / 6.0;
        }
        let exact = 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
        assert!(
            (volume / exact - 1.0).abs() < 0.02,
            "volume {volume} vs {exact}"
        );
        check_vertices(&m, &v, dims, origin_node, &g, 0.0);
    }

    #[test]
    fn random_fields_are_closed_when_padded() {
        for seed in 0..4 {
            let (v, dims) = pad(&random_field(100 + seed, [17; 3]), [17; 3]);
            let g = GridGeom::new([0.0; 3], 1.0, 18).unwrap();
            let m = extract(&v, dims, [0; 3], &g);
            check_closed_oriented(&m.triangles).unwrap();
            check_vertices(&m, &v, dims, [0; 3], &g, 0.0);
        }
    }

    #[test]
    fn checkerboard_of_ambiguous_faces_is_closed() {
        for parity in 0..2 {
            let d = [9, 8, 7];
            let mut v = vec![0.0f32; d[0] * d[1] * d[2]];
            for z in 0..d[2] {
                for y in 0..d[1] {
                    for x in 0..d[0] {
                        v[idx(d, x, y, z)] = if (x + y + z) % 2 == parity { -1.0 } else { 1.0 };
                    }
                }
            }
            let (v, dims) = pad(&v, d);
            let g = GridGeom::new([0.0; 3], 1.0, 20).unwrap();
            let m = extract(&v, dims, [1, 2, 3], &g);
            check_closed_oriented(&m.triangles).unwrap();
            // Inside corners are kept apart: one small octahedron-like blob per inside node.
            assert!(!m.triangles.is_empty());
        }
    }

    #[test]
    fn values_equal_to_iso_are_outside_and_degenerate_triangles_stay() {
        // One inside node surrounded by nodes exactly at iso: the vertices sit on the nodes.
        let dims = [3; 3];
        let mut v = vec![0.0f32; 27];
        v[13] = -1.0;
        let g = GridGeom::new([0.0; 3], 1.0, 2).unwrap();
        let m = extract(&v, dims, [0; 3], &g);
        // 6 crossing edges, each vertex on the far node (t = 1).
        assert_eq!(m.keys.len(), 6);
        for p in &m.positions {
            let off: f64 = p.iter().map(|c| (c - 1.0).abs()).sum();
            assert_eq!(off, 1.0);
        }
        check_closed_oriented(&m.triangles).unwrap();
        // All-iso block: nothing is inside, no surface.
        let m = extract(&[0.0; 27], dims, [0; 3], &g);
        assert!(m.triangles.is_empty());
    }

    #[test]
    fn split_tiles_weld_to_the_whole_block() {
        for axis in 0..3 {
            let dims = [13, 11, 12];
            let v = random_field(300 + axis as u64, dims);
            let g = GridGeom::new([0.5, -2.0, 7.0], 0.25, 30).unwrap();
            let origin = [1, 2, 3];
            let whole = extract(&v, dims, origin, &g);
            let cut = 6;
            let mut tris = Vec::new();
            let mut pos: HashMap<EdgeKey, [f64; 3]> = HashMap::new();
            for (lo, hi) in [(0, cut), (cut, dims[axis] - 1)] {
                let mut d = dims;
                d[axis] = hi - lo + 1;
                let mut sub = Vec::with_capacity(d[0] * d[1] * d[2]);
                for z in 0..d[2] {
                    for y in 0..d[1] {
                        for x in 0..d[0] {
                            let mut q = [x, y, z];
                            q[axis] += lo;
                            sub.push(v[idx(dims, q[0], q[1], q[2])]);
                        }
                    }
                }
                let mut o = origin;
                o[axis] += lo as u64;
                let m = extract(&sub, d, o, &g);
                for (k, p) in m.keys.iter().zip(&m.positions) {
                    if let Some(old) = pos.insert(*k, *p) {
                        assert_eq!(old, *p, "seam vertex differs");
                    }
                }
                tris.extend(key_triangles(&m));
            }
            tris.sort_unstable();
            assert_eq!(tris, key_triangles(&whole), "axis {axis}");
            assert_eq!(pos.len(), whole.keys.len());
            for (k, p) in whole.keys.iter().zip(&whole.positions) {
                assert_eq!(pos[k], *p);
            }
        }
    }

    #[test]
    fn bad_shapes_are_errors_not_panics() {
        let g = GridGeom::new([0.0; 3], 1.0, 4).unwrap();
        let mut m = TileMesh::default();
        let mut ws = McWorkspace::new();
        let e = ws.extract(&[0.0; 7], [2, 2, 2], [0; 3], 0.0, &g, &mut m);
        assert!(matches!(e, Err(Error::Internal(_))));
        let e = ws.extract(&[0.0; 8], [2, 2, 2], [4, 0, 0], 0.0, &g, &mut m);
        assert!(matches!(e, Err(Error::Internal(_))));
        let e = ws.extract(&[0.0; 8], [2, 2, 2], [u64::MAX, 0, 0], 0.0, &g, &mut m);
        assert!(matches!(e, Err(Error::Internal(_))));
        // A flat block has no cell.
        let s = ws
            .extract(&[-1.0; 4], [2, 2, 1], [0; 3], 0.0, &g, &mut m)
            .unwrap();
        assert_eq!(s.cells, 0);
        // The workspace is reusable after errors and between sizes.
        let s = ws
            .extract(
                &[-1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0],
                [2, 2, 2],
                [3, 3, 3],
                0.0,
                &g,
                &mut m,
            )
            .unwrap();
        assert_eq!((s.cells, s.active_cells), (1, 1));
        assert_eq!(m.triangles.len(), 1);
        assert!(McWorkspace::scratch_bytes([2, 2, 2]) > 0);
    }

    #[test]
    fn non_finite_values_give_finite_positions() {
        let g = GridGeom::new([0.0; 3], 1.0, 4).unwrap();
        let mut v = [1.0f32; 8];
        v[0] = f32::NEG_INFINITY;
        v[1] = f32::NAN;
        let m = extract(&v, [2, 2, 2], [0; 3], &g);
        assert!(!m.triangles.is_empty());
        assert!(m.positions.iter().flatten().all(|c| c.is_finite()));
    }
}
