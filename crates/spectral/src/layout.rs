//! Patch layout (Pauly & Gross 2001, §3): the points of a cell are split into small clusters
//! by a binary space partition, then clusters are merged, best pair first, into patches that
//! each satisfy the normal-cone condition, so that each patch is a height field over a plane.
//!
//! # Split
//!
//! A cluster (a range of one permuted array of (position, index), so no per-cluster
//! allocation and splits read memory in order) is split at
//! the median of the longest side of its bounding box, ties of the coordinate broken by point
//! index, until it has at most `min(cluster_max, patch_max)` points *and* its normal cone
//! ([`enclosing_cone`](super::cone::enclosing_cone), exact) has aperture `2θ <= max_aperture`.
//! A cone failure splits further, down to single points if needed (a single point always
//! passes). Splitting at the median index halves the count, so duplicate positions terminate.
//! Points with a zero (degenerate) normal stay with their spatial cluster and are ignored by
//! the cones; a cluster with no non-zero normal has no cone and merges freely.
//!
//! # Adjacency
//!
//! Each BSP leaf gets the bounding box of its points, widened by the local sample spacing
//! `s = sqrt(d1·d2 / n)` of the first ancestor that had at most `cluster_max` points
//! (`d1 >= d2` the two longest sides of its box, `n` its points; `d1 / n` if that is zero).
//! Two leaves are adjacent when their widened boxes overlap, i.e. when their point sets come
//! within about `s_a + s_b` of each other per axis. Pairs are found by sort-and-sweep along the
//! longest axis of all boxes, in the order of (lower bound, leaf index): deterministic,
//! `O(L log L + candidates)`, with the candidates per leaf capped (512 examined, 32 kept) so
//! that many leaves on one spot (duplicate points) cannot make it quadratic.
//!
//! # Merge
//!
//! Greedy over adjacent pairs `(A, B)`, highest priority first, with a binary heap whose
//! entries carry the two clusters' version counters (an entry whose cluster has merged since
//! is stale and skipped), union-find for membership, and per-cluster linked lists of adjacency
//! half-edges that are concatenated on merge and compacted (self-loops and repeats dropped)
//! when the merged cluster re-scores its neighbours. A merge is allowed only if the merged
//! size `n = n_A + n_B <= patch_max` and the merged cone bound
//! ([`merge_cones`]) has aperture `α <= max_aperture`. The priority
//! is `Φ = Φ_S · Φ_NC · Φ_B · Φ_Reg` with
//!
//! - size: `Φ_S = 1 - n / (2·patch_max)`, in `[1/2, 1)`: smaller merged patches first;
//! - normal cone: `Φ_NC = 1 - α / (2·max_aperture)`, in `[1/2, 1]`: flatter patches first
//!   (`Φ_NC = 1` when no member has a normal);
//! - boundary: `Φ_B = max(Q, 0.01)` with `Q = 4π·area / perimeter²` the isoperimetric quotient
//!   of the merged points' covariance ellipse in the plane normal to the merged cone's axis:
//!   semi-axes `a >= b` from the 2×2 covariance's eigenvalues, area `πab`, perimeter by
//!   Ramanujan's `π(3(a+b) - sqrt((3a+b)(a+3b)))`. `Q = 1` for a disc and falls towards 0 as
//!   the patch gets elongated: a cheap stand-in for boundary length over area, from additive
//!   moments (`Σp`, `Σppᵀ`) so each score costs `O(1)`;
//! - regularisation: `Φ_Reg = max(1, cluster_min / min(n_A, n_B))`: a cluster under
//!   `cluster_min` points is merged first, up to `cluster_min` times the priority.
//!
//! Merging goes on until no allowed pair is left. The output cone of each patch is the exact
//! smallest cap of its members' normals (at most the merged bound, so the condition holds).
//! Patches are ordered by their smallest member; members are ascending. The result depends
//! only on the input slices: no hashing, no threads, no clock.

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::f64::consts::PI;

use super::cone::{Cone, ConeWorkspace, cross, dot, enclosing_cone_with, merge_cones, normalize};
use crate::error::{Error, Result};

