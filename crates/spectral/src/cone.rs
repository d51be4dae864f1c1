//! Normal cones: the smallest spherical cap that holds a set of unit normals (Pauly & Gross
//! 2001, §3, the normal-cone condition of the patch layout).
//!
//! A patch can be written as a height field over a plane only if no normal turns by a right
//! angle or more away from the plane's normal. The paper bounds this by the patch's *normal
//! cone*: the cap of the unit sphere `{x : axis·x >= cos θ}` of half angle `θ` that contains
//! every normal; the condition is an aperture `2θ <= π/2`.
//!
//! # The smallest cap is a minimum-norm problem
//!
//! For `θ < π/2` write `w = axis / cos θ`. A normal `n` lies in the cap iff `w·n >= 1`, and
//! `|w| = 1 / cos θ`, so the smallest cap is the point of smallest norm of the polyhedron
//! `{w : w·nᵢ >= 1 ∀i}`. That polyhedron is non-empty iff the normals lie in an *open*
//! hemisphere; otherwise no cap of half angle `< π/2` exists and [`enclosing_cone`] returns
//! `None`. The problem is LP-type of combinatorial dimension 3: the optimum is fixed by at
//! most three normals on its boundary circle, which gives the caps through one normal (the
//! normal itself), two (axis on the bisector, `θ` half their angle) and three (the circle
//! through them: axis the normal of their plane, turned towards them).
//!
//! # Algorithm
//!
//! Welzl's randomized incremental algorithm in its iterative form, three nested loops as for
//! the smallest enclosing circle in the plane: expected `O(n)` on a random order. The order
//! is a Fisher–Yates shuffle driven by a fixed-seed xorshift, so the result depends on the
//! input slice only. A last pass widens the cap, if rounding left any normal outside, to the
//! smallest dot product with the axis, so the returned cap contains every normal as computed
//! in `f64`; a cap whose half angle reaches `π/2` there is reported as `None`.
//!
//! [`merge_cones`] bounds the cone of a union in `O(1)`: the smallest cap holding two caps has
//! half angle `(θa + θb + d) / 2` (with `d` the angle between the axes) and its axis on the
//! great circle through both axes, unless one cap already holds the other.

use std::f64::consts::PI;

/// A spherical cap of the unit sphere: every direction within `half_angle` of `axis`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cone {
    /// Unit axis (the cap's centre on the sphere).
    pub axis: [f64; 3],
    /// Half opening angle, radians, in `[0, π]`. The cone's *aperture* is twice this.
    pub half_angle: f64,
}

impl Cone {
    /// The full opening angle `2·half_angle`, radians.
    pub fn aperture(&self) -> f64 {
        2.0 * self.half_angle
    }

    /// Whether unit direction `n` lies in the cap, with an angular slack of `tol_rad`.
    pub fn contains(&self, n: [f64; 3], tol_rad: f64) -> bool {
        angle(self.axis, n) <= self.half_angle + tol_rad
    }
}

/// Reusable buffers of [`enclosing_cone_with`].
#[derive(Debug, Default)]
pub struct ConeWorkspace {
    /// Unit normals of the current call, in shuffled order.
    pts: Vec<[f64; 3]>,
}

impl ConeWorkspace {
    /// The number of normals (non-zero, finite) the last call of [`enclosing_cone_with`] used.
    pub fn used(&self) -> usize {
        self.pts.len()
    }
}

/// Smallest cap containing every normal `normals[i]` for `i` in `idx` (zero normals skipped).
/// `None` when the normals are not within an open hemisphere (no cap of half angle `< π/2`),
/// or `idx` has no non-zero normal. Allocates a workspace; see [`enclosing_cone_with`].
pub fn enclosing_cone(normals: &[[f32; 3]], idx: &[u32]) -> Option<Cone> {
    enclosing_cone_with(&mut ConeWorkspace::default(), normals, idx)
}

/// [`enclosing_cone`] with reusable buffers. Normals need not be unit length: each non-zero,
/// finite normal is normalised; a zero or non-finite one is skipped.
pub fn enclosing_cone_with(
    ws: &mut ConeWorkspace,
    normals: &[[f32; 3]],
    idx: &[u32],
) -> Option<Cone> {
    ws.pts.clear();
    for &i in idx {
        if let Some(u) = unit_f32(normals[i as usize]) {
            ws.pts.push(u);
        }
    }
    shuffle(&mut ws.pts);
    smallest_cap(&ws.pts)
}

