//! Sampled distances both ways between a mesh and a reference: the exact surface of a truth
//! file, another mesh, or a point set.

use rand::Rng;
use rand_pcg::Pcg64;
use rayon::prelude::*;
use serde::Serialize;

use super::{PointIndex, TriangleIndex, corners, double_area};
use crate::geom::vec::{add, scale};
use crate::io::mesh_read::Mesh;
use crate::synth::Truth;
use crate::synth::rng::stream_rng;
use crate::synth::sampler::Sampler;
use crate::types::Aabb;

/// The `q`-quantile (0..=1) of `v` (sorted in place); NaN for an empty slice.
pub fn quantile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let i = ((v.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    v[i]
}

/// Samples per generator chunk: chunk `i` draws from its own generator, seeded from
/// `(seed, stream, i)` only, so results do not depend on the number of threads.
const SAMPLE_CHUNK: usize = 4096;

/// Generator stream of the samples on the checked mesh (streams keep the two directions from
/// sharing random numbers).
const STREAM_MESH: u64 = 1;
/// Generator stream of the samples on an exact surface.
const STREAM_TRUTH: u64 = 2;
/// Generator stream of the samples on a reference mesh.
const STREAM_REFERENCE: u64 = 3;
/// Generator stream of the subset of a large reference point set.
const STREAM_SUBSET: u64 = 4;

/// Map `f` over `n` samples drawn by `draw`, in parallel chunks; the results are in sample
/// order and depend only on `(seed, stream)`. `f` returns `None` for samples to drop.
fn map_samples<D, F>(n: usize, seed: u64, stream: u64, draw: D, f: F) -> Vec<f64>
where
    D: Fn(&mut Pcg64) -> [f64; 3] + Sync,
    F: Fn([f64; 3]) -> Option<f64> + Sync,
{
    let chunks = n.div_ceil(SAMPLE_CHUNK);
    let per_chunk: Vec<Vec<f64>> = (0..chunks)
        .into_par_iter()
        .map(|c| {
            let mut rng = stream_rng(seed, stream, c as u64);
            let len = (n - c * SAMPLE_CHUNK).min(SAMPLE_CHUNK);
            (0..len).filter_map(|_| f(draw(&mut rng))).collect()
        })
        .collect();
    per_chunk.concat()
}

/// Points uniform by area on the triangles of a mesh.
struct AreaSampler<'a> {
    mesh: &'a Mesh,
    /// `cumulative[i]`: total area of triangles `0..=i` (out-of-range ones count 0).
    cumulative: Vec<f64>,
}

impl<'a> AreaSampler<'a> {
    fn new(mesh: &'a Mesh) -> AreaSampler<'a> {
        let mut cumulative: Vec<f64> = mesh
            .triangles
            .par_iter()
            .map(|&t| corners(mesh, t).map_or(0.0, |c| 0.5 * double_area(&c)))
            .collect();
        let mut s = 0.0;
        for a in &mut cumulative {
            s += *a;
            *a = s;
        }
        AreaSampler { mesh, cumulative }
    }

    /// Total area.
    fn area(&self) -> f64 {
        self.cumulative.last().copied().unwrap_or(0.0)
    }

    /// One point; the mesh must have a positive area.
    fn sample(&self, rng: &mut Pcg64) -> [f64; 3] {
        let u = rng.random::<f64>() * self.area();
        let i = self
            .cumulative
            .partition_point(|&c| c <= u)
            .min(self.cumulative.len() - 1);
        let Some([a, b, c]) = corners(self.mesh, self.mesh.triangles[i]) else {
            // Zero-area entries are never picked: u < area(0..=i) - area(0..i) > 0.
            return [f64::NAN; 3];
        };
        // Uniform on the triangle: Osada et al., "Shape distributions" (2002), eq. 1.
        let s = rng.random::<f64>().sqrt();
        let r = rng.random::<f64>();
        add(
            add(scale(a, 1.0 - s), scale(b, s * (1.0 - r))),
            scale(c, s * r),
        )
    }
}

/// One point of the exact surface, uniform by area: [`crate::synth`]'s sampler (the
/// constructions of its module docs), the normal dropped.
pub fn sample_truth<R: Rng + ?Sized>(t: &Truth, rng: &mut R) -> [f64; 3] {
    Sampler::new(t).sample_point(rng)
}

/// Summary of sampled unsigned distances, in the units of the surfaces (or relative, after
/// [`Distances::scaled`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Distances {
    /// Mean distance.
    pub mean: f64,
    /// Root mean square distance.
    pub rms: f64,
    /// 95th percentile.
    pub p95: f64,
    /// Largest distance (one-sided Hausdorff distance, as sampled).
    pub max: f64,
    /// Number of samples; the other fields are NaN when it is 0 (serialised as `null`).
    pub samples: usize,
}