/// Parameters of [`layout`].
#[derive(Clone, Debug, PartialEq)]
pub struct LayoutParams {
    /// Largest BSP cluster, points (the paper: 100).
    pub cluster_max: usize,
    /// Clusters under this many points are merged first (`Φ_Reg`), points (the paper: 25).
    pub cluster_min: usize,
    /// Largest patch, points.
    pub patch_max: usize,
    /// Largest full opening angle of a patch's normal cone, radians (the paper: π/2). Values
    /// at or above π are treated as just under π.
    pub max_aperture: f64,
}

impl Default for LayoutParams {
    fn default() -> Self {
        LayoutParams {
            cluster_max: 100,
            cluster_min: 25,
            patch_max: 1000,
            max_aperture: PI / 2.0,
        }
    }
}

impl LayoutParams {
    /// Rejects parameters that cannot describe a layout: a zero size, or an aperture that is
    /// negative or not finite.
    pub fn check(&self) -> Result<()> {
        if self.cluster_max == 0 || self.cluster_min == 0 || self.patch_max == 0 {
            return Err(Error::Usage(format!(
                "patch layout: cluster_max ({}), cluster_min ({}) and patch_max ({}) must be at least 1",
                self.cluster_max, self.cluster_min, self.patch_max
            )));
        }
        if !(self.max_aperture.is_finite() && self.max_aperture >= 0.0) {
            return Err(Error::Usage(format!(
                "patch layout: the normal cone's aperture must be a finite angle >= 0, found {}",
                self.max_aperture
            )));
        }
        Ok(())
    }
}

/// One patch of the layout.
#[derive(Clone, Debug, PartialEq)]
pub struct PatchSeed {
    /// Indices into the positions, ascending.
    pub members: Vec<u32>,
    /// The smallest cap holding the members' non-zero normals. When no member has one
    /// (`oriented == 0`) it is the placeholder `axis = (0, 0, 1)`, `half_angle = 0`.
    pub cone: Cone,
    /// How many members have a non-zero, finite normal.
    pub oriented: u32,
}

/// Reusable buffers of [`layout_with`].
#[derive(Debug, Default)]
pub struct Workspace {
    items: Vec<Item>,
    ids: Vec<u32>,
    stack: Vec<(u32, u32, f64)>,
    leaves: Vec<Leaf>,
    leaf_of: Vec<u32>,
    order: Vec<u32>,
    he_to: Vec<u32>,
    he_next: Vec<u32>,
    parent: Vec<u32>,
    clusters: Vec<Cluster>,
    stamp: Vec<u32>,
    heap: BinaryHeap<Candidate>,
    patch_of: Vec<u32>,
    cone: ConeWorkspace,
}

/// A point during the BSP: its position beside its index, so splits read memory in order.
#[derive(Clone, Copy, Debug)]
struct Item {
    p: [f64; 3],
    i: u32,
}

/// A BSP leaf: a range of `Workspace::items` and its widened bounding box.
#[derive(Clone, Copy, Debug)]
struct Leaf {
    lo: u32,
    hi: u32,
    box_lo: [f64; 3],
    box_hi: [f64; 3],
}

/// A cluster during merging (indexed by its first leaf).
#[derive(Clone, Copy, Debug)]
struct Cluster {
    size: u32,
    version: u32,
    head: u32,
    tail: u32,
    cone: Option<Cone>,
    /// `Σ (p - origin)`.
    sum: [f64; 3],
    /// `Σ (p - origin)(p - origin)ᵀ`: xx, xy, xz, yy, yz, zz.
    sq: [f64; 6],
}

/// A heap entry: priority bits (a non-negative `f64`), the pair (ascending), their versions.
type Candidate = (u64, Reverse<u32>, Reverse<u32>, u32, u32);

const NIL: u32 = u32::MAX;

/// The patch layout of `pos` with `normals` (same length): every index in exactly one patch.
/// Allocates its buffers; see [`layout_with`]. Sizes of 0 in `params` are taken as 1.
pub fn layout(pos: &[[f64; 3]], normals: &[[f32; 3]], params: &LayoutParams) -> Vec<PatchSeed> {
    layout_with(&mut Workspace::default(), pos, normals, params)
}

