//! Local frames of a surface normal.

use super::vec::{cross, dot};

/// A right-handed orthonormal pair `(t₁, t₂)` with `t₁ × t₂ = n` spanning the plane normal to
/// the unit `n`, chosen from `n` alone (so the same normal always gives the same frame): `t₁`
/// is the axis least aligned with `n` crossed with `n`, normalised.
pub fn plane_basis(n: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let a = if n[0].abs() <= n[1].abs() && n[0].abs() <= n[2].abs() {
        [1.0, 0.0, 0.0]
    } else if n[1].abs() <= n[2].abs() {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    let u = cross(a, n);
    let l = dot(u, u).sqrt();
    let u = [u[0] / l, u[1] / l, u[2] / l];
    (u, cross(n, u))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_basis_is_orthonormal_and_right_handed() {
        for n in [
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.6, 0.0, -0.8],
            [0.48, 0.6, 0.64],
        ] {
            let (t1, t2) = plane_basis(n);
            for (a, b, want) in [
                (t1, t1, 1.0),
                (t2, t2, 1.0),
                (t1, t2, 0.0),
                (t1, n, 0.0),
                (t2, n, 0.0),
            ] {
                assert!((dot(a, b) - want).abs() < 1e-12, "{n:?}");
            }
            let c = cross(t1, t2);
            assert!((0..3).all(|i| (c[i] - n[i]).abs() < 1e-12), "{n:?}");
        }
    }
}
