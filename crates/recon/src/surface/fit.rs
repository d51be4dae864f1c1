//! Vertex fit: each vertex of the extracted surface moved onto the plane of its nearest input
//! points (one-step MLS projection), or onto their quadratic jet where they are curved, and
//! its colour and intensity from the same neighbours.

use super::colour::{COLOUR_NEIGHBOURS, blend_colour};
use super::point_grid::PointGrid;
use crate::geom::frame::plane_basis;
use crate::geom::least_eigenvector;
use crate::noise::PRECISE_WITHIN_VOXELS;
use crate::types::{EdgeKey, GridGeom};

/// Input points whose plane a vertex is moved onto (`fit`).
pub const FIT_NEIGHBOURS: usize = 20;

/// Extra neighbours gathered beyond those used, so that ties at the last place are seen and
/// broken alike.
const TIE_NEIGHBOURS: usize = 2;

/// How close to either end of its grid edge a fitted vertex may come, in edge lengths (at
/// least; more where float32 output could not tell the vertex from the end, see
/// [`edge_margin`]). Keeps every triangle's corners inside three distinct edges of its cell,
/// so no triangle collapses ([module docs](super)).
pub const EDGE_MARGIN: f64 = 0.01;

/// A vertex that slid more than this along its edge (in voxels) is fitted once more, to the
/// plane of the points around where it went.
const REFIT_VOXELS: f64 = 0.1;

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
    /// The vertex, moved along its grid edge toward its neighbours' plane when fitting.
    pub pos: [f64; 3],
    /// The vertex moved along the plane's normal instead (the plain one-step projection):
    /// where [`super::settle()`] finds that no triangle collapses or flips with it (`pos` when
    /// the vertex does not move).
    pub free_pos: [f64; 3],
    /// 8-bit RGB colour.
    pub color: [u8; 3],
    /// Intensity.
    pub intensity: f32,
    /// Farthest neighbour used: the answer is exact when the gathered box reaches beyond it.
    pub reach: f64,
    /// Sampling density at the vertex, input points per square unit: `k / (π r²)` for its
    /// `k` nearest points ([`FIT_NEIGHBOURS`] when fitting or asked for, else the colour's
    /// neighbours) within distance `r` of it, the farthest's (0 where it has no neighbour
    /// at a distance).
    pub density: f32,
}

