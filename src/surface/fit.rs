//! Vertex fit: each vertex of the extracted surface moved onto the plane of its nearest input
//! points (one-step MLS projection), and its colour and intensity from the same neighbours.

use super::colour::{COLOUR_NEIGHBOURS, blend_colour};
use super::point_grid::PointGrid;

/// Input points whose plane a vertex is moved onto (`fit`).
pub const FIT_NEIGHBOURS: usize = 20;

/// Extra neighbours gathered beyond those used, so that ties at the last place are seen and
/// broken alike.
const TIE_NEIGHBOURS: usize = 2;

/// The cell of the [`PointGrid`] a tile's points are bucketed in, in fine voxels (a start:
/// the grid adapts it to the points' density).
const POINT_GRID_CELL_VOXELS: f64 = 2.5;

/// A neighbour of a vertex: squared distance, position, 16-bit colour, intensity.
pub type Neighbour = (f64, [f64; 3], [u16; 3], f32);

/// Input points near a tile (those within `lo..hi`), with their colours (zero without).
#[derive(Debug, Default)]
pub struct NearPoints {
    /// Positions, world frame.
    pub pos: Vec<[f64; 3]>,
    /// 16-bit RGB colours, one per point (zero when the input has none).
    pub col: Vec<[u16; 3]>,
    /// Intensities, one per point (zero when the input has none).
    pub inten: Vec<f32>,
    /// Lower corner of the box the points were gathered from.
    pub lo: [f64; 3],
    /// Upper corner of the box the points were gathered from.
    pub hi: [f64; 3],
}

/// What the input points say about one vertex.
#[derive(Debug, Clone, Copy)]
pub struct VertexFit {
    /// The vertex, moved onto its neighbours' plane when fitting.
    pub pos: [f64; 3],
    /// 8-bit RGB colour.
    pub color: [u8; 3],
    /// Intensity.
    pub intensity: f32,
    /// Farthest neighbour used: the answer is exact when the gathered box reaches beyond it.
    pub reach: f64,
}

impl NearPoints {
    /// For each vertex: its position moved onto the plane of its [`FIT_NEIGHBOURS`] nearest
    /// input points (when `fit`, [`project`]), and its colour and intensity
    /// ([`blend_colour`]). Neighbours are ordered by distance, then position, then colour, so
    /// the answer depends only on the point set. Also returns the vertices whose answer may
    /// not be exact: their farthest neighbour lies beyond the gathered box's faces.
    pub fn fit_vertices(
        &self,
        vertices: &[[f64; 3]],
        h: f64,
        fit: bool,
    ) -> (Vec<VertexFit>, Vec<usize>) {
        if self.pos.is_empty() {
            let out = vertices
                .iter()
                .map(|v| VertexFit {
                    pos: *v,
                    color: [128; 3],
                    intensity: 0.0,
                    reach: 0.0,
                })
                .collect();
            return (out, Vec::new());
        }
        let grid = PointGrid::new(&self.pos, self.lo, self.hi, POINT_GRID_CELL_VOXELS * h);
        let want = if fit {
            FIT_NEIGHBOURS
        } else {
            COLOUR_NEIGHBOURS
        };
        let k = want + TIE_NEIGHBOURS;
        let mut inexact = Vec::new();
        let mut found = Vec::with_capacity(k);
        let out = vertices
            .iter()
            .enumerate()
            .map(|(vi, v)| {
                grid.nearest(*v, k, &mut found);
                let nb = self.neighbours(&found, want);
                let reach = nb.last().map_or(0.0, |x| x.0.sqrt());
                let room = (0..3)
                    .map(|a| (v[a] - self.lo[a]).min(self.hi[a] - v[a]))
                    .fold(f64::INFINITY, f64::min);
                if reach >= room {
                    inexact.push(vi);
                }
                let (color, intensity) = blend_colour(&nb, h);
                let pos = if fit { project(*v, &nb, h) } else { *v };
                VertexFit {
                    pos,
                    color,
                    intensity,
                    reach,
                }
            })
            .collect();
        (out, inexact)
    }

