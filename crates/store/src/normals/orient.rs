//! Consistent orientation of estimated normals.
//!
//! A plane fit gives each normal up to sign. Hoppe et al. (1992, §3.3) orient them by
//! propagation over a graph of near neighbours, along a minimum spanning tree of the costs
//! `1 − |nᵢ·nⱼ|`, so that the sign travels first between nearly parallel normals, where flipping
//! it is unambiguous, and reaches high-curvature places last: a point joining the tree takes
//! the sign that makes its normal agree with the one it joins through (`nⱼ·nᵢ ≥ 0`).
//!
//! Out of core this runs at two levels:
//! - [`orient_local`]: Prim's algorithm inside one store cell, over the cell's symmetric
//!   k-nearest-neighbour graph. Each connected part gets a component id. Where the point's scan
//!   has a known viewpoint `v` and `|n·v̂| ≥` [`VIEW_CONFIDENT`], the viewpoint decides the sign
//!   instead (a scanner sees the front of a surface); propagation fills in the grazing points.
//! - [`orient_nodes`]: the components of all cells are the nodes of a second graph, whose edge
//!   weights sum `nₐ·n_b` over neighbour pairs that straddle two cells (the halo overlap). A
//!   maximum spanning forest on `|w|` fixes their relative signs. The absolute sign of each tree
//!   comes from the viewpoint votes when any node has one (a virtual node all votes attach to,
//!   taken first), else from the hull: at the extreme point of the tree along each of ±x, ±y,
//!   ±z, a normal faces outward, each extreme voting with its normal's component along that
//!   axis (so the top of a terrain decides it, not its vertical edges).
//!
//! Nested surfaces without a viewpoint (a hollow shell's inner wall) get an outward normal from
//! the hull rule, which is wrong for them; give a viewpoint for such scans.

/// Least `|n·v̂|` at which a viewpoint alone decides a normal's sign.
pub const VIEW_CONFIDENT: f32 = 0.2;

/// Directions of the hull extremes: +x, −x, +y, −y, +z, −z.
pub const HULL_DIRS: usize = 6;

/// A symmetric neighbour graph in compressed rows.
#[derive(Debug, Default, Clone)]
pub struct Graph {
    /// Row starts, `n + 1` entries.
    pub offsets: Vec<u32>,
    /// Neighbours.
    pub targets: Vec<u32>,
}

impl Graph {
    /// The symmetric closure of directed edges `(from, to)` over `n` vertices.
    pub fn symmetric(n: usize, edges: &[(u32, u32)]) -> Graph {
        let mut deg = vec![0u32; n + 1];
        for &(a, b) in edges {
            deg[a as usize] += 1;
            deg[b as usize] += 1;
        }
        let mut offsets = vec![0u32; n + 1];
        for i in 0..n {
            offsets[i + 1] = offsets[i] + deg[i];
        }
        let mut next: Vec<u32> = offsets[..n].to_vec();
        let mut targets = vec![0u32; offsets[n] as usize];
        for &(a, b) in edges {
            targets[next[a as usize] as usize] = b;
            next[a as usize] += 1;
            targets[next[b as usize] as usize] = a;
            next[b as usize] += 1;
        }
        Graph { offsets, targets }
    }