/// [`layout`] with reusable buffers. Positions must be finite.
///
/// # Panics
///
/// If `pos` and `normals` differ in length, or hold `2^32 - 1` points or more (a store cell
/// holds at most `2^18`).
pub fn layout_with(
    ws: &mut Workspace,
    pos: &[[f64; 3]],
    normals: &[[f32; 3]],
    params: &LayoutParams,
) -> Vec<PatchSeed> {
    assert_eq!(pos.len(), normals.len(), "one normal per position");
    assert!(pos.len() < NIL as usize, "too many points for u32 indices");
    let p = Limits::new(params);
    split(ws, pos, normals, &p);
    adjacency(ws);
    merge(ws, &p);
    assemble(ws, pos.len(), normals)
}

/// The parameters as used: sizes at least 1, the aperture under π.
struct Limits {
    leaf_max: usize,
    cluster_max: usize,
    cluster_min: f64,
    patch_max: usize,
    aperture: f64,
}

impl Limits {
    fn new(p: &LayoutParams) -> Self {
        let patch_max = p.patch_max.max(1);
        let cluster_max = p.cluster_max.max(1);
        let aperture = if p.max_aperture.is_nan() {
            0.0
        } else {
            p.max_aperture
        };
        Limits {
            leaf_max: cluster_max.min(patch_max),
            cluster_max,
            cluster_min: p.cluster_min.max(1) as f64,
            patch_max,
            aperture: aperture.clamp(0.0, PI * (1.0 - 1e-9)),
        }
    }
}

/// The BSP: fills `items`, `leaves` and the leaves' clusters.
fn split(ws: &mut Workspace, pos: &[[f64; 3]], normals: &[[f32; 3]], p: &Limits) {
    let n = pos.len();
    ws.items.clear();
    ws.items.extend(
        pos.iter()
            .enumerate()
            .map(|(i, &q)| Item { p: q, i: i as u32 }),
    );
    ws.leaves.clear();
    ws.clusters.clear();
    ws.stack.clear();
    if n == 0 {
        return;
    }
    let (glo, ghi) = bounds(&ws.items);
    let origin = [
        0.5 * (glo[0] + ghi[0]),
        0.5 * (glo[1] + ghi[1]),
        0.5 * (glo[2] + ghi[2]),
    ];
    ws.stack.push((0, n as u32, f64::NAN));
    while let Some((lo, hi, spacing)) = ws.stack.pop() {
        let items = &mut ws.items[lo as usize..hi as usize];
        let (bmin, bmax) = bounds(items);
        let len = items.len();
        let mut spacing = spacing;
        if len <= p.cluster_max && spacing.is_nan() {
            spacing = sample_spacing(bmin, bmax, len);
        }
        if len <= p.leaf_max {
            ws.ids.clear();
            ws.ids.extend(items.iter().map(|it| it.i));
            let cone = enclosing_cone_with(&mut ws.cone, normals, &ws.ids);
            let ok = len == 1
                || match cone {
                    Some(c) => c.aperture() <= p.aperture,
                    None => ws.cone.used() == 0,
                };
            if ok {
                let w = if spacing.is_finite() { spacing } else { 0.0 };
                ws.leaves.push(Leaf {
                    lo,
                    hi,
                    box_lo: [bmin[0] - w, bmin[1] - w, bmin[2] - w],
                    box_hi: [bmax[0] + w, bmax[1] + w, bmax[2] + w],
                });
                ws.clusters.push(new_cluster(items, origin, cone));
                continue;
            }
        }
        let d = [bmax[0] - bmin[0], bmax[1] - bmin[1], bmax[2] - bmin[2]];
        let axis = if d[0] >= d[1] && d[0] >= d[2] {
            0
        } else if d[1] >= d[2] {
            1
        } else {
            2
        };
        let mid = len / 2;
        items.select_nth_unstable_by(mid, |a, b| {
            a.p[axis].total_cmp(&b.p[axis]).then(a.i.cmp(&b.i))
        });
        let m = lo + mid as u32;
        ws.stack.push((m, hi, spacing));
        ws.stack.push((lo, m, spacing));
    }
}

