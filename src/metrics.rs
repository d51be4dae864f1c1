//! Distances and checks shared by tests, benches and `scanflow check`.

use kiddo::SquaredEuclidean;
use kiddo::immutable::float::kdtree::ImmutableKdTree;

/// A nearest-neighbour index over a point set (kd-tree).
pub struct PointIndex {
    tree: ImmutableKdTree<f64, u64, 3, 32>,
}

impl PointIndex {
    /// Index `points`.
    pub fn new(points: &[[f64; 3]]) -> PointIndex {
        PointIndex {
            tree: ImmutableKdTree::new_from_slice(points),
        }
    }

    /// Distance from `p` to the nearest indexed point (infinite for an empty index).
    pub fn nearest_distance(&self, p: [f64; 3]) -> f64 {
        self.tree
            .nearest_one::<SquaredEuclidean>(&p)
            .distance
            .sqrt()
    }
}

/// The `q`-quantile (0..=1) of `v` (sorted in place); NaN for an empty slice.
pub fn quantile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let i = ((v.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    v[i]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_matches_brute_force() {
        let pts: Vec<[f64; 3]> = (0..500)
            .map(|i| {
                let t = i as f64 * 0.37;
                [t.sin(), (1.3 * t).cos(), (0.7 * t).sin() * 2.0]
            })
            .collect();
        let idx = PointIndex::new(&pts);
        for q in [[0.1, 0.2, 0.3], [2.0, -1.0, 0.5], [0.0, 0.0, 0.0]] {
            let brute = pts
                .iter()
                .map(|p| {
                    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
                })
                .fold(f64::INFINITY, f64::min);
            assert!((idx.nearest_distance(q) - brute).abs() < 1e-12);
        }
        let mut v = vec![3.0, 1.0, 2.0];
        assert_eq!(quantile(&mut v, 0.5), 2.0);
    }
}
