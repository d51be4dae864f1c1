//! The marching-cubes case table, generated at first use from the face rule of the
//! [module docs](super).
//!
//! Nothing here is pasted from elsewhere: [`case_triangles`] and [`flat_table`] are built once
//! (in a [`OnceLock`]) by the private `generate` from three small facts, the corner numbering
//! [`CORNER_OFFSETS`], the edge numbering [`EDGE_CORNERS`] and the face rule:
//!
//! 1. On each of the 6 faces of the cube, walk the 4 corners in cyclic order. Every maximal
//!    run of consecutive inside corners gets one segment, from the crossing edge where the
//!    run starts to the crossing edge where it ends. So a face with one inside corner, or
//!    with two diagonally opposite inside corners (the ambiguous face), cuts every inside
//!    corner off on its own: inside corners are never joined across an ambiguous face.
//! 2. Each segment is oriented so that, seen from outside the cube looking along the face's
//!    inward direction (outward normal pointing at the viewer), its inside corners lie on
//!    the right of the segment.
//! 3. Every crossing edge of the cube is then the end of exactly one segment and the start
//!    of exactly one other, so the segments chain into closed loops. A loop is a polygon
//!    whose vertices are crossing edges.
//! 4. A loop is fan-triangulated from one of its vertices, the apex. The loop is first
//!    rotated so that its first vertex is a valid apex: one that shares no cube face with any
//!    loop vertex other than its two neighbours. Otherwise a fan diagonal could join two
//!    vertices of one face, and lie in that face where the neighbouring cube has no segment,
//!    which would break the seam. Such a loop exists for ambiguous faces whose two segments
//!    belong to the same loop (case `0b1011_1001`, inside corners 0, 3, 4, 5, 7, is one).
//!
//! Because a face's segments depend only on the signs of its own 4 corners, two cubes that
//! share a face produce the same segments on it, traversed in opposite directions (the face's
//! outward normals are opposite). Together with rule 4 this makes the surface of a grid closed
//! and edge-manifold wherever it does not reach the border of the grid, and consistently
//! oriented. Rule 2 makes the loops run counter-clockwise seen from the outside of the surface
//! (where values exceed the iso-value), so triangles `[a, b, c]` have their normal
//! `(b − a) × (c − a)` pointing toward increasing values.
//!
//! Shape of the generated table: loops have 3 to 7 vertices (144, 66, 72, 52 and 24 loops of
//! 3, 4, 5, 6 and 7 over all cases), and a case has at most [`MAX_CASE_TRIANGLES`] = 5
//! triangles, the bound of the classic table (2, 16, 50, 80, 76 and 32 cases have 0 to 5).
//! A case has `crossing edges − 2·loops` triangles.

use std::sync::OnceLock;

/// Offsets `(x, y, z)` of corner `c` of a cube from its lowest corner, in cells:
/// `(c & 1, (c >> 1) & 1, (c >> 2) & 1)`.
///
/// | corner | 0 | 1 | 2 | 3 | 4 | 5 | 6 | 7 |
/// |--------|---|---|---|---|---|---|---|---|
/// | x      | 0 | 1 | 0 | 1 | 0 | 1 | 0 | 1 |
/// | y      | 0 | 0 | 1 | 1 | 0 | 0 | 1 | 1 |
/// | z      | 0 | 0 | 0 | 0 | 1 | 1 | 1 | 1 |
pub const CORNER_OFFSETS: [[u8; 3]; 8] = [
    [0, 0, 0],
    [1, 0, 0],
    [0, 1, 0],
    [1, 1, 0],
    [0, 0, 1],
    [1, 0, 1],
    [0, 1, 1],
    [1, 1, 1],
];