/// Smallest cap containing two caps: `O(1)`, an upper bound of the exact cone of the union of
/// the normals the two caps were built from. The half angle is capped at `π`.
pub fn merge_cones(a: &Cone, b: &Cone) -> Cone {
    let d = angle(a.axis, b.axis);
    if d + b.half_angle <= a.half_angle {
        return *a;
    }
    if d + a.half_angle <= b.half_angle {
        return *b;
    }
    let half = 0.5 * (a.half_angle + b.half_angle + d);
    if half >= PI {
        return Cone {
            axis: a.axis,
            half_angle: PI,
        };
    }
    // Turn a's axis towards b's by `half - θa` along the great circle through both.
    let t = half - a.half_angle;
    let c = dot(a.axis, b.axis);
    let e = sub(b.axis, scale(a.axis, c));
    let e = normalize(e).unwrap_or_else(|| any_perpendicular(a.axis));
    let axis = normalize(add(scale(a.axis, t.cos()), scale(e, t.sin()))).unwrap_or(a.axis);
    Cone {
        axis,
        half_angle: half,
    }
}

/// Welzl's iteration over unit vectors in the given order (the caller shuffles).
fn smallest_cap(p: &[[f64; 3]]) -> Option<Cone> {
    let first = *p.first()?;
    // A cap as (axis, cos of half angle); membership `axis·x >= cos - EPS`.
    let mut cap = (first, 1.0);
    for i in 1..p.len() {
        if inside(cap, p[i]) {
            continue;
        }
        cap = (p[i], 1.0);
        for j in 0..i {
            if inside(cap, p[j]) {
                continue;
            }
            cap = cap2(p[i], p[j])?;
            for k in 0..j {
                if !inside(cap, p[k]) {
                    cap = cap3(p[i], p[j], p[k])?;
                }
            }
        }
    }
    // Widen to what rounding left outside, so the cap holds every vector as computed.
    let cos = p.iter().fold(cap.1, |m, &x| m.min(dot(cap.0, x)));
    if cos <= 0.0 {
        return None;
    }
    Some(Cone {
        axis: cap.0,
        half_angle: cos.min(1.0).acos(),
    })
}

/// Slack of the membership test in the incremental loops (on cosines).
const EPS: f64 = 1e-12;

fn inside(cap: ([f64; 3], f64), x: [f64; 3]) -> bool {
    dot(cap.0, x) >= cap.1 - EPS
}

/// The smallest cap through two unit vectors; `None` if they are (nearly) antipodal.
fn cap2(a: [f64; 3], b: [f64; 3]) -> Option<([f64; 3], f64)> {
    let axis = normalize(add(a, b))?;
    Some((axis, dot(axis, a).min(dot(axis, b))))
}

