//! The principal-component frame of a set of points: centroid, the axes of largest and
//! second-largest spread, and the normal (least spread), each signed so that its largest
//! component is positive, so the same points always give the same frame (the
//! parameterisation's projection, [`super::param`], and the graph's boundary test,
//! [`super::graph`], both read it).

use crate::geom::vec::cross;

/// An orthonormal frame through a centroid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Frame {
    /// The points' centroid.
    pub(crate) centroid: [f64; 3],
    /// First axis, second axis, normal (right-handed).
    pub(crate) axes: [[f64; 3]; 3],
}

/// Make the largest component of `v` (the first on ties) positive.
fn sign_rule(v: [f64; 3]) -> [f64; 3] {
    let mut k = 0;
    for c in 1..3 {
        if v[c].abs() > v[k].abs() {
            k = c;
        }
    }
    if v[k] < 0.0 { [-v[0], -v[1], -v[2]] } else { v }
}

/// The principal-component frame of `n` points (signed by [`sign_rule`]).
pub(crate) fn pca_frame(points: impl Iterator<Item = [f64; 3]> + Clone, n: usize) -> Frame {
    let inv = 1.0 / n.max(1) as f64;
    let mut c = [0.0; 3];
    for p in points.clone() {
        for k in 0..3 {
            c[k] += p[k];
        }
    }
    c = c.map(|v| v * inv);
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    for p in points {
        let d = nalgebra::Vector3::new(p[0] - c[0], p[1] - c[1], p[2] - c[2]);
        m += d * d.transpose();
    }
    let e = nalgebra::SymmetricEigen::new(m * inv);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| {
        e.eigenvalues[b]
            .total_cmp(&e.eigenvalues[a])
            .then(a.cmp(&b))
    });
    let col = |k: usize| {
        let v = e.eigenvectors.column(order[k]);
        [v[0], v[1], v[2]]
    };
    let first = sign_rule(col(0));
    let normal = sign_rule(col(2));
    let second = cross(normal, first);
    Frame {
        centroid: c,
        axes: [first, second, normal],
    }
}