/// The two corners `[a, b]` (`a < b`) of each of the 12 edges of a cube.
///
/// Edges are numbered by axis, then by the offsets of their lower corner `a` in the two other
/// axes: edge `e` runs along axis `e / 4`, and its lower corner is `a`, `b = a + (1 << axis)`.
///
/// | edge   | 0 | 1 | 2 | 3 | 4 | 5 | 6 | 7 | 8 | 9 | 10 | 11 |
/// |--------|---|---|---|---|---|---|---|---|---|---|----|----|
/// | axis   | x | x | x | x | y | y | y | y | z | z | z  | z  |
/// | a      | 0 | 2 | 4 | 6 | 0 | 1 | 4 | 5 | 0 | 1 | 2  | 3  |
/// | b      | 1 | 3 | 5 | 7 | 2 | 3 | 6 | 7 | 4 | 5 | 6  | 7  |
///
/// Worked example: in the cube whose lowest node is grid node `(i, j, k)`, edge 6 joins corner
/// 4 (offset `(0, 0, 1)`) and corner 6 (offset `(0, 1, 1)`): it is the y-edge from grid node
/// `(i, j, k + 1)` to `(i, j + 1, k + 1)`. With only corner 0 inside (case `1`), the crossing
/// edges are 0, 4 and 8, and the case is one triangle `[0, 4, 8]`: its normal
/// `(e4 − e0) × (e8 − e0)` points to `(1, 1, 1)`, away from the inside corner.
pub const EDGE_CORNERS: [[u8; 2]; 12] = [
    [0, 1],
    [2, 3],
    [4, 5],
    [6, 7],
    [0, 2],
    [1, 3],
    [4, 6],
    [5, 7],
    [0, 4],
    [1, 5],
    [2, 6],
    [3, 7],
];

/// The axis (0 = x, 1 = y, 2 = z) of each edge: `e / 4`.
pub const EDGE_AXIS: [u8; 12] = [0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2];

/// The most triangles any case produces (see the [module docs](self)).
pub const MAX_CASE_TRIANGLES: usize = 5;

/// A face of the cube: the corners whose coordinate on `axis` equals `side`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Face {
    /// Axis of the face's normal (0 = x, 1 = y, 2 = z).
    pub axis: u8,
    /// 0 for the lower face (outward normal `−axis`), 1 for the upper one (`+axis`).
    pub side: u8,
}

impl Face {
    /// The 6 faces, in the order (x, 0), (x, 1), (y, 0), (y, 1), (z, 0), (z, 1).
    pub const ALL: [Face; 6] = [
        Face { axis: 0, side: 0 },
        Face { axis: 0, side: 1 },
        Face { axis: 1, side: 0 },
        Face { axis: 1, side: 1 },
        Face { axis: 2, side: 0 },
        Face { axis: 2, side: 1 },
    ];

    /// Its 4 corners in cyclic order around the face (counter-clockwise seen from `+axis`).
    pub fn corners(self) -> [u8; 4] {
        let u = (self.axis + 1) % 3;
        let v = (self.axis + 2) % 3;
        let base = self.side << self.axis;
        [
            base,
            base | (1 << u),
            base | (1 << u) | (1 << v),
            base | (1 << v),
        ]
    }

    /// True when edge `e` lies in this face.
    pub fn has_edge(self, e: u8) -> bool {
        let [a, b] = EDGE_CORNERS[e as usize];
        let bit = 1 << self.axis;
        (a & bit == 0) == (self.side == 0) && (b & bit == 0) == (self.side == 0)
    }

    /// The face rule (rule 1 and 2 of the [module docs](self)): the oriented segments
    /// `[from, to]` (edge indices) that case `case` has on this face.
    pub fn segments(self, case: u8) -> Vec<[u8; 2]> {
        let cs = self.corners();
        let inside = |c: u8| case & (1 << c) != 0;
        let mut out = Vec::new();
        for i in 0..4 {
            let prev = cs[(i + 3) % 4];
            if !inside(cs[i]) || inside(prev) {
                continue;
            }
            // cs[i] starts a run of inside corners: find where it ends.
            let mut j = i;
            while inside(cs[(j + 1) % 4]) {
                j += 1;
            }
            let enter = edge_between(prev, cs[i]);
            let leave = edge_between(cs[j % 4], cs[(j + 1) % 4]);
            out.push(self.orient([enter, leave], cs[i]));
        }
        out
    }