/// The smallest cap holding three unit vectors with the first two on its boundary: the circle
/// through all three, or, where they are (nearly) on one great circle, the best cap through a
/// pair that holds the third. `None` if no cap under a hemisphere holds them.
fn cap3(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> Option<([f64; 3], f64)> {
    let n = cross(sub(b, a), sub(c, a));
    let len = norm(n);
    if len > 1e-14 {
        let mut axis = scale(n, 1.0 / len);
        if dot(axis, a) < 0.0 {
            axis = scale(axis, -1.0);
        }
        let cos = dot(axis, a).min(dot(axis, b)).min(dot(axis, c));
        if cos > 0.0 {
            return Some((axis, cos));
        }
        return None;
    }
    let mut best: Option<([f64; 3], f64)> = None;
    for (x, y, z) in [(a, b, c), (a, c, b), (b, c, a)] {
        if let Some(cap) = cap2(x, y)
            && inside(cap, z)
            && best.is_none_or(|bc| cap.1 > bc.1)
        {
            best = Some(cap);
        }
    }
    best
}

/// Fisher–Yates with a fixed-seed xorshift64*: the same permutation for the same length.
fn shuffle<T>(v: &mut [T]) {
    let mut s: u64 = 0x9E37_79B9_7F4A_7C15;
    for i in (1..v.len()).rev() {
        s ^= s >> 12;
        s ^= s << 25;
        s ^= s >> 27;
        let r = s.wrapping_mul(0x2545_F491_4F6C_DD1D);
        let j = ((r >> 32) * (i as u64 + 1)) >> 32;
        v.swap(i, j as usize);
    }
}

/// The normal as a unit `f64` vector, or `None` if it is zero or not finite.
pub(crate) fn unit_f32(n: [f32; 3]) -> Option<[f64; 3]> {
    let v = [f64::from(n[0]), f64::from(n[1]), f64::from(n[2])];
    if !v.iter().all(|c| c.is_finite()) {
        return None;
    }
    normalize(v)
}

/// The angle between two unit vectors, accurate near 0 and π (unlike `acos` of the dot).
pub(crate) fn angle(a: [f64; 3], b: [f64; 3]) -> f64 {
    norm(cross(a, b)).atan2(dot(a, b))
}

fn any_perpendicular(a: [f64; 3]) -> [f64; 3] {
    let t = if a[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    normalize(cross(a, t)).unwrap_or([0.0, 0.0, 1.0])
}

pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

pub(crate) fn normalize(a: [f64; 3]) -> Option<[f64; 3]> {
    let l = norm(a);
    (l > 1e-300 && l.is_finite()).then(|| scale(a, 1.0 / l))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    fn random_unit(rng: &mut Pcg64) -> [f64; 3] {
        loop {
            let v = [
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ];
            let l = norm(v);
            if l > 0.1 && l <= 1.0 {
                return scale(v, 1.0 / l);
            }
        }
    }

    /// Normals in a cap of half angle `spread` around a random axis.
    fn cluster(rng: &mut Pcg64, n: usize, spread: f64) -> Vec<[f32; 3]> {
        let axis = random_unit(rng);
        let e1 = any_perpendicular(axis);
        let e2 = cross(axis, e1);
        (0..n)
            .map(|_| {
                let t = rng.random_range(0.0..spread);
                let phi = rng.random_range(0.0..2.0 * PI);
                let v = add(
                    scale(axis, t.cos()),
                    add(
                        scale(e1, t.sin() * phi.cos()),
                        scale(e2, t.sin() * phi.sin()),
                    ),
                );
                [v[0] as f32, v[1] as f32, v[2] as f32]
            })
            .collect()
    }

    /// Brute force: the smallest of all caps through 1, 2 and 3 of the points that hold them all.
    fn brute(p: &[[f64; 3]]) -> Option<f64> {
        let holds = |cap: ([f64; 3], f64)| p.iter().all(|&x| dot(cap.0, x) >= cap.1 - 1e-9);
        let mut best: Option<f64> = None;
        let mut take = |cap: ([f64; 3], f64)| {
            if cap.1 > 0.0 && holds(cap) {
                let h = cap.1.min(1.0).acos();
                best = Some(best.map_or(h, |b: f64| b.min(h)));
            }
        };
        for i in 0..p.len() {
            take((p[i], 1.0));
            for j in i + 1..p.len() {
                if let Some(c) = cap2(p[i], p[j]) {
                    take(c);
                }
                for k in j + 1..p.len() {
                    let n = cross(sub(p[j], p[i]), sub(p[k], p[i]));
                    if let Some(mut axis) = normalize(n) {
                        if dot(axis, p[i]) < 0.0 {
                            axis = scale(axis, -1.0);
                        }
                        take((axis, dot(axis, p[i])));
                    }
                }
            }
        }
        best
    }

    fn units(n: &[[f32; 3]]) -> Vec<[f64; 3]> {
        n.iter().filter_map(|&v| unit_f32(v)).collect()
    }

    #[test]
    fn enclosing_cone_matches_brute_force_on_random_sets() {
        let mut rng = Pcg64::seed_from_u64(7);
        for trial in 0..300 {
            let n = 1 + trial % 25;
            let spread = rng.random_range(0.01..1.5);
            let normals = cluster(&mut rng, n, spread);
            let idx: Vec<u32> = (0..n as u32).collect();
            let got = enclosing_cone(&normals, &idx);
            let want = brute(&units(&normals));
            match (got, want) {
                (Some(c), Some(w)) => {
                    assert!(
                        (c.half_angle - w).abs() < 1e-7,
                        "trial {trial}: {} vs {w}",
                        c.half_angle
                    );
                    for u in units(&normals) {
                        assert!(dot(c.axis, u) >= c.half_angle.cos() - 1e-12);
                    }
                }
                (None, None) => {}
                other => panic!("trial {trial}: {other:?}"),
            }
        }
    }

    #[test]
    fn enclosing_cone_contains_every_normal_of_large_sets() {
        let mut rng = Pcg64::seed_from_u64(11);
        let normals = cluster(&mut rng, 5000, 0.7);
        let idx: Vec<u32> = (0..5000).collect();
        let c = enclosing_cone(&normals, &idx).expect("a cone");
        assert!(c.half_angle <= 0.7 + 1e-6);
        for u in units(&normals) {
            assert!(dot(c.axis, u) >= c.half_angle.cos());
        }
    }

    #[test]
    fn enclosing_cone_is_none_outside_an_open_hemisphere() {
        let n = [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        assert_eq!(enclosing_cone(&n, &[0, 1, 2]), None);
        // Four normals around the equator and one pole: no open hemisphere holds them.
        let n = [
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        assert_eq!(enclosing_cone(&n, &[0, 1, 2, 3, 4]), None);
        let mut rng = Pcg64::seed_from_u64(3);
        let all: Vec<[f32; 3]> = (0..200)
            .map(|_| {
                let v = random_unit(&mut rng);
                [v[0] as f32, v[1] as f32, v[2] as f32]
            })
            .collect();
        let idx: Vec<u32> = (0..200).collect();
        assert_eq!(enclosing_cone(&all, &idx), None);
    }

    #[test]
    fn enclosing_cone_skips_zero_normals_and_uses_only_idx() {
        let n = [
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 2.0],
            [-1.0, 0.0, 0.0],
            [1.0, 0.0, 1.0],
        ];
        assert_eq!(enclosing_cone(&n, &[0]), None);
        assert_eq!(enclosing_cone(&n, &[]), None);
        let c = enclosing_cone(&n, &[0, 1]).expect("one normal");
        assert_eq!(c.half_angle, 0.0);
        let c = enclosing_cone(&n, &[1, 3]).expect("two normals");
        assert!((c.half_angle - PI / 8.0).abs() < 1e-12);
        assert!((c.axis[2] - (PI / 8.0).cos()).abs() < 1e-12);
    }

    #[test]
    fn enclosing_cone_is_deterministic() {
        let mut rng = Pcg64::seed_from_u64(5);
        let normals = cluster(&mut rng, 777, 1.2);
        let idx: Vec<u32> = (0..777).rev().collect();
        let a = enclosing_cone(&normals, &idx).expect("cone");
        let b = enclosing_cone(&normals, &idx).expect("cone");
        assert_eq!(a.axis.map(f64::to_bits), b.axis.map(f64::to_bits));
        assert_eq!(a.half_angle.to_bits(), b.half_angle.to_bits());
    }

    #[test]
    fn merge_cones_holds_both_caps_and_is_tight() {
        let mut rng = Pcg64::seed_from_u64(9);
        for _ in 0..500 {
            let a = Cone {
                axis: random_unit(&mut rng),
                half_angle: rng.random_range(0.0..1.2),
            };
            let b = Cone {
                axis: random_unit(&mut rng),
                half_angle: rng.random_range(0.0..1.2),
            };
            let m = merge_cones(&a, &b);
            assert!((norm(m.axis) - 1.0).abs() < 1e-12);
            // Each cap lies inside: its axis' angle to m's plus its half angle fits.
            for c in [a, b] {
                let d = angle(m.axis, c.axis);
                assert!(
                    d + c.half_angle <= m.half_angle + 1e-9,
                    "{a:?} {b:?} -> {m:?}"
                );
            }
            // Tight: the larger cap when it holds the other, else the closed form.
            let d = angle(a.axis, b.axis);
            let want = if d + a.half_angle <= b.half_angle {
                b.half_angle
            } else if d + b.half_angle <= a.half_angle {
                a.half_angle
            } else {
                0.5 * (a.half_angle + b.half_angle + d)
            };
            assert!((m.half_angle - want.min(PI)).abs() < 1e-12);
        }
    }

    #[test]
    fn merge_cones_bounds_the_exact_cone_of_the_union() {
        let mut rng = Pcg64::seed_from_u64(13);
        for _ in 0..100 {
            let mut n = cluster(&mut rng, 30, 0.4);
            let mut second = cluster(&mut rng, 30, 0.4);
            n.append(&mut second);
            let lo: Vec<u32> = (0..30).collect();
            let hi: Vec<u32> = (30..60).collect();
            let all: Vec<u32> = (0..60).collect();
            let (Some(a), Some(b)) = (enclosing_cone(&n, &lo), enclosing_cone(&n, &hi)) else {
                panic!("cones of clusters");
            };
            let m = merge_cones(&a, &b);
            if let Some(exact) = enclosing_cone(&n, &all) {
                assert!(exact.half_angle <= m.half_angle + 1e-9);
            } else {
                assert!(m.half_angle >= PI / 2.0 - 1e-9);
            }
        }
    }

    /// Throughput on patch-sized sets (run with `--ignored --nocapture`).
    #[test]
    #[ignore]
    fn enclosing_cone_speed_on_patches() {
        let mut rng = Pcg64::seed_from_u64(17);
        let normals = cluster(&mut rng, 200_000, 0.7);
        let mut ws = ConeWorkspace::default();
        let idx: Vec<u32> = (0..200_000).collect();
        let t = std::time::Instant::now();
        let mut sum = 0.0;
        for chunk in idx.chunks(1000) {
            sum += enclosing_cone_with(&mut ws, &normals, chunk).map_or(0.0, |c| c.half_angle);
        }
        let ns = t.elapsed().as_nanos() as f64 / 200_000.0;
        println!("enclosing_cone: {ns:.1} ns/normal on 1000-normal sets (sum {sum:.3})");
    }
}
