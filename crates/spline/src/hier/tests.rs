use super::*;
use crate::tensor;

fn coefs(n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut x = seed;
    let mut next = || {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    (0..n).map(|_| [next(), next(), next()]).collect()
}

fn refined_example() -> Hierarchy {
    let mut h = Hierarchy::new(0.5, [4, 3]);
    let marks = [
        Leaf {
            level: 0,
            cell: [1, 1],
        },
        Leaf {
            level: 0,
            cell: [3, 0],
        },
    ];
    let (missed, changed) = h.refine(&marks, 5);
    assert!(missed.is_empty() && changed);
    let leaves = h.leaves();
    let deep: Vec<Leaf> = leaves
        .iter()
        .filter(|l| l.level == 1)
        .take(3)
        .copied()
        .collect();
    h.refine(&deep, 5);
    h
}

#[test]
fn leaves_tile_the_domain_and_leaf_of_finds_them() {
    let h = refined_example();
    let area: f64 = h
        .leaves()
        .iter()
        .map(|l| h.spacing(l.level as usize).powi(2))
        .sum();
    let size = h.size();
    assert!((area - size[0] * size[1]).abs() < 1e-12);
    for leaf in h.leaves() {
        let s = h.spacing(leaf.level as usize);
        let centre = [
            (leaf.cell[0] as f64 + 0.5) * s,
            (leaf.cell[1] as f64 + 0.5) * s,
        ];
        assert_eq!(h.leaf_of(centre), leaf);
    }
}

#[test]
fn refinement_adds_finer_functions_and_drops_covered_coarse_ones() {
    let h0 = Hierarchy::new(0.5, [4, 3]);
    assert_eq!(h0.per_level(), vec![7 * 6]);
    let h = refined_example();
    let per = h.per_level();
    assert_eq!(per.len(), 3);
    assert!(per[1] > 0 && per[2] > 0, "{per:?}");
    // The full refinement of a level removes every coarse function whose support is covered.
    let mut g = Hierarchy::new(0.5, [4, 4]);
    let all: Vec<Leaf> = g.leaves();
    g.refine(&all, 3);
    assert_eq!(g.per_level(), vec![0, 11 * 11]);
}

#[test]
fn tensor_export_equals_the_hierarchical_surface() {
    for h in [Hierarchy::new(0.5, [4, 3]), refined_example()] {
        let coef = coefs(h.len(), 7);
        let t = h.to_tensor(&coef, [10.0, -2.0, 0.5]);
        assert!(t.is_consistent());
        let size = h.size();
        let dom = t.domain();
        assert_eq!(dom, [[0.0, size[0]], [0.0, size[1]]]);
        for k in 0..400 {
            let uv = [
                size[0] * (k as f64 * 0.618_034).fract(),
                size[1] * (k as f64 * 0.414_214).fract(),
            ];
            let a = h.eval(&coef, uv);
            let b = tensor::eval(&t, uv);
            let origin = [10.0, -2.0, 0.5];
            for x in 0..3 {
                assert!((a[0][x] + origin[x] - b[0][x]).abs() < 1e-12, "{uv:?}");
                for d in 1..6 {
                    assert!((a[d][x] - b[d][x]).abs() < 1e-9, "{uv:?} d{d}");
                }
            }
        }
    }
}

#[test]
fn refined_space_contains_the_coarse_surface() {
    // A coarse function whose support lies in the refined region is replaced by finer ones:
    // the surface it made must still be representable. Check by expanding each dropped
    // level-0 function through the refinement mask and evaluating both.
    let coarse = Hierarchy::new(0.5, [4, 4]);
    let coef = coefs(coarse.len(), 3);
    let mut fine = coarse.clone();
    let all = fine.leaves();
    fine.refine(&all, 3);
    // Level-1 coefficients: c1[2i+a, 2j+b] = Σ mask[a'] mask[b'] c0[i, j].
    let mut c1 = vec![[0.0; 3]; fine.len()];
    for (k, f) in coarse.active[0].iter().enumerate() {
        for (a, wa) in MASK_FOR_TEST.iter().enumerate() {
            for (b, wb) in MASK_FOR_TEST.iter().enumerate() {
                let g = [2 * f[0] + a as i64, 2 * f[1] + b as i64];
                if let Some(&idx) = fine.index[1].get(&g) {
                    for x in 0..3 {
                        c1[idx as usize][x] += wa * wb * coef[k][x];
                    }
                }
            }
        }
    }
    for k in 0..200 {
        let uv = [
            2.0 * (k as f64 * 0.618_034).fract(),
            2.0 * (k as f64 * 0.414_214).fract(),
        ];
        let a = coarse.eval(&coef, uv)[0];
        let b = fine.eval(&c1, uv)[0];
        for x in 0..3 {
            assert!((a[x] - b[x]).abs() < 1e-13);
        }
    }
}

const MASK_FOR_TEST: [f64; 5] = crate::basis::MASK;

#[test]
fn pieces_of_neighbouring_rectangles_are_the_same_spline() {
    let h = refined_example();
    let coef = coefs(h.len(), 11);
    let left = h.to_tensor_rect(&coef, [0.0; 3], [0, 0], [2, 3]);
    let right = h.to_tensor_rect(&coef, [0.0; 3], [2, 0], [4, 3]);
    assert!(left.is_consistent() && right.is_consistent());
    assert_eq!(left.domain()[0], [0.0, 1.0]);
    assert_eq!(right.domain()[0], [1.0, 2.0]);
    for k in 0..100 {
        let v = 1.5 * k as f64 / 99.0;
        let a = tensor::eval(&left, [1.0, v]);
        let b = tensor::eval(&right, [1.0, v]);
        let c = h.eval(&coef, [1.0, v]);
        for x in 0..3 {
            // Value, first and second derivatives across the seam agree: C2.
            for d in 0..6 {
                assert!((a[d][x] - b[d][x]).abs() < 1e-9, "d{d} at v={v}");
            }
            assert!((a[0][x] - c[0][x]).abs() < 1e-12);
        }
    }
}

#[test]
fn prolongation_keeps_the_surface_exactly() {
    let coarse = refined_example();
    let coef = coefs(coarse.len(), 5);
    let mut fine = coarse.clone();
    let leaves: Vec<Leaf> = fine.leaves().into_iter().step_by(3).collect();
    fine.refine(&leaves, 6);
    let c2 = coarse.prolong(&coef, &fine);
    for k in 0..300 {
        let uv = [
            2.0 * (k as f64 * 0.618_034).fract(),
            1.5 * (k as f64 * 0.414_214).fract(),
        ];
        let a = coarse.eval(&coef, uv)[0];
        let b = fine.eval(&c2, uv)[0];
        for x in 0..3 {
            assert!((a[x] - b[x]).abs() < 1e-12, "{uv:?}");
        }
    }
}

/// Smallest eigenvalue of the Gram matrix (scaled to a unit diagonal) of the basis over a
/// dense sample of the domain, relative to the largest.
fn gram_condition(h: &Hierarchy) -> f64 {
    let n = h.len();
    let mut g = nalgebra::DMatrix::<f64>::zeros(n, n);
    let size = h.size();
    let m = 120;
    let mut sup = Vec::new();
    let mut lb = LocalBasis::default();
    for b in 0..m {
        for a in 0..m {
            let uv = [
                size[0] * (a as f64 + 0.5) / m as f64,
                size[1] * (b as f64 + 0.5) / m as f64,
            ];
            let leaf = h.leaf_of(uv);
            h.supports(leaf, &mut sup);
            h.local_basis(leaf, uv, &mut lb);
            for x in &sup {
                for y in &sup {
                    g[(x.index as usize, y.index as usize)] += lb.value(x) * lb.value(y);
                }
            }
        }
    }
    let d: Vec<f64> = (0..n).map(|i| g[(i, i)].sqrt()).collect();
    for i in 0..n {
        for j in 0..n {
            g[(i, j)] /= d[i] * d[j];
        }
    }
    let e = nalgebra::SymmetricEigen::new(g).eigenvalues;
    let (lo, hi) = e
        .iter()
        .fold((f64::MAX, 0.0f64), |a, &x| (a.0.min(x), a.1.max(x)));
    lo / hi
}

#[test]
fn the_basis_stays_independent_when_refinement_touches_the_edge() {
    let mut h = Hierarchy::new(0.5, [4, 4]);
    let all = h.leaves();
    h.refine(&all, 5);
    assert!(gram_condition(&h) > 1e-6, "{}", gram_condition(&h));
    // A rectangle against the right edge, then one against a corner, a level deeper.
    let edge: Vec<Leaf> = h
        .leaves()
        .into_iter()
        .filter(|l| l.cell[0] == 7 && l.cell[1] >= 3 && l.cell[1] <= 4)
        .collect();
    h.refine(&edge, 5);
    let c1 = gram_condition(&h);
    let corner: Vec<Leaf> = h
        .leaves()
        .into_iter()
        .filter(|l| l.level == 2 && l.cell[0] >= 14 && l.cell[1] >= 8)
        .take(2)
        .collect();
    h.refine(&corner, 5);
    let c2 = gram_condition(&h);
    assert!(c1 > 1e-8 && c2 > 1e-8, "{c1} {c2} {:?}", h.per_level());
}