fn new_cluster(items: &[Item], origin: [f64; 3], cone: Option<Cone>) -> Cluster {
    let mut sum = [0.0; 3];
    let mut sq = [0.0; 6];
    for it in items {
        let q = it.p;
        let d = [q[0] - origin[0], q[1] - origin[1], q[2] - origin[2]];
        for k in 0..3 {
            sum[k] += d[k];
        }
        sq[0] += d[0] * d[0];
        sq[1] += d[0] * d[1];
        sq[2] += d[0] * d[2];
        sq[3] += d[1] * d[1];
        sq[4] += d[1] * d[2];
        sq[5] += d[2] * d[2];
    }
    Cluster {
        size: items.len() as u32,
        version: 0,
        head: NIL,
        tail: NIL,
        cone,
        sum,
        sq,
    }
}

fn bounds(items: &[Item]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for it in items {
        for k in 0..3 {
            lo[k] = lo[k].min(it.p[k]);
            hi[k] = hi[k].max(it.p[k]);
        }
    }
    (lo, hi)
}

/// Mean spacing of `n` samples of a surface in the box `lo..hi`: `sqrt(d1·d2 / n)` for its
/// two longest sides, `d1 / n` if the box is a segment.
fn sample_spacing(lo: [f64; 3], hi: [f64; 3], n: usize) -> f64 {
    let mut d = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    d.sort_by(|a, b| b.total_cmp(a));
    let n = n.max(1) as f64;
    let s = (d[0] * d[1] / n).sqrt();
    if s > 0.0 { s } else { d[0] / n }
}

/// At most this many leaves are examined after each leaf in the sweep order.
const SWEEP_SCAN: usize = 512;
/// At most this many adjacent leaves are recorded after each leaf in the sweep order.
const SWEEP_FOUND: usize = 32;

/// Adjacent leaves by sort-and-sweep of their widened boxes along the longest axis of all
/// boxes: fills the half-edges. Each leaf examines at most [`SWEEP_SCAN`] successors and
/// records at most [`SWEEP_FOUND`] of them, which bounds the work where many leaves share one
/// box (duplicate points split by their normals); on a sampled surface a leaf's slab holds
/// about `2·sqrt(L)` leaves, so the caps do not bind there. A cap that binds (a dense 3D cloud)
/// only drops adjacencies: fewer merges, never an invalid patch.
fn adjacency(ws: &mut Workspace) {
    let leaves = &ws.leaves;
    let mut glo = [f64::INFINITY; 3];
    let mut ghi = [f64::NEG_INFINITY; 3];
    for l in leaves {
        for k in 0..3 {
            glo[k] = glo[k].min(l.box_lo[k]);
            ghi[k] = ghi[k].max(l.box_hi[k]);
        }
    }
    let d = [ghi[0] - glo[0], ghi[1] - glo[1], ghi[2] - glo[2]];
    let x = if d[0] >= d[1] && d[0] >= d[2] {
        0
    } else if d[1] >= d[2] {
        1
    } else {
        2
    };
    let (y, z) = ((x + 1) % 3, (x + 2) % 3);
    ws.order.clear();
    ws.order.extend(0..leaves.len() as u32);
    ws.order.sort_unstable_by(|&a, &b| {
        leaves[a as usize].box_lo[x]
            .total_cmp(&leaves[b as usize].box_lo[x])
            .then(a.cmp(&b))
    });
    ws.he_to.clear();
    ws.he_next.clear();
    for (k, &a) in ws.order.iter().enumerate() {
        let la = &leaves[a as usize];
        let mut found = 0;
        for &b in ws.order[k + 1..].iter().take(SWEEP_SCAN) {
            let lb = &leaves[b as usize];
            if lb.box_lo[x] > la.box_hi[x] || found == SWEEP_FOUND {
                break;
            }
            let overlap = [y, z]
                .iter()
                .all(|&d| lb.box_lo[d] <= la.box_hi[d] && la.box_lo[d] <= lb.box_hi[d]);
            if !overlap {
                continue;
            }
            found += 1;
            for (from, to) in [(a, b), (b, a)] {
                let e = ws.he_to.len() as u32;
                let c = &mut ws.clusters[from as usize];
                ws.he_to.push(to);
                ws.he_next.push(c.head);
                if c.head == NIL {
                    c.tail = e;
                }
                c.head = e;
            }
        }
    }
}

