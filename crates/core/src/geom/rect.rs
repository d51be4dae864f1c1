//! The smallest-area rectangle enclosing a set of 2D points (Pauly & Gross 2001, §3: the
//! parameter domain of a patch's height field is the smallest rectangle holding the `(u, v)`
//! projections of its points).
//!
//! # Math
//!
//! A smallest-area enclosing rectangle has a side collinear with an edge of the convex hull
//! (Freeman & Shapira 1975). So: build the hull (Andrew's monotone chain, counter-clockwise,
//! collinear points dropped, after discarding the points strictly inside the octagon of the
//! extremes along ±x, ±y, ±(x+y), ±(x−y): Akl & Toussaint's throw-away step, which leaves a
//! small fraction of a patch's points to sort), then for each hull edge direction `e` measure the extents of the
//! hull along `e` and along `perp(e) = (-e.y, e.x)`. Rotating calipers (Toussaint 1983) keep
//! the three extreme vertices (furthest along `e`, along `perp(e)`, and against `e`) as
//! pointers that only advance as the edge turns counter-clockwise, so all edges cost `O(h)`
//! after the `O(n log n)` hull.
//!
//! # Convention
//!
//! [`Rect::axis`] is the unit direction of the *longer* side; coordinates of a point `p` in
//! the rectangle's frame are `(p·axis, p·perp(axis))` with `perp(a) = (-a[1], a[0])`, and
//! `lo`, `hi` are the extents of the points in that frame, so `hi[0] - lo[0] >= hi[1] - lo[1]`.
//! Example: the points `(0, 0)`, `(0, 3)`, `(1, 0)`, `(1, 3)` give `axis = (0, 1)`,
//! `perp(axis) = (-1, 0)`, `lo = (0, -1)`, `hi = (3, 0)`.
//!
//! Degenerate input stays valid: one point (or all equal) gives `axis = (1, 0)` and
//! `lo = hi` = the point; collinear points give the segment's direction and a zero second
//! extent; an empty slice gives the zero rectangle at the origin.

/// A rectangle in the plane: a rotated frame and the extents in it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rect {
    /// Unit direction of the first (longer) side.
    pub axis: [f64; 2],
    /// Lower corner in `(axis, perp(axis))` coordinates, `perp(a) = (-a[1], a[0])`.
    pub lo: [f64; 2],
    /// Upper corner in the same coordinates; `hi[0] - lo[0] >= hi[1] - lo[1]`.
    pub hi: [f64; 2],
}

impl Rect {
    /// The side lengths `hi - lo` (first >= second).
    pub fn size(&self) -> [f64; 2] {
        [self.hi[0] - self.lo[0], self.hi[1] - self.lo[1]]
    }

    /// The area.
    pub fn area(&self) -> f64 {
        let s = self.size();
        s[0] * s[1]
    }

    /// Coordinates of `p` in the rectangle's frame `(p·axis, p·perp(axis))`.
    pub fn to_frame(&self, p: [f64; 2]) -> [f64; 2] {
        let a = self.axis;
        [p[0] * a[0] + p[1] * a[1], -p[0] * a[1] + p[1] * a[0]]
    }
}

/// Reusable buffers of [`min_area_rect_with`].
#[derive(Debug, Default)]
pub struct RectWorkspace {
    /// The points sorted lexicographically.
    sorted: Vec<[f64; 2]>,
    /// The convex hull, counter-clockwise.
    hull: Vec<[f64; 2]>,
}

/// Smallest-area rectangle enclosing `pts` (finite coordinates). 1 or 2 points and collinear
/// points give a degenerate but valid rectangle. Allocates; see [`min_area_rect_with`].
pub fn min_area_rect(pts: &[[f64; 2]]) -> Rect {
    min_area_rect_with(&mut RectWorkspace::default(), pts)
}