    /// Order the segment `s` so that the inside corner `c` lies on its right seen from outside.
    fn orient(self, s: [u8; 2], c: u8) -> [u8; 2] {
        // Doubled coordinates keep edge midpoints integral.
        let m = |e: u8| -> [i32; 3] {
            let [a, b] = EDGE_CORNERS[e as usize];
            let (pa, pb) = (CORNER_OFFSETS[a as usize], CORNER_OFFSETS[b as usize]);
            [0, 1, 2].map(|d| pa[d] as i32 + pb[d] as i32)
        };
        let (p, q) = (m(s[0]), m(s[1]));
        let pc = CORNER_OFFSETS[c as usize].map(|v| 2 * v as i32);
        let d = [q[0] - p[0], q[1] - p[1], q[2] - p[2]];
        let w = [pc[0] - p[0], pc[1] - p[1], pc[2] - p[2]];
        let cross = [
            d[1] * w[2] - d[2] * w[1],
            d[2] * w[0] - d[0] * w[2],
            d[0] * w[1] - d[1] * w[0],
        ];
        let outward = if self.side == 1 { 1 } else { -1 };
        // Right of the segment seen from outside: clockwise, a negative turn about the normal.
        if cross[self.axis as usize] * outward < 0 {
            s
        } else {
            [s[1], s[0]]
        }
    }
}

/// The edge joining corners `a` and `b` (which differ in one axis).
fn edge_between(a: u8, b: u8) -> u8 {
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    let axis = (hi ^ lo).trailing_zeros() as u8;
    // Lower corner without the axis bit, then its two other bits in axis order.
    let (u, v) = match axis {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    };
    axis * 4 + ((lo >> u) & 1) + 2 * ((lo >> v) & 1)
}

/// True when edges `e` and `f` lie in a common face of the cube.
pub fn share_face(e: u8, f: u8) -> bool {
    Face::ALL.iter().any(|fc| fc.has_edge(e) && fc.has_edge(f))
}

/// Bit set of the crossing edges of `case`: edges with one inside and one outside corner.
pub fn crossing_edges(case: u8) -> u16 {
    let mut m = 0u16;
    for (e, [a, b]) in EDGE_CORNERS.iter().enumerate() {
        if ((case >> a) & 1) != ((case >> b) & 1) {
            m |= 1 << e;
        }
    }
    m
}

/// The closed loops of `case`: rules 1–3 chained, each rotated to start at a valid fan apex
/// (rule 4). Loops come in order of their smallest edge index.
pub fn case_loops(case: u8) -> Vec<Vec<u8>> {
    let mut next = [u8::MAX; 12];
    for f in Face::ALL {
        for [a, b] in f.segments(case) {
            debug_assert_eq!(next[a as usize], u8::MAX, "two segments start at edge {a}");
            next[a as usize] = b;
        }
    }
    let crossing = crossing_edges(case);
    let mut seen = 0u16;
    let mut loops = Vec::new();
    for start in 0..12u8 {
        if crossing & (1 << start) == 0 || seen & (1 << start) != 0 {
            continue;
        }
        let mut lp = Vec::new();
        let mut e = start;
        while e != u8::MAX && seen & (1 << e) == 0 {
            seen |= 1 << e;
            lp.push(e);
            e = next[e as usize];
        }
        debug_assert_eq!(e, start, "the segments of case {case} do not close");
        let n = lp.len();
        let apex = (0..n).find(|&r| {
            (0..n).all(|j| {
                j == r || j == (r + 1) % n || j == (r + n - 1) % n || !share_face(lp[r], lp[j])
            })
        });
        debug_assert!(apex.is_some(), "no valid fan apex in a loop of case {case}");
        lp.rotate_left(apex.unwrap_or(0));
        loops.push(lp);
    }
    loops
}

