//! The uniform cubic B-spline and its refinement, and knot insertion into any knot vector.
//!
//! # The uniform cubic B-spline
//!
//! `N(t)` has knots `0, 1, 2, 3, 4` and is a cubic polynomial on each unit interval; a
//! function of level `l` is `B_i(u) = N(u / h_l - i)` with knot spacing `h_l = h_0 / 2^l`
//! (Greiner & Hormann 1997, §5). On the cell `[c h, (c + 1) h)` with local coordinate
//! `s = u / h - c ∈ [0, 1)`, the four functions `i = c - 3, …, c` are nonzero and equal
//!
//! ```text
//! b0 = (1 - s)³ / 6,  b1 = (3s³ - 6s² + 4) / 6,  b2 = (-3s³ + 3s² + 3s + 1) / 6,  b3 = s³ / 6
//! ```
//!
//! (they sum to 1). Derivatives in `u` carry `1/h` per order.
//!
//! # Refinement
//!
//! `N(t) = Σ_j w_j N(2t - j)` with `w = (1, 4, 6, 4, 1) / 8`: a level-`l` function is exactly
//! the combination `B^l_i = Σ_j w_j B^{l+1}_{2i+j}`.
//!
//! # Knot insertion (the Oslo algorithm)
//!
//! A B-spline `N_{t}` of degree 3 on knots `t_0 ≤ … ≤ t_4` is, on any refined knot vector `τ`
//! that contains `t_0, …, t_4`, the combination `Σ_j α_j N_{τ, j}` of the B-splines of `τ`,
//! with the discrete B-splines (Cohen, Lyche & Riesenfeld 1980)
//!
//! ```text
//! α⁰_i(j) = [t_i ≤ τ_j < t_{i+1}]
//! αᵏ_i(j) = (τ_{j+k} - t_i) / (t_{i+k} - t_i) · αᵏ⁻¹_i(j)
//!         + (t_{i+k+1} - τ_{j+k}) / (t_{i+k+1} - t_{i+1}) · αᵏ⁻¹_{i+1}(j)
//! ```
//!
//! (a term with a zero denominator is zero), and `α_j = α³_0(j)`. [`oslo`] computes them.

/// The four nonzero uniform cubic B-splines at local coordinate `s ∈ [0, 1]` of a cell, and
/// their first and second derivatives in `s` (`[value, d/ds, d²/ds²]`, each `[b0, b1, b2, b3]`
/// for the functions `c - 3, …, c`).
pub fn cubic(s: f64) -> [[f64; 4]; 3] {
    let t = 1.0 - s;
    let s2 = s * s;
    let s3 = s2 * s;
    [
        [
            t * t * t / 6.0,
            (3.0 * s3 - 6.0 * s2 + 4.0) / 6.0,
            (-3.0 * s3 + 3.0 * s2 + 3.0 * s + 1.0) / 6.0,
            s3 / 6.0,
        ],
        [
            -0.5 * t * t,
            1.5 * s2 - 2.0 * s,
            -1.5 * s2 + s + 0.5,
            0.5 * s2,
        ],
        [t, 3.0 * s - 2.0, -3.0 * s + 1.0, s],
    ]
}

/// The refinement mask of the uniform cubic B-spline: `B^l_i = Σ_j MASK[j] B^{l+1}_{2i+j}`.
pub const MASK: [f64; 5] = [0.125, 0.5, 0.75, 0.5, 0.125];

/// Four-point Gauss–Legendre nodes on `[0, 1]` and their weights (exact for degree 7).
pub const GAUSS4: [(f64, f64); 4] = [
    (0.069_431_844_202_973_71, 0.173_927_422_568_726_93),
    (0.330_009_478_207_571_87, 0.326_072_577_431_273_07),
    (0.669_990_521_792_428_1, 0.326_072_577_431_273_07),
    (0.930_568_155_797_026_3, 0.173_927_422_568_726_93),
];