impl NearPoints {
    /// For each vertex (at `vertices[i]` on grid edge `keys[i]` of `geom`): its position moved
    /// along its edge toward the plane of its [`FIT_NEIGHBOURS`] nearest input points (when
    /// `fit` gives the samples' measured noise in input units, 0 where unknown: [`project`]),
    /// and its colour and intensity ([`blend_colour`]). Neighbours are
    /// ordered by distance, then position, then colour, so the answer depends only on the
    /// point set and the vertex. Also returns the vertices whose answer may not be exact:
    /// their farthest neighbour lies beyond the gathered box's faces. `density` asks for
    /// the [`VertexFit::density`] from [`FIT_NEIGHBOURS`] points even without fitting.
    pub fn fit_vertices(
        &self,
        vertices: &[[f64; 3]],
        keys: &[EdgeKey],
        geom: &GridGeom,
        fit: Option<f64>,
        density: bool,
    ) -> (Vec<VertexFit>, Vec<usize>) {
        debug_assert_eq!(vertices.len(), keys.len());
        let h = geom.h;
        if self.pos.is_empty() {
            let out = vertices
                .iter()
                .map(|v| VertexFit {
                    pos: *v,
                    free_pos: *v,
                    color: [128; 3],
                    intensity: 0.0,
                    reach: 0.0,
                    density: 0.0,
                })
                .collect();
            return (out, Vec::new());
        }
        let grid = PointGrid::new(&self.pos, self.lo, self.hi, POINT_GRID_CELL_VOXELS * h);
        let want = if fit.is_some() || density {
            FIT_NEIGHBOURS
        } else {
            COLOUR_NEIGHBOURS
        };
        let k = want + TIE_NEIGHBOURS;
        let mut inexact = Vec::new();
        let mut found = Vec::with_capacity(k);
        let out = vertices
            .iter()
            .zip(keys)
            .enumerate()
            .map(|(vi, (v, key))| {
                grid.nearest(*v, k, &mut found);
                let nb = self.neighbours(&found, want);
                let reach = nb.last().map_or(0.0, |x| x.0.sqrt());
                let density = if reach > 0.0 {
                    (nb.len() as f64 / (std::f64::consts::PI * reach * reach)) as f32
                } else {
                    0.0
                };
                let room = (0..3)
                    .map(|a| (v[a] - self.lo[a]).min(self.hi[a] - v[a]))
                    .fold(f64::INFINITY, f64::min);
                if reach >= room {
                    inexact.push(vi);
                }
                let (color, intensity) = blend_colour(&nb, h);
                let (mut pos, mut reach) = (*v, reach);
                let mut free_pos = *v;
                if let Some(noise) = fit {
                    let (node, axis) = geom.decode_edge(*key);
                    let a = axis as usize;
                    let mut up = node;
                    up[a] += 1;
                    let edge = [geom.node_position(node)[a], geom.node_position(up)[a]];
                    let (p, first) = project_plane(*v, a, edge, &nb, h, noise);
                    pos = p;
                    free_pos = p;
                    if let Some((plane, kept)) = first {
                        let step = plane.offset(*v) - kept;
                        free_pos = [0, 1, 2].map(|d| v[d] - step * plane.n[d]);
                    }
                    // A long slide along the edge: the plane again, from the points around
                    // where the vertex went (exact too: its reach counts from the vertex).
                    if let (Some((plane, kept)), true) =
                        (first, (p[a] - v[a]).abs() > REFIT_VOXELS * h)
                    {
                        grid.nearest(p, k, &mut found);
                        let nb2 = self.neighbours(&found, want);
                        let reach2 = nb2.last().map_or(0.0, |x| x.0.sqrt());
                        let room2 = (0..3)
                            .map(|d| (p[d] - self.lo[d]).min(self.hi[d] - p[d]))
                            .fold(f64::INFINITY, f64::min);
                        if reach2 >= room2 && reach < room {
                            inexact.push(vi);
                        }
                        reach = reach.max(reach2 + (p[a] - v[a]).abs());
                        pos = refit(p, a, edge, &nb2, h, &plane, kept);
                    }
                }
                VertexFit {
                    pos,
                    free_pos,
                    color,
                    intensity,
                    reach,
                    density,
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
        // `found` is ordered by distance already: only a tie in distance can reorder it.
        if found.windows(2).all(|w| w[0].0 < w[1].0) {
            nb.truncate(want);
            return nb;
        }
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

/// `v`, a vertex on the grid edge along `axis` from coordinate `edge[0]` to `edge[1]`, moved
/// along that edge toward the plane of its neighbours `nb` (nearest first; fine spacing `h`):
/// the one-step MLS projection of the [module docs](super), to where the edge meets the
/// plane, shrunk by what twice the standard error of the plane's offset explains, and kept
/// within the edge by [`edge_margin`]. Not moved (only kept within the edge) when fewer than
/// 3 neighbours, or the nearest or the plane beyond two voxels (two of the neighbours'
/// spacings where they lie farther apart), or for `noise` of [`FIT_NOISE_LIMIT_VOXELS`] or
/// more. `noise` is the samples' measured spread across the surface (input units; 0 where
/// unknown), the part of the residuals that does not count as a misfit (`MISFIT_SHARE`).
pub fn project(
    v: [f64; 3],
    axis: usize,
    edge: [f64; 2],
    nb: &[Neighbour],
    h: f64,
    noise: f64,
) -> [f64; 3] {
    project_plane(v, axis, edge, nb, h, noise).0
}

/// [`project`], and the plane with the offset from it the vertex keeps when it moved.
fn project_plane(
    v: [f64; 3],
    axis: usize,
    edge: [f64; 2],
    nb: &[Neighbour],
    h: f64,
    noise: f64,
) -> ([f64; 3], Option<(Plane, f64)>) {
    let mut p = v;
    p[axis] = clamp_to_edge(v[axis], edge);
    if noise >= FIT_NOISE_LIMIT_VOXELS * h {
        return (p, None);
    }
    let Some(plane) = Plane::fit(nb, h, precise(noise, h)) else {
        return (p, None);
    };
    let off = plane.offset(v);
    if off.abs() > 2.0 * plane.scale || off == 0.0 {
        return (p, None);
    }
    let step = plane.shrink(off, noise);
    p[axis] = clamp_to_edge(v[axis] + plane.along(v, axis, step), edge);
    (p, Some((plane, off - step)))
}

/// The vertex `p` (moved along its edge toward `first`'s plane, keeping offset `kept` from
/// it) moved again along the edge, to offset `kept` from the plane of its own neighbours
/// `nb`, when that plane is found and within twice its [`Plane::scale`].
fn refit(
    p: [f64; 3],
    axis: usize,
    edge: [f64; 2],
    nb: &[Neighbour],
    h: f64,
    first: &Plane,
    kept: f64,
) -> [f64; 3] {
    let Some(mut plane) = Plane::fit(nb, h, first.precise) else {
        return p;
    };
    if (0..3).map(|a| plane.n[a] * first.n[a]).sum::<f64>() < 0.0 {
        plane.flip();
    }
    let off = plane.offset(p);
    if off.abs() > 2.0 * plane.scale {
        return p;
    }
    let mut q = p;
    q[axis] = clamp_to_edge(p[axis] + plane.along(p, axis, off - kept), edge);
    q
}

/// The move along an axis that changes a plane's offset by `-step`, the plane's normal having
/// `n_axis` along it (an axis parallel to the plane gives an infinite move, which the edge's
/// ends stop).
fn along(step: f64, n_axis: f64) -> f64 {
    let s = -step / n_axis;
    if step == 0.0 || s.is_nan() { 0.0 } else { s }
}

/// The local surface of a vertex's neighbours: their least-squares plane, bent into a
/// quadratic height field over it where the points say it is curved (module docs of
/// [`super`], "Vertex fit").
#[derive(Debug, Clone, Copy)]
struct Plane {
    /// The neighbours' mean.
    c: [f64; 3],
    /// Unit normal: the eigenvector of their covariance's least eigenvalue.
    n: [f64; 3],
    /// Unit tangents: the other two eigenvectors.
    t: [[f64; 3]; 2],
    /// The height over the plane, `h(x, y) = q0 + q1 x + q2 y + q3 x² + q4 x y + q5 y²` in the
    /// tangent coordinates; all zero where the plane is kept.
    q: [f64; 6],
    /// Standard error of the surface's offset at the neighbours' mean.
    se: f64,
    /// The residuals' standard deviation, `√(RSS/(k − p))` for `p` fitted parameters.
    sd: f64,
    /// Half the distance within which the nearest neighbour and the plane must lie for a
    /// vertex to be fitted: the voxel `h`, or the neighbours' spacing where larger,
    /// `√(A/k)` for `k` neighbours spread over an area `A = 4π √(λ₁λ₂)/k` (a disc's, `λ₁, λ₂`
    /// the covariance's eigenvalues along the plane). Without it, samples 6 voxels apart
    /// left most vertices unfitted: the 1M-point bumpy sphere at depth 12 came out 2.9·10⁻⁵
    /// off (3.6 without any fit) where depth 10 gives 1.9·10⁻⁶. The spread is the
    /// neighbours' own, so a vertex over a hole, whose neighbours lie to one side of it,
    /// stays unfitted. Only for precise samples ([`precise`]): noisy ones
    /// that sparse are fitted over discs of a dozen voxels whose curvature the plane misses
    /// and the noise hides from the jet's test (12,000 samples with noise 0.0005 at depth
    /// 9, 5 voxels apart: 1.1·10⁻³ mean distance against 6.5·10⁻⁴ unfitted), and the
    /// smoothed surface there averages more samples than the fit's 20.
    scale: f64,
    /// Whether it was fitted as precise samples (the reach of [`Plane::scale`]).
    precise: bool,
}

/// The share of the residuals' spread beyond what noise explains, `√(sd² − σ²)`, that
/// bounds how well the fit knows the offset, beside its standard error: where the plane or
/// the jet misfits the points (a relief whose curvature radius is under the neighbourhood's
/// radius), the error at the vertex is of the order of the residuals, not of their mean.
/// Measured on precise 1M-point spheres carrying a relief at depth 9 (mean distance to the
/// exact surface ·10⁻⁴, the default screening; share 0.5 → 1, no fit in brackets): 1%
/// amplitude at 8 voxels' wavelength 5.5 → 4.87 (4.90), at 12 voxels 2.37 → 2.63 (2.80),
/// at 30 voxels 0.287 → 0.328 (0.77); 2% at 8 voxels 7.34 → 5.34 (5.31), which half the
/// spread left above PoissonRecon's 6.78. Tighter relief than the neighbourhood follows
/// is what a precise scan's detail is, so the whole spread. Noisy samples take
/// [`NOISY_MISFIT_SHARE`].
const MISFIT_SHARE: f64 = 1.0;

/// [`MISFIT_SHARE`] for samples that are not precise ([`precise`]). Their noise `σ` is one
/// figure pooled over the scan, and a real scan's noise is not the same everywhere: where
/// merged scans overlap, their misregistration adds to it. There a neighbourhood's residuals
/// exceed `σ` with no relief to follow, and counted whole as misfit they held its vertices
/// on the smoothed field. Measured on the raw bunny scans at depth 8 (`σ` 0.171 voxel
/// between close samples, 0.215 before the pairs' cut; two-sided mean distance to
/// `bun_zipper` ·10⁻⁴, Open3D 1.940): share 1 1.837, 0.7 1.823, 0.5 1.804, 0.3 1.768,
/// 0 1.760 (with the uncut `σ`: 1 1.817, 0.7 1.804, 0.5 1.785); the precise relief rows
/// keep a share of 1. The price is on synthetic relief whose noise is uniform, of a
/// quarter voxel, at depth 9 (1M points, mean distance ·10⁻⁴, share 1 → 0.5 → 0.3,
/// unfitted in brackets): 1% amplitude at 12 voxels' wavelength 4.98 → 5.31 → 5.92
/// (4.91), 2% at 18 voxels 4.58 → 4.98 → 5.48 (4.53). Counting the noise's own χ² spread
/// as explained instead (up to `σ²(1 + z√(2/dof))`) cost those rows more for less: z = 2
/// gave the bunny 1.781 and the 12-voxel row 5.46.
const NOISY_MISFIT_SHARE: f64 = 0.5;

/// Residuals within this many times the samples' measured noise `σ` are taken as noise, not
/// misfit. `σ` read between close samples ([`FIT_NOISE_LIMIT_VOXELS`]) holds the spread of
/// every source the fit's neighbours carry, a merged scan's misregistration too, so once.
/// (Three times the spread within voxels, which read under it, hid a relief's misfit behind
/// the noise: a 1% relief of 12 voxels' wavelength with noise of 0.25 voxel, 6.0·10⁻⁴ mean
/// distance against 5.0·10⁻⁴ now and 4.8·10⁻⁴ unfitted.)
const NOISE_SPAN: f64 = 1.0;

pub use crate::noise::FIT_NOISE_LIMIT_VOXELS;

/// The jet is kept over the plane when its three curvature terms reduce the residual by more
/// than this F ratio, `((RSS_plane − RSS_jet)/3) / (RSS_jet/(k − 6))`. The 99th percentile of
/// F(3, 14) (20 neighbours) is 5.6, but noisy relief took jets from noise at that level and its
/// largest error grew by half; at 20 noisy inputs keep their planes and precise curved ones
/// still take jets (module docs of [`super`]).
const JET_F_RATIO: f64 = 20.0;

/// Whether samples of the measured `noise` (input units; 0 where it could not be measured)
/// are precise for a grid of spacing `h`: under the reconstruction's one threshold,
/// [`PRECISE_WITHIN_VOXELS`] of spread within fine voxels. Only these are fitted beyond
/// two voxels (`Plane::scale`). Unmeasured noise counts as precise here (the screening
/// weight takes it as not: [`crate::noise::noise_limit`]): it goes unmeasured
/// where no fine voxel holds two samples, exactly the sparse samples the reach is for.
fn precise(noise: f64, h: f64) -> bool {
    noise < PRECISE_WITHIN_VOXELS * h
}

/// Fewest neighbours for a jet (six unknowns, and a residual left to judge them by).
const JET_MIN_NEIGHBOURS: usize = 10;

impl Plane {
    /// The surface of `nb` (nearest first), or `None` when fewer than 3 or the nearest beyond
    /// twice its [`Plane::scale`] (the voxel `h`, or, for `precise` samples, their spacing
    /// where larger).
    fn fit(nb: &[Neighbour], h: f64, precise: bool) -> Option<Plane> {
        // Only precise samples are fitted beyond two voxels: the others are refused before
        // the covariance is summed, as before the sparse reach.
        let far = nb.first().is_some_and(|x| x.0 > 4.0 * h * h);
        if nb.len() < 3 || (far && !precise) {
            return None;
        }
        let k = nb.len() as f64;
        let mut c = [0f64; 3];
        for (_, p, _, _) in nb {
            for a in 0..3 {
                c[a] += p[a] / k;
            }
        }
        let mut m = nalgebra::Matrix3::<f64>::zeros();
        for (_, p, _, _) in nb {
            let d = nalgebra::Vector3::new(p[0] - c[0], p[1] - c[1], p[2] - c[2]);
            m += d * d.transpose();
        }
        // The normal in closed form (a tenth of the tile stage's time went to the iterative
        // solver at 100M points); the iterative one where the points make a line or a blob.
        let (n, t) = match least_eigenvector(&m) {
            Some(v) => {
                let n = [v[0], v[1], v[2]];
                let (t0, t1) = plane_basis(n);
                (n, [t0, t1])
            }
            None => {
                let e = m.symmetric_eigen();
                let i = e.eigenvalues.imin();
                let col = |j: usize| {
                    let v = e.eigenvectors.column(j);
                    [v[0], v[1], v[2]]
                };
                (col(i), [col((i + 1) % 3), col((i + 2) % 3)])
            }
        };
        // Where the nearest point is beyond two voxels, the samples may be sparser than the
        // grid: the reach is then twice their spacing (`Plane::scale`), from the area their
        // spread along the plane covers.
        let mut scale = h;
        if far {
            let mt = |a: [f64; 3], b: [f64; 3]| {
                let mb = m * nalgebra::Vector3::new(b[0], b[1], b[2]);
                a[0] * mb[0] + a[1] * mb[1] + a[2] * mb[2]
            };
            let det = mt(t[0], t[0]) * mt(t[1], t[1]) - mt(t[0], t[1]).powi(2);
            let area = 4.0 * std::f64::consts::PI * det.max(0.0).sqrt() / k;
            scale = scale.max((area / k).sqrt());
            if nb[0].0 > 4.0 * scale * scale {
                return None;
            }
        }
        // The least eigenvalue, as the squared distances to the plane it stands for.
        let rss_plane: f64 = nb
            .iter()
            .map(|(_, p, _, _)| {
                let z = (0..3).map(|a| (p[a] - c[a]) * n[a]).sum::<f64>();
                z * z
            })
            .sum();
        let mut plane = Plane {
            c,
            n,
            t,
            q: [0.0; 6],
            se: rss_plane.sqrt() / k,
            sd: (rss_plane / (k - 3.0).max(1.0)).sqrt(),
            scale,
            precise,
        };
        plane.bend(nb, rss_plane, h);
        Some(plane)
    }

    /// Fits the quadratic height field over the plane to `nb` and keeps it when its curvature
    /// terms are significant ([`JET_F_RATIO`]); the offset's standard error is then the
    /// jet's.
    fn bend(&mut self, nb: &[Neighbour], rss_plane: f64, h: f64) {
        if nb.len() < JET_MIN_NEIGHBOURS {
            return;
        }
        let mut ata = nalgebra::Matrix6::<f64>::zeros();
        let mut atz = nalgebra::Vector6::<f64>::zeros();
        // Scaled by the voxel so the normal equations stay well conditioned.
        let row = |p: [f64; 3]| {
            let (x, y, z) = self.local(p);
            let (u, v) = (x / h, y / h);
            (nalgebra::Vector6::new(1.0, u, v, u * u, u * v, v * v), z)
        };
        for (_, p, _, _) in nb {
            let (r, z) = row(*p);
            ata += r * r.transpose();
            atz += r * z;
        }
        let Some(chol) = ata.cholesky() else {
            return;
        };
        let sol = chol.solve(&atz);
        let rss: f64 = nb
            .iter()
            .map(|(_, p, _, _)| {
                let (r, z) = row(*p);
                (z - r.dot(&sol)).powi(2)
            })
            .sum();
        let dof = (nb.len() - 6) as f64;
        let gain = rss_plane - rss;
        // Points exactly on a plane leave both residuals at rounding level.
        if gain <= 1e-18 * h * h * nb.len() as f64 || gain / 3.0 <= JET_F_RATIO * rss / dof {
            return;
        }
        let var_q0 = chol.solve(&nalgebra::Vector6::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0))[0];
        self.q = [
            sol[0],
            sol[1] / h,
            sol[2] / h,
            sol[3] / (h * h),
            sol[4] / (h * h),
            sol[5] / (h * h),
        ];
        self.se = (rss / dof * var_q0).max(0.0).sqrt();
        self.sd = (rss / dof).max(0.0).sqrt();
    }

    /// `p` in the plane's frame: tangent coordinates and height.
    fn local(&self, p: [f64; 3]) -> (f64, f64, f64) {
        let d = [p[0] - self.c[0], p[1] - self.c[1], p[2] - self.c[2]];
        let dot = |a: [f64; 3]| a[0] * d[0] + a[1] * d[1] + a[2] * d[2];
        (dot(self.t[0]), dot(self.t[1]), dot(self.n))
    }

    /// Whether the surface is the plane (no curvature kept).
    fn is_flat(&self) -> bool {
        self.q == [0.0; 6]
    }

    /// Signed offset of `v` from the surface, along the normal (the height over the jet).
    fn offset(&self, v: [f64; 3]) -> f64 {
        let (x, y, z) = self.local(v);
        let q = &self.q;
        z - (q[0] + q[1] * x + q[2] * y + q[3] * x * x + q[4] * x * y + q[5] * y * y)
    }

    /// The same surface seen from the other side.
    fn flip(&mut self) {
        self.n = self.n.map(|x| -x);
        self.q = self.q.map(|x| -x);
    }

    /// The move `s` along `axis` from `v` after which the offset is `offset(v) − step`: for
    /// the plane, [`along`]; for the jet, the root nearest `v` of the quadratic in `s` (the
    /// plane's move when there is none).
    fn along(&self, v: [f64; 3], axis: usize, step: f64) -> f64 {
        let plane = along(step, self.n[axis]);
        if self.is_flat() || step == 0.0 {
            return plane;
        }
        let (x, y, _) = self.local(v);
        let (tx, ty, nz) = (self.t[0][axis], self.t[1][axis], self.n[axis]);
        let q = &self.q;
        // offset(v + s e) = offset(v) + b s + a s².
        let a = -(q[3] * tx * tx + q[4] * tx * ty + q[5] * ty * ty);
        let b = nz
            - (q[1] * tx + q[2] * ty + 2.0 * q[3] * x * tx + q[4] * (x * ty + y * tx))
            - 2.0 * q[5] * y * ty;
        // a s² + b s + step = 0.
        let disc = b * b - 4.0 * a * step;
        if disc < 0.0 || (a == 0.0 && b == 0.0) {
            return plane;
        }
        // The root of smaller magnitude, in the cancellation-free form.
        let r = -0.5 * (b + b.signum() * disc.sqrt());
        let s = if r != 0.0 { step / r } else { -step / b };
        if s.is_finite() { s } else { plane }
    }

    /// The part of offset `off` to remove: shrunk toward zero by how much of it the fit's
    /// error could explain (its standard error, or [`MISFIT_SHARE`] of its residuals beyond
    /// [`NOISE_SPAN`] times the samples' measured `noise`, input units, where that is larger;
    /// [`NOISY_MISFIT_SHARE`] for samples that are not precise).
    fn shrink(&self, off: f64, noise: f64) -> f64 {
        let explained = NOISE_SPAN * noise;
        let misfit = (self.sd * self.sd - explained * explained).max(0.0).sqrt();
        let share = if self.precise {
            MISFIT_SHARE
        } else {
            NOISY_MISFIT_SHARE
        };
        let se = self.se.max(share * misfit);
        off * (1.0 - (2.0 * se / off).powi(2)).max(0.0)
    }
}

/// The margin, in input units, that keeps a vertex inside the grid edge `edge` (its two end
/// coordinates along the edge): [`EDGE_MARGIN`] of the edge, or two float32 units in the
/// last place of the larger end if more, so that the vertex written as float32 is still
/// strictly inside the edge written as float32 (rounding to nearest is monotone).
pub fn edge_margin(edge: [f64; 2]) -> f64 {
    let big = edge[0].abs().max(edge[1].abs()) as f32;
    let ulp = if big.is_finite() {
        (f32::from_bits(big.to_bits() + 1) - big) as f64
    } else {
        0.0
    };
    (EDGE_MARGIN * (edge[1] - edge[0])).max(2.0 * ulp)
}

/// `x` clamped to the grid edge `edge` less [`edge_margin`] at both ends (the edge's middle
/// when the margins meet).
fn clamp_to_edge(x: f64, edge: [f64; 2]) -> f64 {
    let m = edge_margin(edge);
    let (lo, hi) = (edge[0] + m, edge[1] - m);
    if lo >= hi {
        0.5 * (edge[0] + edge[1])
    } else {
        x.clamp(lo, hi)
    }
}

#[cfg(test)]
mod tests;