/// All cases, as built once.
struct Table {
    /// Triangles of every case, concatenated.
    tris: Vec<[u8; 3]>,
    /// Case `c`'s triangles are `tris[tri_start[c]..tri_start[c + 1]]`.
    tri_start: [u32; 257],
    /// The flat form: `flat_edges[flat_start[c]..flat_start[c + 1]]` are 3 edges a triangle.
    flat_start: Vec<u32>,
    /// Edge indices of all triangles, concatenated.
    flat_edges: Vec<u8>,
    /// Crossing edges of every case in order of first use by its triangles, concatenated.
    used: Vec<u8>,
    /// Case `c`'s used edges are `used[used_start[c]..used_start[c + 1]]`.
    used_start: [u32; 257],
}

fn generate() -> Table {
    let mut t = Table {
        tris: Vec::new(),
        tri_start: [0; 257],
        flat_start: Vec::with_capacity(257),
        flat_edges: Vec::new(),
        used: Vec::new(),
        used_start: [0; 257],
    };
    t.flat_start.push(0);
    for case in 0..=255u8 {
        for lp in case_loops(case) {
            for i in 1..lp.len() - 1 {
                let tri = [lp[0], lp[i], lp[i + 1]];
                t.tris.push(tri);
                t.flat_edges.extend_from_slice(&tri);
            }
        }
        let c = case as usize;
        t.tri_start[c + 1] = t.tris.len() as u32;
        t.flat_start.push(t.flat_edges.len() as u32);
        let mut have = 0u16;
        for &e in &t.flat_edges[t.flat_start[c] as usize..] {
            if have & (1 << e) == 0 {
                have |= 1 << e;
                t.used.push(e);
            }
        }
        t.used_start[c + 1] = t.used.len() as u32;
    }
    t
}

fn table() -> &'static Table {
    static TABLE: OnceLock<Table> = OnceLock::new();
    TABLE.get_or_init(generate)
}

/// The triangles of case `case` (bit `c` set when corner `c` is inside, value `< iso`), as
/// edge indices ([`EDGE_CORNERS`]), counter-clockwise seen from outside the surface.
pub fn case_triangles(case: u8) -> &'static [[u8; 3]] {
    let t = table();
    let c = case as usize;
    &t.tris[t.tri_start[c] as usize..t.tri_start[c + 1] as usize]
}

/// The crossing edges of case `case` in order of first use by [`case_triangles`]: the order
/// in which a cell creates its vertices. Every crossing edge is used.
pub fn case_edges(case: u8) -> &'static [u8] {
    let t = table();
    let c = case as usize;
    &t.used[t.used_start[c] as usize..t.used_start[c + 1] as usize]
}