impl Distances {
    /// Summarise `d` (reordered).
    pub fn from_values(d: &mut [f64]) -> Distances {
        if d.is_empty() {
            return Distances {
                mean: f64::NAN,
                rms: f64::NAN,
                p95: f64::NAN,
                max: f64::NAN,
                samples: 0,
            };
        }
        let n = d.len() as f64;
        // Sequential sums: a parallel reduction would add in an order that depends on work
        // stealing, and the figures must not change from run to run.
        let (s, s2) = d.iter().fold((0.0, 0.0), |a, &x| (a.0 + x, a.1 + x * x));
        let max = d.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let p95 = quantile(d, 0.95);
        Distances {
            mean: s / n,
            rms: (s2 / n).sqrt(),
            p95,
            max,
            samples: d.len(),
        }
    }

    /// Every distance multiplied by `s` (say `1 / diagonal`).
    pub fn scaled(&self, s: f64) -> Distances {
        Distances {
            mean: self.mean * s,
            rms: self.rms * s,
            p95: self.p95 * s,
            max: self.max * s,
            samples: self.samples,
        }
    }
}

/// Distances both ways between a mesh and a reference surface (exact truth, mesh or points).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TwoSided {
    /// From points on the mesh to the reference.
    pub to_reference: Distances,
    /// From points of the reference to the mesh.
    pub from_reference: Distances,
    /// Bounding-box diagonal of the reference, for relative figures.
    pub diagonal: f64,
}

impl TwoSided {
    /// The symmetric Hausdorff distance, as sampled (NaN when a side has no sample).
    pub fn hausdorff(&self) -> f64 {
        if self.to_reference.samples == 0 || self.from_reference.samples == 0 {
            return f64::NAN;
        }
        self.to_reference.max.max(self.from_reference.max)
    }

    /// Every distance divided by `diagonal` (whose own value becomes 1).
    pub fn relative(&self) -> TwoSided {
        let s = 1.0 / self.diagonal;
        TwoSided {
            to_reference: self.to_reference.scaled(s),
            from_reference: self.from_reference.scaled(s),
            diagonal: 1.0,
        }
    }
}

/// Distances of `samples` points uniform by area on `m` to `f`; none when `m` has no area.
fn from_mesh_samples(
    m: &Mesh,
    samples: usize,
    seed: u64,
    stream: u64,
    f: impl Fn([f64; 3]) -> Option<f64> + Sync,
) -> Vec<f64> {
    let sampler = AreaSampler::new(m);
    if !(sampler.area().is_finite() && sampler.area() > 0.0) {
        return Vec::new();
    }
    map_samples(samples, seed, stream, |rng| sampler.sample(rng), f)
}

/// Distances between mesh `m` and the exact surface `t`, `samples` points each way (seeded).
///
/// Mesh → truth: points uniform by area on the triangles of `m`, and their exact distance
/// [`Truth::distance`]. Truth → mesh: points uniform by area on `t` ([`sample_truth`]), and
/// their exact distance to the triangles of `m` ([`TriangleIndex`]). `diagonal` is that of
/// [`Truth::bounding_box`]. A mesh without area gets no mesh → truth sample and infinite
/// truth → mesh distances.
pub fn mesh_to_truth(m: &Mesh, t: &Truth, samples: usize, seed: u64) -> TwoSided {
    let mut to = from_mesh_samples(m, samples, seed, STREAM_MESH, |p| Some(t.distance(p)));
    let index = TriangleIndex::new(m);
    let sampler = Sampler::new(t);
    let mut from = map_samples(
        samples,
        seed,
        STREAM_TRUTH,
        |rng| sampler.sample_point(rng),
        |p| Some(index.distance(p)),
    );
    TwoSided {
        to_reference: Distances::from_values(&mut to),
        from_reference: Distances::from_values(&mut from),
        diagonal: t.bounding_box().diagonal(),
    }
}