/// [`min_area_rect`] with reusable buffers: `O(n log n)`.
pub fn min_area_rect_with(ws: &mut RectWorkspace, pts: &[[f64; 2]]) -> Rect {
    convex_hull(pts, &mut ws.sorted, &mut ws.hull);
    let hull = &ws.hull;
    match hull.len() {
        0 => Rect {
            axis: [1.0, 0.0],
            lo: [0.0; 2],
            hi: [0.0; 2],
        },
        1 => Rect {
            axis: [1.0, 0.0],
            lo: hull[0],
            hi: hull[0],
        },
        2 => frame_rect(hull, unit(sub(hull[1], hull[0])).unwrap_or([1.0, 0.0])),
        _ => frame_rect(hull, best_edge(hull)),
    }
}

/// The direction of the hull edge whose rectangle has the smallest area (rotating calipers).
fn best_edge(h: &[[f64; 2]]) -> [f64; 2] {
    let n = h.len();
    let at = |i: usize| h[i % n];
    let (mut right, mut top, mut left) = (1usize, 1usize, 1usize);
    let mut best = (f64::INFINITY, [1.0, 0.0]);
    for i in 0..n {
        let Some(e) = unit(sub(at(i + 1), at(i))) else {
            continue;
        };
        let nrm = [-e[1], e[0]];
        let along = |j: usize| dot(sub(at(j), at(i)), e);
        let up = |j: usize| dot(sub(at(j), at(i)), nrm);
        if i == 0 {
            right = 1;
        }
        right = right.max(i + 1);
        while right < i + 1 + n && along(right + 1) >= along(right) {
            right += 1;
        }
        if i == 0 {
            top = right;
        }
        top = top.max(right);
        while top < right + n && up(top + 1) >= up(top) {
            top += 1;
        }
        if i == 0 {
            left = top;
        }
        left = left.max(top);
        while left < top + n && along(left + 1) <= along(left) {
            left += 1;
        }
        let area = (along(right) - along(left)) * up(top);
        if area < best.0 {
            best = (area, e);
        }
    }
    best.1
}

/// The rectangle of the points in the frame of `dir`, its longer side first.
fn frame_rect(h: &[[f64; 2]], dir: [f64; 2]) -> Rect {
    let extents = |a: [f64; 2]| {
        let r = Rect {
            axis: a,
            lo: [f64::INFINITY; 2],
            hi: [f64::NEG_INFINITY; 2],
        };
        h.iter().fold(r, |mut r, &p| {
            let q = r.to_frame(p);
            for k in 0..2 {
                r.lo[k] = r.lo[k].min(q[k]);
                r.hi[k] = r.hi[k].max(q[k]);
            }
            r
        })
    };
    let r = extents(dir);
    let s = r.size();
    if s[0] >= s[1] {
        r
    } else {
        extents([-dir[1], dir[0]])
    }
}