    fn row(&self, i: usize) -> &[u32] {
        &self.targets[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }
}

/// Result of [`orient_local`].
#[derive(Debug, Default, Clone)]
pub struct Local {
    /// Component of each point.
    pub comp: Vec<u32>,
    /// Number of components.
    pub components: usize,
    /// Points whose sign the viewpoint decided.
    pub by_view: u64,
}

#[inline]
fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Buckets of the priority queue: costs are binned by angle (`√(1 − |cos θ|)` is close to
/// proportional to θ), 4096 bins from 0° to 90°.
const BINS: usize = 4096;

#[inline]
fn bin(cost: f32) -> usize {
    ((cost.max(0.0).sqrt() * (BINS - 1) as f32) as usize).min(BINS - 1)
}

/// Prim's frontier: edges `(to, from)` in buckets of their binned cost.
struct Frontier {
    buckets: Vec<Vec<(u32, u32)>>,
    /// No bucket below this one holds an edge.
    low: usize,
    queued: usize,
    /// Lowest bin seen toward each vertex not yet in a tree: an edge that does not improve on
    /// it is never queued (Prim's decrease-key, done lazily).
    best: Vec<u16>,
}

impl Frontier {
    fn new(n: usize) -> Frontier {
        Frontier {
            buckets: vec![Vec::new(); BINS],
            low: BINS,
            queued: 0,
            best: vec![u16::MAX; n],
        }
    }

    /// Queue the edges from vertex `i` to the vertices of `g` not yet in a tree.
    fn push_edges(&mut self, g: &Graph, comp: &[u32], normals: &[[f32; 3]], i: usize) {
        for &t in g.row(i) {
            let tu = t as usize;
            if comp[tu] == u32::MAX {
                let b = bin(1.0 - dot(normals[i], normals[tu]).abs());
                if (b as u16) < self.best[tu] {
                    self.best[tu] = b as u16;
                    self.buckets[b].push((t, i as u32));
                    self.queued += 1;
                    self.low = self.low.min(b);
                }
            }
        }
    }

    /// The cheapest queued edge (last in first out within a bin).
    fn pop(&mut self) -> Option<(u32, u32)> {
        if self.queued == 0 {
            self.low = BINS;
            return None;
        }
        while self.buckets[self.low].is_empty() {
            self.low += 1;
        }
        self.queued -= 1;
        self.buckets[self.low].pop()
    }
}

/// Orient `normals` in place along minimum spanning trees of `g` (costs `1 − |nᵢ·nⱼ|`).
/// `view[i]` is the unit direction from point `i` toward its scanner, or zero; `view` may be
/// empty when no scan has a viewpoint. Prim's algorithm over a bucket queue of the costs binned
/// by angle (ties within a bin of 0.02° taken last in, first out), so it is linear in the
/// edges; deterministic for a given input.
pub fn orient_local(normals: &mut [[f32; 3]], g: &Graph, view: &[[f32; 3]]) -> Local {
    let n = normals.len();
    let mut comp = vec![u32::MAX; n];
    let mut components = 0usize;
    let mut by_view = 0u64;
    let mut frontier = Frontier::new(n);
    // Sign from the viewpoint when it is decisive.
    let decide = |nrm: &mut [f32; 3], i: usize| -> bool {
        if view.is_empty() {
            return false;
        }
        let d = dot(*nrm, view[i]);
        if d.abs() >= VIEW_CONFIDENT {
            if d < 0.0 {
                *nrm = nrm.map(|c| -c);
            }
            true
        } else {
            false
        }
    };
    for root in 0..n {
        if comp[root] != u32::MAX {
            continue;
        }
        let c = components as u32;
        components += 1;
        comp[root] = c;
        by_view += decide(&mut normals[root], root) as u64;
        frontier.push_edges(g, &comp, normals, root);
        while let Some((j, from)) = frontier.pop() {
            let j = j as usize;
            if comp[j] != u32::MAX {
                continue;
            }
            comp[j] = c;
            let mut nj = normals[j];
            if decide(&mut nj, j) {
                by_view += 1;
            } else if dot(nj, normals[from as usize]) < 0.0 {
                nj = nj.map(|v| -v);
            }
            normals[j] = nj;
            frontier.push_edges(g, &comp, normals, j);
        }
    }
    Local {
        comp,
        components,
        by_view,
    }
}

/// One component of one cell, as a node of the cross-cell graph.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Node {
    /// Σ `n·v̂` over its points with a viewpoint.
    pub vote: f64,
    /// Per hull direction: the extreme coordinate along it (signed so that larger is more
    /// extreme) and the normal's component along it at that point.
    pub ext: [(f64, f32); HULL_DIRS],
}

impl Node {
    /// A node with no points yet.
    pub const EMPTY: Node = Node {
        vote: 0.0,
        ext: [(f64::NEG_INFINITY, 0.0); HULL_DIRS],
    };