/// A reference surface to compare a mesh with.
#[derive(Debug, Clone, Copy)]
pub enum Reference<'a> {
    /// A triangle mesh.
    Mesh(&'a Mesh),
    /// A point set (a scan, say).
    Points(&'a [[f64; 3]]),
}

/// Parameters of [`mesh_to_reference`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferenceParams {
    /// Samples each way (for a point reference, at most this many of its points).
    pub samples: usize,
    /// Seed of the samplers.
    pub seed: u64,
    /// When set, mesh samples farther than this (in the mesh's units) from every reference
    /// vertex or point are left out of mesh → reference, so that a reference with holes
    /// (a scan) does not charge the mesh for filling them. Choose it above the reference's
    /// sample spacing (edge length). Reference → mesh is not affected.
    pub restrict_to_reference: Option<f64>,
}

impl Default for ReferenceParams {
    fn default() -> ReferenceParams {
        ReferenceParams {
            samples: 100_000,
            seed: 0,
            restrict_to_reference: None,
        }
    }
}

/// Distances between mesh `m` and a reference mesh or point set.
///
/// * Mesh reference: `samples` points uniform by area on each mesh, and their exact distance
///   to the triangles of the other.
/// * Point reference: mesh → reference takes `samples` points on `m` and their distance to the
///   nearest reference point; reference → mesh takes the reference points themselves (all of
///   them when there are at most `samples`, else a seeded uniform subset of `samples`) and their
///   exact distance to the triangles of `m`.
///
/// `diagonal` is that of the reference's bounding box (all its vertices or points).
/// [`ReferenceParams::restrict_to_reference`] drops mesh samples far from the reference;
/// `to_reference.samples` counts those kept.
pub fn mesh_to_reference(m: &Mesh, reference: Reference<'_>, params: &ReferenceParams) -> TwoSided {
    let ref_points: &[[f64; 3]] = match reference {
        Reference::Mesh(r) => &r.vertices,
        Reference::Points(p) => p,
    };
    let bounds = ref_points.iter().fold(Aabb::EMPTY, |mut b, &p| {
        b.add(p);
        b
    });
    let diagonal = if bounds.is_empty() {
        0.0
    } else {
        bounds.diagonal()
    };
    let (seed, samples) = (params.seed, params.samples);
    let restrict = params.restrict_to_reference;
    let point_index = (restrict.is_some() || matches!(reference, Reference::Points(_)))
        .then(|| PointIndex::new(ref_points));
    let nearest_point = |p: [f64; 3]| {
        point_index
            .as_ref()
            .map_or(f64::INFINITY, |idx| idx.nearest_distance(p))
    };
    let keep = |p: [f64; 3]| restrict.is_none_or(|r| nearest_point(p) <= r);
    let mesh_index = TriangleIndex::new(m);
    let (mut to, mut from) = match reference {
        Reference::Mesh(r) => {
            let ref_index = TriangleIndex::new(r);
            let to = from_mesh_samples(m, samples, seed, STREAM_MESH, |p| {
                keep(p).then(|| ref_index.distance(p))
            });
            let from = from_mesh_samples(r, samples, seed, STREAM_REFERENCE, |p| {
                Some(mesh_index.distance(p))
            });
            (to, from)
        }
        Reference::Points(pts) => {
            let to = from_mesh_samples(m, samples, seed, STREAM_MESH, |p| {
                let d = nearest_point(p);
                restrict.is_none_or(|r| d <= r).then_some(d)
            });
            let from: Vec<f64> = if pts.len() <= samples {
                pts.par_iter().map(|&p| mesh_index.distance(p)).collect()
            } else {
                let mut rng = stream_rng(seed, STREAM_SUBSET, 0);
                let mut pick = rand::seq::index::sample(&mut rng, pts.len(), samples).into_vec();
                pick.sort_unstable();
                pick.par_iter()
                    .map(|&i| mesh_index.distance(pts[i]))
                    .collect()
            };
            (to, from)
        }
    };
    TwoSided {
        to_reference: Distances::from_values(&mut to),
        from_reference: Distances::from_values(&mut from),
        diagonal,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check_mesh;
    use crate::fixtures::{chord_error, grid, octahedron, signed_volume, uv_sphere};
    use crate::geom::vec::norm;
    use rand::SeedableRng;

    #[test]
    fn uv_sphere_is_close_to_the_sphere_both_ways() {
        let m = uv_sphere(60, 120);
        let c = check_mesh(&m);
        assert!(c.watertight && c.oriented && c.components == 1, "{c:?}");
        assert!(signed_volume(&m) > 0.0);
        let bound = chord_error(&m);
        let t = Truth::Sphere { radius: 1.0 };
        let d = mesh_to_truth(&m, &t, 20_000, 3);
        assert_eq!(
            (d.to_reference.samples, d.from_reference.samples),
            (20_000, 20_000)
        );
        assert!((d.diagonal - 12f64.sqrt()).abs() < 1e-12);
        for (name, s) in [("to", d.to_reference), ("from", d.from_reference)] {
            assert!(s.max <= bound * (1.0 + 1e-9), "{name}: {s:?} bound {bound}");
            assert!(s.max >= 0.5 * bound, "{name}: {s:?} bound {bound}");
            assert!(
                s.mean > 0.1 * bound && s.mean < s.rms && s.rms <= s.max,
                "{name}: {s:?}"
            );
        }
        // Deterministic in the seed.
        assert_eq!(mesh_to_truth(&m, &t, 20_000, 3), d);
        assert_ne!(mesh_to_truth(&m, &t, 20_000, 4), d);
        // A sphere of another radius is off by the difference.
        let d = mesh_to_truth(&m, &Truth::Sphere { radius: 1.1 }, 2000, 3);
        assert!((d.to_reference.mean - 0.1).abs() < 2.0 * bound);
        assert!((d.from_reference.mean - 0.1).abs() < 2.0 * bound);
    }

    #[test]
    fn truth_samples_lie_on_the_surface_uniformly() {
        let mut rng = Pcg64::seed_from_u64(5);
        for shape in crate::synth::Shape::ALL {
            let t = Truth::standard(shape);
            let n = if shape == crate::synth::Shape::Bumpy {
                200
            } else {
                2000
            };
            for _ in 0..n {
                let p = sample_truth(&t, &mut rng);
                assert!(t.distance(p) < 1e-9, "{shape}: {p:?}");
            }
        }
        // Torus: the outer half (cos v > 0) holds (πR + 2r) / (2πR) of the area.
        let (big, small) = (1.0, 0.35);
        let t = Truth::Torus {
            major_radius: big,
            minor_radius: small,
        };
        let n = 40_000;
        let outer = (0..n)
            .filter(|_| {
                let p = sample_truth(&t, &mut rng);
                p[0].hypot(p[1]) > big
            })
            .count();
        let want = (std::f64::consts::PI * big + 2.0 * small) / (std::f64::consts::TAU * big);
        assert!(
            (outer as f64 / n as f64 - want).abs() < 0.01,
            "{outer} {want}"
        );
        // Two sheets: the inner sphere holds r2² / (r1² + r2²) of the area.
        let t = Truth::TwoSheets {
            outer_radius: 1.0,
            inner_radius: 0.5,
        };
        let inner = (0..n)
            .filter(|_| norm(sample_truth(&t, &mut rng)) < 0.75)
            .count();
        assert!((inner as f64 / n as f64 - 0.2).abs() < 0.01, "{inner}");
    }

    #[test]
    fn mesh_against_reference_mesh_and_points() {
        let params = ReferenceParams {
            samples: 5000,
            ..ReferenceParams::default()
        };
        let m = grid(20, 1.0, 0.0);
        let same = mesh_to_reference(&m, Reference::Mesh(&m), &params);
        assert!(same.hausdorff() < 1e-15, "{same:?}");
        assert!((same.diagonal - 2f64.sqrt()).abs() < 1e-15);

        // A parallel plane 0.01 above, coarser: exactly 0.01 both ways.
        let up = grid(7, 1.0, 0.01);
        let d = mesh_to_reference(&m, Reference::Mesh(&up), &params);
        for s in [d.to_reference, d.from_reference] {
            assert!(
                (s.mean - 0.01).abs() < 1e-12 && (s.max - 0.01).abs() < 1e-12,
                "{s:?}"
            );
        }

        // Points: the grid's own vertices. Reference → mesh is 0, mesh → points at most
        // half a cell diagonal.
        let cell = 1.0 / 20.0;
        let d = mesh_to_reference(&m, Reference::Points(&m.vertices), &params);
        assert_eq!(d.from_reference.samples, m.vertices.len());
        assert!(d.from_reference.max < 1e-15);
        assert!(d.to_reference.max <= cell * 0.5f64.sqrt() + 1e-12);
        assert!(d.to_reference.mean > 0.2 * cell);
        // More points than samples: a seeded subset.
        let few = ReferenceParams {
            samples: 100,
            ..params
        };
        let d = mesh_to_reference(&m, Reference::Points(&m.vertices), &few);
        assert_eq!(d.from_reference.samples, 100);

        // A reference covering half of the mesh: without restriction the far half counts.
        let half: Vec<[f64; 3]> = m.vertices.iter().copied().filter(|p| p[0] <= 0.5).collect();
        let d = mesh_to_reference(&m, Reference::Points(&half), &params);
        assert!(d.to_reference.max > 0.4);
        let restricted = ReferenceParams {
            restrict_to_reference: Some(2.0 * cell),
            ..params
        };
        let d = mesh_to_reference(&m, Reference::Points(&half), &restricted);
        assert!(d.to_reference.max <= 2.0 * cell);
        let kept = d.to_reference.samples as f64 / params.samples as f64;
        assert!((kept - 0.6).abs() < 0.05, "{kept}");
        let half_mesh = grid(10, 0.5, 0.0);
        let d = mesh_to_reference(&m, Reference::Mesh(&half_mesh), &restricted);
        assert!(d.to_reference.max <= 2.0 * cell);
        assert!(d.from_reference.max < 1e-15);
    }

    #[test]
    fn empty_meshes_give_no_samples() {
        let e = Mesh::default();
        let t = Truth::Sphere { radius: 1.0 };
        let d = mesh_to_truth(&e, &t, 100, 0);
        assert_eq!(d.to_reference.samples, 0);
        assert!(d.to_reference.mean.is_nan() && d.hausdorff().is_nan());
        assert_eq!(d.from_reference.max, f64::INFINITY);
        let params = ReferenceParams {
            samples: 100,
            restrict_to_reference: Some(1.0),
            ..ReferenceParams::default()
        };
        let o = octahedron();
        let d = mesh_to_reference(&o, Reference::Mesh(&e), &params);
        assert_eq!((d.to_reference.samples, d.diagonal), (0, 0.0));
        let d = mesh_to_reference(&o, Reference::Points(&[]), &params);
        assert_eq!((d.to_reference.samples, d.from_reference.samples), (0, 0));
        let d = mesh_to_reference(&e, Reference::Mesh(&o), &params);
        assert_eq!(d.from_reference.max, f64::INFINITY);
        let c = check_mesh(&e);
        assert_eq!((c.components, c.diagonal), (0, 0.0));
        assert!(c.watertight);
    }

    /// Scale, 10M triangles: `cargo test --lib -- --ignored check_mesh_scale --nocapture`
    /// (about 1 s for `check_mesh` and 7 s for `mesh_to_reference` on 2 cores, 1.7 GB).
    #[test]
    #[ignore]
    fn check_mesh_scale() {
        let m = grid(2237, 1.0, 0.0);
        let started = std::time::Instant::now();
        let c = check_mesh(&m);
        eprintln!(
            "check_mesh: {} triangles in {:.2} s",
            c.triangles,
            started.elapsed().as_secs_f64()
        );
        assert_eq!(c.boundary_edges, 4 * 2237);
        let started = std::time::Instant::now();
        let idx = TriangleIndex::new(&m);
        eprintln!(
            "TriangleIndex::new: {:.2} s",
            started.elapsed().as_secs_f64()
        );
        let started = std::time::Instant::now();
        let s: f64 = (0..100_000)
            .into_par_iter()
            .map(|i| idx.distance([i as f64 * 1e-5, 0.3, 0.01]))
            .sum();
        eprintln!(
            "100k queries 0.01 above the grid: {:.2} s",
            started.elapsed().as_secs_f64()
        );
        assert!((s - 1000.0).abs() < 1e-9);
        drop(idx);
        let started = std::time::Instant::now();
        let d = mesh_to_reference(&m, Reference::Mesh(&m), &ReferenceParams::default());
        eprintln!(
            "mesh_to_reference, itself, 100k samples each way: {:.2} s",
            started.elapsed().as_secs_f64()
        );
        assert_eq!(d.hausdorff(), 0.0);
    }
}
