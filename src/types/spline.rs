//! A tensor-product B-spline surface, as the spline stage hands it to the writers.

/// A non-rational tensor-product B-spline surface `S(u, v) = Σ_ij c_ij N_i(u) M_j(v)` in world
/// coordinates (the input's units and frame).
///
/// `knots[0]` is the u knot vector (non-decreasing, `count[0] + degree[0] + 1` values),
/// `knots[1]` the v one. The surface's domain is `[knots[0][degree[0]], knots[0][count[0]]] ×
/// [knots[1][degree[1]], knots[1][count[1]]]`; the spline stage always writes clamped knot
/// vectors (end knots of multiplicity `degree + 1`), so the domain is the first and last knot.
/// Control points are stored with u fastest: `ctrl[i + count[0] * j]` is `c_ij`.
#[derive(Debug, Clone, PartialEq)]
pub struct TensorSurface {
    /// Polynomial degree along u and v (3 for the spline stage's bicubic surfaces).
    pub degree: [usize; 2],
    /// Knot vectors along u and v, in parameter units.
    pub knots: [Vec<f64>; 2],
    /// Number of control points along u and v.
    pub count: [usize; 2],
    /// Control points, u fastest, in world coordinates.
    pub ctrl: Vec<[f64; 3]>,
}

impl TensorSurface {
    /// The parameter domain as `[[u0, u1], [v0, v1]]`.
    pub fn domain(&self) -> [[f64; 2]; 2] {
        [0, 1].map(|d| [self.knots[d][self.degree[d]], self.knots[d][self.count[d]]])
    }

    /// Whether the sizes agree: knot counts, control-point count, degrees at least 1.
    pub fn is_consistent(&self) -> bool {
        (0..2).all(|d| {
            self.degree[d] >= 1
                && self.count[d] > self.degree[d]
                && self.knots[d].len() == self.count[d] + self.degree[d] + 1
                && self.knots[d].windows(2).all(|w| w[0] <= w[1])
        }) && self.ctrl.len() == self.count[0] * self.count[1]
    }
}