/// Andrew's monotone chain: the hull counter-clockwise from the lowest-leftmost point,
/// collinear and repeated points dropped.
fn convex_hull(pts: &[[f64; 2]], sorted: &mut Vec<[f64; 2]>, hull: &mut Vec<[f64; 2]>) {
    sorted.clear();
    let octagon = extremes(pts);
    sorted.extend(pts.iter().filter(|&&p| !strictly_inside(&octagon, p)));
    sorted.sort_unstable_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    sorted.dedup();
    hull.clear();
    if sorted.len() < 3 {
        hull.extend_from_slice(sorted);
        return;
    }
    for &p in sorted.iter() {
        while hull.len() >= 2 && turn(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0 {
            hull.pop();
        }
        hull.push(p);
    }
    let lower = hull.len() + 1;
    for &p in sorted.iter().rev().skip(1) {
        while hull.len() >= lower && turn(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0 {
            hull.pop();
        }
        hull.push(p);
    }
    hull.pop();
}

/// The points extreme along ±x, ±y, ±(x+y), ±(x-y), counter-clockwise from the lowest: a
/// convex polygon inside the hull (Akl & Toussaint 1978), possibly with repeated corners.
fn extremes(pts: &[[f64; 2]]) -> [[f64; 2]; 8] {
    let Some(&first) = pts.first() else {
        return [[0.0; 2]; 8];
    };
    let dirs: [[f64; 2]; 8] = [
        [0.0, -1.0],
        [1.0, -1.0],
        [1.0, 0.0],
        [1.0, 1.0],
        [0.0, 1.0],
        [-1.0, 1.0],
        [-1.0, 0.0],
        [-1.0, -1.0],
    ];
    let mut best = [(f64::NEG_INFINITY, first); 8];
    for &p in pts {
        for (b, d) in best.iter_mut().zip(dirs) {
            let v = dot(p, d);
            if v > b.0 {
                *b = (v, p);
            }
        }
    }
    best.map(|b| b.1)
}

/// Whether `p` lies strictly inside the convex polygon `poly` (counter-clockwise, repeated
/// corners allowed); `false` for a polygon of under three distinct corners.
fn strictly_inside(poly: &[[f64; 2]; 8], p: [f64; 2]) -> bool {
    let mut edges = 0;
    for k in 0..8 {
        let (a, b) = (poly[k], poly[(k + 1) % 8]);
        if a == b {
            continue;
        }
        if turn(a, b, p) <= 0.0 {
            return false;
        }
        edges += 1;
    }
    edges >= 3
}

/// Twice the signed area of `a, b, c`: positive for a counter-clockwise turn.
fn turn(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

fn unit(a: [f64; 2]) -> Option<[f64; 2]> {
    let l = dot(a, a).sqrt();
    (l > 1e-300 && l.is_finite()).then(|| [a[0] / l, a[1] / l])
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    /// Brute force: every pair of points as a side direction (a superset of the hull edges).
    fn brute_area(p: &[[f64; 2]]) -> f64 {
        let mut best = f64::INFINITY;
        for i in 0..p.len() {
            for j in 0..p.len() {
                if let Some(e) = unit(sub(p[j], p[i])) {
                    best = best.min(area_in(p, e));
                }
            }
        }
        best
    }

    fn area_in(p: &[[f64; 2]], e: [f64; 2]) -> f64 {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for &q in p {
            let c = [dot(q, e), dot(q, [-e[1], e[0]])];
            for k in 0..2 {
                lo[k] = lo[k].min(c[k]);
                hi[k] = hi[k].max(c[k]);
            }
        }
        (hi[0] - lo[0]) * (hi[1] - lo[1])
    }

    fn random_set(rng: &mut Pcg64, n: usize) -> Vec<[f64; 2]> {
        let (a, b) = (rng.random_range(0.1..3.0), rng.random_range(0.1..3.0));
        let rot = rng.random_range(0.0..std::f64::consts::PI);
        let (s, c) = rot.sin_cos();
        let disc = rng.random_bool(0.5);
        (0..n)
            .map(|_| {
                let (mut x, mut y) = (rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
                if disc {
                    while x * x + y * y > 1.0 {
                        x = rng.random_range(-1.0..1.0);
                        y = rng.random_range(-1.0..1.0);
                    }
                }
                let (x, y) = (a * x, b * y);
                [c * x - s * y + 5.0, s * x + c * y - 2.0]
            })
            .collect()
    }

    fn check_holds(r: &Rect, p: &[[f64; 2]]) {
        let s = r.size();
        assert!(s[0] >= s[1]);
        assert!((r.axis[0].hypot(r.axis[1]) - 1.0).abs() < 1e-12);
        for &q in p {
            let f = r.to_frame(q);
            for k in 0..2 {
                assert!(
                    f[k] >= r.lo[k] - 1e-9 && f[k] <= r.hi[k] + 1e-9,
                    "{q:?} outside {r:?}"
                );
            }
        }
    }

    #[test]
    fn min_area_rect_matches_brute_force_over_point_pairs() {
        let mut rng = Pcg64::seed_from_u64(1);
        for trial in 0..200 {
            let n = 3 + trial % 60;
            let p = random_set(&mut rng, n);
            let r = min_area_rect(&p);
            check_holds(&r, &p);
            let want = brute_area(&p);
            assert!(
                (r.area() - want).abs() <= 1e-9 * want.max(1.0),
                "trial {trial}: {} vs {want}",
                r.area()
            );
        }
    }

    #[test]
    fn min_area_rect_beats_a_fine_angle_sweep() {
        let mut rng = Pcg64::seed_from_u64(2);
        for _ in 0..20 {
            let p = random_set(&mut rng, 400);
            let r = min_area_rect(&p);
            check_holds(&r, &p);
            let sweep = (0..18_000)
                .map(|k| {
                    let t = k as f64 * std::f64::consts::PI / 36_000.0;
                    area_in(&p, [t.cos(), t.sin()])
                })
                .fold(f64::INFINITY, f64::min);
            assert!(r.area() <= sweep * (1.0 + 1e-12));
            assert!(r.area() >= sweep * (1.0 - 1e-3));
        }
    }

    #[test]
    fn min_area_rect_follows_the_documented_convention() {
        let r = min_area_rect(&[[0.0, 0.0], [0.0, 3.0], [1.0, 0.0], [1.0, 3.0], [0.5, 1.0]]);
        assert_eq!(r.axis, [0.0, 1.0]);
        assert_eq!(r.lo, [0.0, -1.0]);
        assert_eq!(r.hi, [3.0, 0.0]);
    }

    #[test]
    fn min_area_rect_of_degenerate_sets_is_valid() {
        let r = min_area_rect(&[]);
        assert_eq!(r.area(), 0.0);
        let r = min_area_rect(&[[2.0, 3.0], [2.0, 3.0]]);
        assert_eq!((r.axis, r.lo, r.hi), ([1.0, 0.0], [2.0, 3.0], [2.0, 3.0]));
        let line: Vec<[f64; 2]> = (0..10)
            .map(|i| [1.0 + i as f64, 2.0 - 2.0 * i as f64])
            .collect();
        let r = min_area_rect(&line);
        check_holds(&r, &line);
        assert!(r.size()[1].abs() < 1e-12);
        assert!((r.size()[0] - 9.0 * 5f64.sqrt()).abs() < 1e-9);
        let two = [[0.0, 0.0], [3.0, 4.0]];
        let r = min_area_rect(&two);
        check_holds(&r, &two);
        assert!((r.size()[0] - 5.0).abs() < 1e-12);
    }

    #[test]
    fn min_area_rect_of_a_rotated_grid_finds_its_rotation() {
        let (s, c) = 0.3f64.sin_cos();
        let p: Vec<[f64; 2]> = (0..20)
            .flat_map(|i| (0..7).map(move |j| (i as f64, j as f64)))
            .map(|(x, y)| [c * x - s * y, s * x + c * y])
            .collect();
        let r = min_area_rect(&p);
        assert!((r.area() - 19.0 * 6.0).abs() < 1e-9);
        assert!((r.axis[0].abs() - c).abs() < 1e-12 && (r.axis[1].abs() - s).abs() < 1e-12);
    }

    /// Throughput on patch-sized sets (run with `--ignored --nocapture`).
    #[test]
    #[ignore]
    fn min_area_rect_speed_on_patches() {
        let mut rng = Pcg64::seed_from_u64(3);
        let sets: Vec<Vec<[f64; 2]>> = (0..200).map(|_| random_set(&mut rng, 1000)).collect();
        let mut ws = RectWorkspace::default();
        let t = std::time::Instant::now();
        let mut area = 0.0;
        for p in &sets {
            area += min_area_rect_with(&mut ws, p).area();
        }
        let ns = t.elapsed().as_nanos() as f64 / (200.0 * 1000.0);
        println!("min_area_rect: {ns:.1} ns/point on 1000-point sets (sum of areas {area:.3})");
    }
}
