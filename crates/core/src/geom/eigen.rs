//! Eigenvectors of small symmetric matrices in closed form: the normal of a neighbourhood's
//! covariance (the normals' plane fits, the vertex fit's discs).

use nalgebra::{Matrix3, Vector3};

/// Unit eigenvector of the smallest eigenvalue of a symmetric positive semi-definite 3×3
/// matrix, in closed form: eigenvalues by the trigonometric solution of the characteristic
/// cubic (Smith 1961), the vector as the largest cross product of two rows of `A − λ₃I`.
/// `None` when the two smallest eigenvalues are both ~0 relative to the largest (a line or a
/// point: no plane).
pub fn least_eigenvector(a: &Matrix3<f64>) -> Option<Vector3<f64>> {
    let p1 = a[(0, 1)] * a[(0, 1)] + a[(0, 2)] * a[(0, 2)] + a[(1, 2)] * a[(1, 2)];
    let q = a.trace() / 3.0;
    let p2 = (a[(0, 0)] - q).powi(2) + (a[(1, 1)] - q).powi(2) + (a[(2, 2)] - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    if p.is_nan() || p == 0.0 {
        return None;
    }
    let b = (a - Matrix3::identity() * q) / p;
    let r = (b.determinant() / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let hi = q + 2.0 * p * phi.cos();
    let lo = q + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos();
    let mid = 3.0 * q - hi - lo;
    // (The trigonometric solution is accurate to ~1e-8 of the largest eigenvalue near repeated
    // roots, so "~0" is taken as below 1e-6 of it.)
    if mid.is_nan() || mid <= 1e-6 * hi || !lo.is_finite() {
        return None;
    }
    let m = a - Matrix3::identity() * lo;
    let (r0, r1, r2) = (
        m.row(0).transpose(),
        m.row(1).transpose(),
        m.row(2).transpose(),
    );
    let cands = [r0.cross(&r1), r0.cross(&r2), r1.cross(&r2)];
    let best = cands
        .iter()
        .max_by(|x, y| x.norm_squared().total_cmp(&y.norm_squared()))?;
    let l = best.norm();
    if l.is_nan() || l <= 0.0 {
        return None;
    }
    Some(best / l)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closed_form_eigenvector_matches_nalgebra() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        for _ in 0..2000 {
            // Random covariances of flattened point clouds.
            let g = Matrix3::from_fn(|_, _| rng.random::<f64>() - 0.5);
            let d = Matrix3::from_diagonal(&Vector3::new(
                rng.random::<f64>() + 0.1,
                rng.random::<f64>() + 0.1,
                rng.random::<f64>() * 0.05,
            ));
            let a = g * d * g.transpose();
            let e = nalgebra::SymmetricEigen::new(a);
            let i = e.eigenvalues.imin();
            let want: Vector3<f64> = e.eigenvectors.column(i).into();
            let got = least_eigenvector(&a).unwrap();
            assert!(got.dot(&want).abs() > 1.0 - 1e-6, "{a} {got} {want}");
        }
        // Diagonal and degenerate cases.
        let a = Matrix3::from_diagonal(&Vector3::new(2.0, 1.0, 0.0));
        assert!((least_eigenvector(&a).unwrap()[2].abs() - 1.0).abs() < 1e-12);
        assert!(least_eigenvector(&Matrix3::from_diagonal(&Vector3::new(1.0, 0.0, 0.0))).is_none());
        assert!(least_eigenvector(&Matrix3::zeros()).is_none());
    }
}