    /// The `want` nearest of the points `found` (squared distance, index), ordered by
    /// distance, then position, then colour, then intensity.
    fn neighbours(&self, found: &[(f64, u32)], want: usize) -> Vec<Neighbour> {
        let mut nb: Vec<Neighbour> = found
            .iter()
            .map(|&(d2, i)| {
                let i = i as usize;
                (d2, self.pos[i], self.col[i], self.inten[i])
            })
            .collect();
        nb.sort_by(|a, b| {
            a.0.total_cmp(&b.0)
                .then(a.1.partial_cmp(&b.1).unwrap_or(std::cmp::Ordering::Equal))
                .then(a.2.cmp(&b.2))
                .then(a.3.total_cmp(&b.3))
        });
        nb.truncate(want);
        nb
    }
}

/// `v` moved onto the plane of its neighbours `nb` (nearest first; fine spacing `h`): the
/// one-step MLS projection of the [module docs](super), left alone when fewer than 3
/// neighbours, the nearest beyond two voxels, or the plane beyond two voxels, and shrunk by
/// what twice the standard error of the plane's offset explains.
pub fn project(v: [f64; 3], nb: &[Neighbour], h: f64) -> [f64; 3] {
    if nb.len() < 3 || nb[0].0 > 4.0 * h * h {
        return v;
    }
    let n = nb.len() as f64;
    let mut c = [0f64; 3];
    for (_, p, _, _) in nb {
        for a in 0..3 {
            c[a] += p[a] / n;
        }
    }
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    for (_, p, _, _) in nb {
        let d = nalgebra::Vector3::new(p[0] - c[0], p[1] - c[1], p[2] - c[2]);
        m += d * d.transpose();
    }
    let e = m.symmetric_eigen();
    let i = e.eigenvalues.imin();
    let nrm = e.eigenvectors.column(i);
    let off = (v[0] - c[0]) * nrm[0] + (v[1] - c[1]) * nrm[1] + (v[2] - c[2]) * nrm[2];
    let se = e.eigenvalues[i].max(0.0).sqrt() / n;
    if off.abs() > 2.0 * h {
        return v;
    }
    // Shrunk toward zero by how much of it the plane's error could explain.
    let step = if off == 0.0 {
        0.0
    } else {
        off * (1.0 - (2.0 * se / off).powi(2)).max(0.0)
    };
    [0, 1, 2].map(|a| v[a] - step * nrm[a])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_follows_precise_points_and_ignores_noise() {
        let h = 0.01;
        // Precise points on z = 0: a vertex 0.3 voxel above moves onto the plane.
        let mut nb: Vec<Neighbour> = Vec::new();
        for i in 0..5 {
            for j in 0..4 {
                let p = [i as f64 * 0.004 - 0.008, j as f64 * 0.004 - 0.006, 0.0];
                nb.push((p[0] * p[0] + p[1] * p[1], p, [0; 3], 0.0));
            }
        }
        nb.sort_by(|a, b| a.0.total_cmp(&b.0));
        let v = project([0.0, 0.0, 0.003], &nb, h);
        assert!(v[2].abs() < 1e-9, "{v:?}");
        // Too far from every point (more than two voxels): left alone.
        let far: Vec<_> = nb.iter().map(|x| (x.0 + 1.0, x.1, x.2, x.3)).collect();
        assert_eq!(project([0.0, 0.0, 0.003], &far, h), [0.0, 0.0, 0.003]);
        // Noisy points: an offset within the plane's error is not followed.
        let noisy: Vec<_> = nb
            .iter()
            .enumerate()
            .map(|(i, x)| {
                let z = if i % 2 == 0 { 0.004 } else { -0.004 };
                (x.0, [x.1[0], x.1[1], z], x.2, x.3)
            })
            .collect();
        let v = project([0.0, 0.0, 0.0015], &noisy, h);
        assert!(v[2] > 0.0015 * 0.5, "{v:?}");
    }
}