    /// Add a point with its (locally oriented) normal and its `n·v̂` (0 without viewpoint).
    #[inline]
    pub fn add(&mut self, p: [f64; 3], n: [f32; 3], vote: f32) {
        self.vote += vote as f64;
        for a in 0..3 {
            for (s, d) in [(1.0, 2 * a), (-1.0, 2 * a + 1)] {
                let v = s * p[a];
                if v > self.ext[d].0 {
                    self.ext[d] = (v, s as f32 * n[a]);
                }
            }
        }
    }
}

/// A neighbour pair across two cells: a point of component `comp` with normal `n`, and point
/// `to_idx` of cell `to_cell`.
#[derive(Debug, Clone, Copy)]
pub struct Cross {
    /// Component of the point in its own cell.
    pub comp: u32,
    /// Its (locally oriented) normal.
    pub n: [f32; 3],
    /// The cell of its nearest halo neighbour.
    pub to_cell: u32,
    /// That neighbour's index in its cell.
    pub to_idx: u32,
}

/// One cell, oriented on its own.
#[derive(Debug)]
pub struct CellOrientation {
    /// Normals, locally oriented; zero where no plane fits.
    pub normals: Vec<[f32; 3]>,
    /// Component of each point.
    pub comp: Vec<u32>,
    /// The components as nodes of the cross-cell graph.
    pub nodes: Vec<Node>,
    /// The cross-cell pairs of its oriented points.
    pub cross: Vec<Cross>,
    /// Points whose sign the viewpoint decided.
    pub by_view: u64,
    /// Points without a normal (no plane among their neighbours).
    pub degenerate: u64,
}

/// Orient the fitted `normals` of a cell's points `pos` along its neighbour graph (`nbrs`:
/// [`super::ORIENT_K`] own neighbours a point, `u32::MAX` for none), toward `dirs` (each
/// point's direction to its viewpoint; empty without). `cross_of` pairs points with an index
/// into the halo, whose `halo_origin` gives the other cell's point.
pub fn orient_cell(
    pos: &[[f64; 3]],
    normals: &[Option<[f32; 3]>],
    nbrs: &[u32],
    dirs: &[[f32; 3]],
    cross_of: &[(u32, u32)],
    halo_origin: &[(u32, u32)],
) -> CellOrientation {
    let n = pos.len();
    let k = super::ORIENT_K;
    let mut degenerate = 0u64;
    let mut normals: Vec<[f32; 3]> = normals
        .iter()
        .map(|x| {
            x.unwrap_or_else(|| {
                degenerate += 1;
                [0.0; 3]
            })
        })
        .collect();
    let mut edges = Vec::with_capacity(n * k);
    for i in 0..n {
        if normals[i] == [0.0; 3] {
            continue;
        }
        for &j in &nbrs[i * k..(i + 1) * k] {
            if j != u32::MAX && normals[j as usize] != [0.0; 3] {
                edges.push((i as u32, j));
            }
        }
    }
    let g = Graph::symmetric(n, &edges);
    drop(edges);
    let local = orient_local(&mut normals, &g, dirs);
    let mut nodes = vec![Node::EMPTY; local.components];
    for i in 0..n {
        let vote = if dirs.is_empty() {
            0.0
        } else {
            dot(normals[i], dirs[i])
        };
        nodes[local.comp[i] as usize].add(pos[i], normals[i], vote);
    }
    let cross = cross_of
        .iter()
        .filter(|(i, _)| normals[*i as usize] != [0.0; 3])
        .map(|&(i, h)| {
            let (to_cell, to_idx) = halo_origin[h as usize];
            Cross {
                comp: local.comp[i as usize],
                n: normals[i as usize],
                to_cell,
                to_idx,
            }
        })
        .collect();
    CellOrientation {
        normals,
        comp: local.comp,
        nodes,
        cross,
        by_view: local.by_view,
        degenerate,
    }
}

/// Signs for the nodes: `true` where a node's normals must flip. `edges` are `(a, b, w)` with
/// `w = Σ nₐ·n_b` over the neighbour pairs joining nodes `a` and `b`. Also returns the number
/// of trees (connected parts) of the forest.
pub fn orient_nodes(nodes: &[Node], edges: &[(u32, u32, f64)]) -> (Vec<bool>, usize) {
    let n = nodes.len();
    let v = n as u32; // the virtual viewpoint node
    // Vote edges first (they pin absolute signs), each class by decreasing weight.
    let mut all: Vec<(u8, f64, u32, u32, f64)> = Vec::with_capacity(edges.len() + n);
    for (i, nd) in nodes.iter().enumerate() {
        if nd.vote != 0.0 {
            all.push((0, -nd.vote.abs(), i as u32, v, nd.vote));
        }
    }
    for &(a, b, w) in edges {
        if w != 0.0 && a != b {
            all.push((1, -w.abs(), a.min(b), a.max(b), w));
        }
    }
    all.sort_by(|x, y| {
        (x.0, x.1, x.2, x.3)
            .partial_cmp(&(y.0, y.1, y.2, y.3))
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let mut parent: Vec<u32> = (0..=v).collect();
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    let mut adj: Vec<Vec<(u32, bool)>> = vec![Vec::new(); n + 1];
    for &(_, _, a, b, w) in &all {
        let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
        if ra == rb {
            continue;
        }
        parent[ra as usize] = rb;
        // Same sign across the edge when w > 0.
        adj[a as usize].push((b, w < 0.0));
        adj[b as usize].push((a, w < 0.0));
    }
    let mut flip = vec![false; n + 1];
    let mut seen = vec![false; n + 1];
    let mut trees = 0;
    let mut order = vec![v];
    order.extend(0..v);
    let mut stack = Vec::new();
    for root in order {
        if seen[root as usize] || (root == v && adj[v as usize].is_empty()) {
            continue;
        }
        trees += 1;
        seen[root as usize] = true;
        let mut members = vec![root];
        stack.push(root);
        while let Some(x) = stack.pop() {
            for &(y, opposite) in &adj[x as usize] {
                if !seen[y as usize] {
                    seen[y as usize] = true;
                    flip[y as usize] = flip[x as usize] ^ opposite;
                    members.push(y);
                    stack.push(y);
                }
            }
        }
        if root == v {
            continue;
        }
        // No viewpoint in this tree: the hull decides.
        let mut vote = 0.0f64;
        for d in 0..HULL_DIRS {
            let best = members
                .iter()
                .copied()
                .max_by(|&a, &b| {
                    nodes[a as usize].ext[d]
                        .0
                        .total_cmp(&nodes[b as usize].ext[d].0)
                        .then(b.cmp(&a))
                })
                .unwrap_or(root);
            let c = nodes[best as usize].ext[d].1 as f64;
            vote += if flip[best as usize] { -c } else { c };
        }
        if vote < 0.0 {
            for &m in &members {
                flip[m as usize] = !flip[m as usize];
            }
        }
    }
    flip.truncate(n);
    (flip, trees)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn propagation_makes_a_ring_consistent() {
        // Points on a circle, normals radial with random signs, each linked to its neighbours.
        let n = 100;
        let mut normals = Vec::new();
        let mut edges = Vec::new();
        for i in 0..n {
            let t = i as f32 / n as f32 * std::f32::consts::TAU;
            let s = if (i * 7919) % 3 == 0 { -1.0 } else { 1.0 };
            normals.push([s * t.cos(), s * t.sin(), 0.0]);
            edges.push((i as u32, ((i + 1) % n) as u32));
        }
        let g = Graph::symmetric(n, &edges);
        let l = orient_local(&mut normals, &g, &[]);
        assert_eq!(l.components, 1);
        let s0 = normals[0][0].signum();
        for (i, nrm) in normals.iter().enumerate() {
            let t = i as f32 / n as f32 * std::f32::consts::TAU;
            assert!((nrm[0] * t.cos() + nrm[1] * t.sin()) * s0 > 0.99, "{i}");
        }
    }

    #[test]
    fn viewpoint_decides_where_confident() {
        let mut normals = vec![[0.0, 0.0, -1.0], [0.0, 0.0, 1.0]];
        let g = Graph::symmetric(2, &[]);
        let view = vec![[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]];
        let l = orient_local(&mut normals, &g, &view);
        assert_eq!(l.by_view, 2);
        assert_eq!(l.components, 2);
        assert!(normals.iter().all(|n| n[2] == 1.0));
    }

    fn node(p: [f64; 3], n: [f32; 3], vote: f32) -> Node {
        let mut x = Node::EMPTY;
        x.add(p, n, vote);
        x
    }

    #[test]
    fn hull_faces_outward_and_edges_carry_signs() {
        // Two nodes on a unit sphere at +x and -x, both normals pointing +x (one is wrong);
        // the edge says they disagree.
        let nodes = [
            node([1.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0.0),
            node([-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0.0),
        ];
        let (flip, trees) = orient_nodes(&nodes, &[(0, 1, -3.0)]);
        assert_eq!(trees, 1);
        assert_eq!(flip, vec![false, true]);
        // Both inward and consistent with each other: the hull flips both.
        let nodes = [
            node([1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], 0.0),
            node([-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0.0),
        ];
        let (flip, _) = orient_nodes(&nodes, &[(0, 1, 3.0)]);
        assert_eq!(flip, vec![true, true]);
    }

    #[test]
    fn votes_beat_the_hull() {
        // An inner wall facing inward, as its scanner saw it: the vote keeps it.
        let nodes = [node([0.5, 0.0, 0.0], [-1.0, 0.0, 0.0], 0.9)];
        let (flip, trees) = orient_nodes(&nodes, &[]);
        assert_eq!((flip, trees), (vec![false], 1));
        let nodes = [node([0.5, 0.0, 0.0], [-1.0, 0.0, 0.0], -0.9)];
        assert_eq!(orient_nodes(&nodes, &[]).0, vec![true]);
    }
}