/// The table in flat form, for upload to a GPU: `(offsets, edges)`, where `offsets` has 257
/// entries and case `c`'s triangles are the edge indices `edges[offsets[c]..offsets[c + 1]]`,
/// three per triangle, in the order of [`case_triangles`].
pub fn flat_table() -> (&'static [u32], &'static [u8]) {
    let t = table();
    (&t.flat_start, &t.flat_edges)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    #[test]
    fn edge_numbering_is_consistent() {
        for (e, [a, b]) in EDGE_CORNERS.iter().enumerate() {
            assert!(a < b);
            assert_eq!(b - a, 1 << EDGE_AXIS[e]);
            assert_eq!(edge_between(*a, *b), e as u8);
            assert_eq!(edge_between(*b, *a), e as u8);
            assert_eq!(EDGE_AXIS[e] as usize, e / 4);
        }
        for (c, o) in CORNER_OFFSETS.iter().enumerate() {
            assert_eq!(*o, [c as u8 & 1, (c as u8 >> 1) & 1, (c as u8 >> 2) & 1]);
        }
        // Each face holds 4 edges; each edge lies in 2 faces.
        for f in Face::ALL {
            assert_eq!((0..12).filter(|&e| f.has_edge(e)).count(), 4);
        }
        for e in 0..12 {
            assert_eq!(Face::ALL.iter().filter(|f| f.has_edge(e)).count(), 2);
        }
    }

    #[test]
    fn worked_example_of_the_docs() {
        assert_eq!(case_triangles(1), &[[0, 4, 8]]);
        assert_eq!(case_triangles(0), &[] as &[[u8; 3]]);
        assert_eq!(case_triangles(255), &[] as &[[u8; 3]]);
    }

    #[test]
    fn triangles_use_exactly_the_crossing_edges() {
        for case in 0..=255u8 {
            let crossing = crossing_edges(case);
            let mut used = 0u16;
            for t in case_triangles(case) {
                for &e in t {
                    assert!(
                        crossing & (1 << e) != 0,
                        "case {case}: edge {e} not crossing"
                    );
                    used |= 1 << e;
                }
                assert!(t[0] != t[1] && t[1] != t[2] && t[0] != t[2], "case {case}");
            }
            assert_eq!(used, crossing, "case {case}");
            let mut from_used = 0u16;
            for &e in case_edges(case) {
                from_used |= 1 << e;
            }
            assert_eq!(from_used, crossing);
            assert_eq!(case_edges(case).len(), crossing.count_ones() as usize);
        }
    }

    #[test]
    fn segments_chain_into_loops() {
        for case in 0..=255u8 {
            let mut starts = 0u16;
            let mut ends = 0u16;
            for f in Face::ALL {
                for [a, b] in f.segments(case) {
                    assert!(f.has_edge(a) && f.has_edge(b));
                    assert_eq!(starts & (1 << a), 0);
                    assert_eq!(ends & (1 << b), 0);
                    starts |= 1 << a;
                    ends |= 1 << b;
                }
            }
            assert_eq!(starts, crossing_edges(case), "case {case}");
            assert_eq!(ends, crossing_edges(case), "case {case}");
            let total: usize = case_loops(case).iter().map(Vec::len).sum();
            assert_eq!(total, crossing_edges(case).count_ones() as usize);
        }
    }

    /// The oriented triangle edges of `case` whose two ends lie in face `f`.
    fn face_pattern(case: u8, f: Face) -> BTreeSet<[u8; 2]> {
        let mut s = BTreeSet::new();
        for t in case_triangles(case) {
            for i in 0..3 {
                let (a, b) = (t[i], t[(i + 1) % 3]);
                if f.has_edge(a) && f.has_edge(b) {
                    assert!(s.insert([a, b]), "case {case}: edge {a}-{b} twice");
                }
            }
        }
        s
    }

    /// Map an edge of face `(axis, 1)` to the same grid edge seen from the cube above it, where
    /// it lies in face `(axis, 0)`.
    fn across(e: u8, axis: u8) -> u8 {
        let [a, b] = EDGE_CORNERS[e as usize];
        let bit = 1 << axis;
        edge_between(a & !bit, b & !bit)
    }

    #[test]
    fn neighbours_agree_on_every_shared_face() {
        for case in 0..=255u8 {
            for f in Face::ALL {
                let mine = face_pattern(case, f);
                let rule: BTreeSet<[u8; 2]> = f.segments(case).into_iter().collect();
                assert_eq!(mine, rule, "case {case} face {f:?}");
                if f.side == 0 {
                    continue;
                }
                // Every case of the cube above that has the same corners on the shared face.
                let bit = 1u8 << f.axis;
                let low = Face {
                    axis: f.axis,
                    side: 0,
                };
                for other in 0..=255u8 {
                    let same = (0..8u8)
                        .filter(|c| c & bit != 0)
                        .all(|c| (case >> c) & 1 == (other >> (c & !bit)) & 1);
                    if !same {
                        continue;
                    }
                    let theirs = face_pattern(other, low);
                    let mapped: BTreeSet<[u8; 2]> = mine
                        .iter()
                        .map(|&[a, b]| [across(b, f.axis), across(a, f.axis)])
                        .collect();
                    assert_eq!(mapped, theirs, "cases {case} / {other}, axis {}", f.axis);
                }
            }
        }
    }

    #[test]
    fn ambiguous_faces_keep_inside_corners_apart() {
        // Corners 0 and 3 inside, 1 and 2 outside on face z = 0.
        let f = Face { axis: 2, side: 0 };
        let segs = f.segments(0b1001);
        assert_eq!(segs.len(), 2);
        let mut ends: Vec<BTreeSet<u8>> =
            segs.iter().map(|s| s.iter().copied().collect()).collect();
        ends.sort();
        // Edges 0 (0-1) and 4 (0-2) cut off corner 0; 1 (2-3) and 5 (1-3) cut off corner 3.
        assert_eq!(ends, vec![BTreeSet::from([0, 4]), BTreeSet::from([1, 5])]);
    }

    #[test]
    fn fan_diagonals_never_lie_in_a_face() {
        for case in 0..=255u8 {
            for lp in case_loops(case) {
                let n = lp.len();
                for j in 2..n - 1 {
                    assert!(!share_face(lp[0], lp[j]), "case {case} loop {lp:?}");
                }
            }
        }
        // The case the docs name has such a loop; its apex is not its smallest edge.
        let lp = case_loops(0b1011_1001);
        assert_eq!(lp.len(), 1);
        assert_eq!(lp[0].len(), 7);
        assert_ne!(lp[0][0], *lp[0].iter().min().unwrap_or(&0));
        // Without the rotation, some fan diagonal would lie in a face.
        let mut naive = lp[0].clone();
        let start = naive
            .iter()
            .position(|&e| e == *lp[0].iter().min().unwrap_or(&0));
        naive.rotate_left(start.unwrap_or(0));
        assert!((2..6).any(|j| share_face(naive[0], naive[j])));
    }

    #[test]
    fn flat_table_matches_and_max_is_documented() {
        let (off, edges) = flat_table();
        assert_eq!(off.len(), 257);
        assert_eq!(off[256] as usize, edges.len());
        let mut max = 0;
        for case in 0..=255u8 {
            let c = case as usize;
            let flat = &edges[off[c] as usize..off[c + 1] as usize];
            let tris: Vec<u8> = case_triangles(case).iter().flatten().copied().collect();
            assert_eq!(flat, &tris[..]);
            max = max.max(case_triangles(case).len());
        }
        assert_eq!(max, MAX_CASE_TRIANGLES);
        // The shape of the table, as documented: cases by triangle count, loops by length.
        let mut tris = [0; 6];
        let mut loops = [0; 8];
        for case in 0..=255u8 {
            tris[case_triangles(case).len()] += 1;
            for l in case_loops(case) {
                loops[l.len()] += 1;
            }
        }
        assert_eq!(tris, [2, 16, 50, 80, 76, 32]);
        assert_eq!(loops, [0, 0, 0, 144, 66, 72, 52, 24]);
    }

    #[test]
    fn case_one_normal_points_away_from_the_inside_corner() {
        // Midpoints of edges 0, 4, 8 in doubled coordinates.
        let m = |e: u8| {
            let [a, b] = EDGE_CORNERS[e as usize];
            [0, 1, 2]
                .map(|d| (CORNER_OFFSETS[a as usize][d] + CORNER_OFFSETS[b as usize][d]) as i32)
        };
        for case in 0..=255u8 {
            for t in case_triangles(case) {
                let [a, b, c] = t.map(m);
                let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
                let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
                let nrm = [
                    u[1] * v[2] - u[2] * v[1],
                    u[2] * v[0] - u[0] * v[2],
                    u[0] * v[1] - u[1] * v[0],
                ];
                // The normal must point away from at least one inside corner in the direction
                // of the triangle, i.e. toward an outside corner: check the single-corner cases.
                if case.count_ones() == 1 {
                    let c0 = case.trailing_zeros() as usize;
                    let p = CORNER_OFFSETS[c0].map(|x| 2 * x as i32);
                    let w = [a[0] - p[0], a[1] - p[1], a[2] - p[2]];
                    assert!(
                        nrm[0] * w[0] + nrm[1] * w[1] + nrm[2] * w[2] > 0,
                        "case {case}"
                    );
                }
            }
        }
    }
}