/// Union-find root with path halving.
fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let g = parent[parent[x as usize] as usize];
        parent[x as usize] = g;
        x = g;
    }
    x
}

/// Greedy merging of adjacent clusters by priority.
fn merge(ws: &mut Workspace, p: &Limits) {
    let l = ws.clusters.len();
    ws.parent.clear();
    ws.parent.extend(0..l as u32);
    ws.stamp.clear();
    ws.stamp.resize(l, 0);
    ws.heap.clear();
    for e in (0..ws.he_to.len()).step_by(2) {
        let (a, b) = (ws.he_to[e + 1], ws.he_to[e]);
        push_candidate(&mut ws.heap, &ws.clusters, a, b, p);
    }
    let mut epoch = 0u32;
    while let Some((_, Reverse(a), Reverse(b), va, vb)) = ws.heap.pop() {
        if ws.parent[a as usize] != a
            || ws.parent[b as usize] != b
            || ws.clusters[a as usize].version != va
            || ws.clusters[b as usize].version != vb
        {
            continue;
        }
        let (ca, cb) = (ws.clusters[a as usize], ws.clusters[b as usize]);
        let (r, o) = if ca.size >= cb.size { (a, b) } else { (b, a) };
        let (cr, co) = if r == a { (ca, cb) } else { (cb, ca) };
        ws.parent[o as usize] = r;
        let mut m = joined(&cr, &co);
        m.version = cr.version + 1;
        // Concatenate the half-edge lists.
        if co.head != NIL {
            if m.head == NIL {
                m.head = co.head;
            } else {
                ws.he_next[m.tail as usize] = co.head;
            }
            m.tail = co.tail;
        }
        ws.clusters[r as usize] = m;
        epoch += 1;
        rescore(ws, r, epoch, p);
    }
}

/// Walks `r`'s half-edges: drops self-loops and repeats, points the rest at roots, and pushes
/// a candidate for each neighbour.
fn rescore(ws: &mut Workspace, r: u32, epoch: u32, p: &Limits) {
    let mut prev = NIL;
    let mut e = ws.clusters[r as usize].head;
    while e != NIL {
        let next = ws.he_next[e as usize];
        let t = find(&mut ws.parent, ws.he_to[e as usize]);
        if t == r || ws.stamp[t as usize] == epoch {
            if prev == NIL {
                ws.clusters[r as usize].head = next;
            } else {
                ws.he_next[prev as usize] = next;
            }
        } else {
            ws.stamp[t as usize] = epoch;
            ws.he_to[e as usize] = t;
            push_candidate(&mut ws.heap, &ws.clusters, r, t, p);
            prev = e;
        }
        e = next;
    }
    ws.clusters[r as usize].tail = prev;
}

/// The union of two clusters (head, tail and version are the first's).
fn joined(a: &Cluster, b: &Cluster) -> Cluster {
    let cone = match (a.cone, b.cone) {
        (Some(x), Some(y)) => Some(merge_cones(&x, &y)),
        (x, y) => x.or(y),
    };
    let mut m = *a;
    m.size += b.size;
    m.cone = cone;
    for k in 0..3 {
        m.sum[k] += b.sum[k];
    }
    for k in 0..6 {
        m.sq[k] += b.sq[k];
    }
    m
}

/// Scores the merge of `a` and `b` and pushes it if it is allowed.
fn push_candidate(heap: &mut BinaryHeap<Candidate>, cl: &[Cluster], a: u32, b: u32, p: &Limits) {
    let (ca, cb) = (&cl[a as usize], &cl[b as usize]);
    let n = (ca.size + cb.size) as usize;
    if n > p.patch_max {
        return;
    }
    let m = joined(ca, cb);
    let alpha = m.cone.map_or(0.0, |c| c.aperture());
    if alpha > p.aperture {
        return;
    }
    let phi_s = 1.0 - n as f64 / (2.0 * p.patch_max as f64);
    let phi_nc = if p.aperture > 0.0 {
        1.0 - alpha / (2.0 * p.aperture)
    } else {
        1.0
    };
    let phi_b = compactness(&m).max(0.01);
    let phi_reg = (p.cluster_min / f64::from(ca.size.min(cb.size))).max(1.0);
    let phi = phi_s * phi_nc * phi_b * phi_reg;
    let (lo, hi) = (a.min(b), a.max(b));
    let (vlo, vhi) = (cl[lo as usize].version, cl[hi as usize].version);
    heap.push((phi.max(0.0).to_bits(), Reverse(lo), Reverse(hi), vlo, vhi));
}