/// The coefficients of the cubic B-spline with knots `t` in the basis of the refined knot
/// vector `tau` (which must contain every `t_i` with at least its multiplicity in `t`):
/// `(first, α)` with `N_t = Σ_k α[k] N_{tau, first + k}`, zeros trimmed from both ends.
pub fn oslo(t: &[f64; 5], tau: &[f64]) -> (usize, Vec<f64>) {
    // Only the B-splines of tau with support inside [t0, t4] take part: τ_j ≥ t0 and
    // τ_{j+4} ≤ t4.
    let first = tau.partition_point(|&x| x < t[0]);
    let end = tau
        .partition_point(|&x| x <= t[4])
        .saturating_sub(4)
        .max(first);
    let mut out = Vec::with_capacity(end.saturating_sub(first));
    for j in first..end {
        // α⁰ for the four degree-0 pieces of t at τ_j, raised to degree 3.
        let mut a = [0.0f64; 4];
        for (i, ai) in a.iter_mut().enumerate() {
            if t[i] <= tau[j] && tau[j] < t[i + 1] {
                *ai = 1.0;
            }
        }
        for k in 1..=3 {
            for i in 0..4 - k {
                let tj = |m: usize| tau[j + m];
                let left = if t[i + k] > t[i] {
                    (tj(k) - t[i]) / (t[i + k] - t[i]) * a[i]
                } else {
                    0.0
                };
                let right = if t[i + k + 1] > t[i + 1] {
                    (t[i + k + 1] - tj(k)) / (t[i + k + 1] - t[i + 1]) * a[i + 1]
                } else {
                    0.0
                };
                a[i] = left + right;
            }
        }
        out.push(a[0]);
    }
    let lead = out.iter().take_while(|&&x| x == 0.0).count();
    let trail = out.iter().rev().take_while(|&&x| x == 0.0).count();
    if lead == out.len() {
        return (first, Vec::new());
    }
    out.truncate(out.len() - trail);
    (first + lead, out.split_off(lead))
}

/// The value of the cubic B-spline with knots `t` at `u` (Cox–de Boor), for tests and for
/// checking conversions.
pub fn cox_de_boor(t: &[f64], u: f64) -> f64 {
    let p = t.len() - 2;
    let mut n: Vec<f64> = (0..=p)
        .map(|i| f64::from(u8::from(t[i] <= u && u < t[i + 1])))
        .collect();
    for k in 1..=p {
        for i in 0..=p - k {
            let a = if t[i + k] > t[i] {
                (u - t[i]) / (t[i + k] - t[i]) * n[i]
            } else {
                0.0
            };
            let b = if t[i + k + 1] > t[i + 1] {
                (t[i + k + 1] - u) / (t[i + k + 1] - t[i + 1]) * n[i + 1]
            } else {
                0.0
            };
            n[i] = a + b;
        }
    }
    n[0]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cubic_pieces_match_cox_de_boor_and_derivatives() {
        for k in 0..=20 {
            let s = k as f64 / 20.0 * 0.999;
            let [v, d, dd] = cubic(s);
            assert!((v.iter().sum::<f64>() - 1.0).abs() < 1e-15);
            for (m, &vm) in v.iter().enumerate() {
                // Function c-3+m on knots 0..4 shifted: its local argument is s + 3 - m.
                let t = [0.0, 1.0, 2.0, 3.0, 4.0];
                let x = s + 3.0 - m as f64;
                assert!((cox_de_boor(&t, x) - vm).abs() < 1e-14);
                let e = 1e-5;
                let fd = (cox_de_boor(&t, x + e) - cox_de_boor(&t, x - e)) / (2.0 * e);
                assert!((fd - d[m]).abs() < 1e-8, "d {m} {s}");
                let fdd = (cox_de_boor(&t, x + e) - 2.0 * cox_de_boor(&t, x)
                    + cox_de_boor(&t, x - e))
                    / (e * e);
                assert!((fdd - dd[m]).abs() < 1e-4, "dd {m} {s}");
            }
        }
    }

    #[test]
    fn refinement_mask_reproduces_the_coarse_function() {
        let t = [0.0, 1.0, 2.0, 3.0, 4.0];
        for k in 0..80 {
            let x = k as f64 * 0.05;
            let fine: f64 = MASK
                .iter()
                .enumerate()
                .map(|(j, w)| w * cox_de_boor(&t, 2.0 * x - j as f64))
                .sum();
            assert!((fine - cox_de_boor(&t, x)).abs() < 1e-14);
        }
    }

    #[test]
    fn oslo_expansion_equals_the_function_on_irregular_refinements() {
        let t = [0.0, 2.0, 4.0, 6.0, 8.0];
        let taus: [Vec<f64>; 3] = [
            vec![-2.0, 0.0, 1.0, 2.0, 3.0, 4.0, 6.0, 7.0, 8.0, 10.0, 12.0],
            vec![0.0, 0.0, 0.0, 2.0, 3.0, 3.5, 4.0, 6.0, 8.0, 8.0, 8.0, 8.0],
            vec![-6.0, -4.0, -2.0, 0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0],
        ];
        for tau in &taus {
            let (first, a) = oslo(&t, tau);
            for k in 0..160 {
                let x = k as f64 * 0.05;
                let sum: f64 = a
                    .iter()
                    .enumerate()
                    .map(|(m, am)| am * cox_de_boor(&tau[first + m..first + m + 5], x))
                    .sum();
                assert!((sum - cox_de_boor(&t, x)).abs() < 1e-13, "{tau:?} at {x}");
            }
        }
    }
}