/// Isoperimetric quotient `4π·area / perimeter²` of the cluster's covariance ellipse in the
/// plane normal to its cone axis (the z axis if it has none); 1 for a point.
fn compactness(c: &Cluster) -> f64 {
    let n = f64::from(c.size);
    let mu = [c.sum[0] / n, c.sum[1] / n, c.sum[2] / n];
    let s = c.sq;
    let cov = [
        [
            s[0] / n - mu[0] * mu[0],
            s[1] / n - mu[0] * mu[1],
            s[2] / n - mu[0] * mu[2],
        ],
        [
            s[1] / n - mu[1] * mu[0],
            s[3] / n - mu[1] * mu[1],
            s[4] / n - mu[1] * mu[2],
        ],
        [
            s[2] / n - mu[2] * mu[0],
            s[4] / n - mu[2] * mu[1],
            s[5] / n - mu[2] * mu[2],
        ],
    ];
    let axis = c.cone.map_or([0.0, 0.0, 1.0], |c| c.axis);
    let t = if axis[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let t1 = normalize(cross(axis, t)).unwrap_or([1.0, 0.0, 0.0]);
    let t2 = cross(axis, t1);
    let quad = |u: [f64; 3], v: [f64; 3]| {
        let cv = [dot(cov[0], v), dot(cov[1], v), dot(cov[2], v)];
        dot(u, cv)
    };
    let (c11, c12, c22) = (quad(t1, t1), quad(t1, t2), quad(t2, t2));
    let mean = 0.5 * (c11 + c22);
    let r = (0.25 * (c11 - c22) * (c11 - c22) + c12 * c12).sqrt();
    let a = (mean + r).max(0.0).sqrt();
    let b = (mean - r).max(0.0).sqrt();
    if a <= 0.0 {
        return 1.0;
    }
    let perimeter = PI * (3.0 * (a + b) - ((3.0 * a + b) * (a + 3.0 * b)).sqrt());
    (4.0 * PI * PI * a * b / (perimeter * perimeter)).clamp(0.0, 1.0)
}

/// The patches: members gathered per root in point order, then each patch's exact cone.
fn assemble(ws: &mut Workspace, n: usize, normals: &[[f32; 3]]) -> Vec<PatchSeed> {
    ws.leaf_of.clear();
    ws.leaf_of.resize(n, NIL);
    for (k, leaf) in ws.leaves.iter().enumerate() {
        for it in &ws.items[leaf.lo as usize..leaf.hi as usize] {
            ws.leaf_of[it.i as usize] = k as u32;
        }
    }
    ws.patch_of.clear();
    ws.patch_of.resize(ws.leaves.len(), NIL);
    let mut patches: Vec<PatchSeed> = Vec::new();
    let placeholder = Cone {
        axis: [0.0, 0.0, 1.0],
        half_angle: 0.0,
    };
    for i in 0..n {
        let r = find(&mut ws.parent, ws.leaf_of[i]) as usize;
        if ws.patch_of[r] == NIL {
            ws.patch_of[r] = patches.len() as u32;
            let members = Vec::with_capacity(ws.clusters[r].size as usize);
            patches.push(PatchSeed {
                members,
                cone: placeholder,
                oriented: 0,
            });
        }
        patches[ws.patch_of[r] as usize].members.push(i as u32);
    }
    for patch in &mut patches {
        if let Some(c) = enclosing_cone_with(&mut ws.cone, normals, &patch.members) {
            patch.cone = c;
        }
        patch.oriented = ws.cone.used() as u32;
    }
    patches
}

#[cfg(test)]
mod tests;
