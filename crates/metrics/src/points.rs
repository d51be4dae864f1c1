//! `scanflow check` on a point cloud: the distance of every point to an exact surface or to a
//! reference, and how much of the bumpy sphere's relief the points keep.
//!
//! # Distances ([`point_distances`])
//!
//! Every point is measured, none sampled: to a truth, by [`Truth::distance`] (exact); to a
//! reference mesh, by the exact point-to-triangle distance ([`TriangleIndex`]); to a reference
//! point set, by the distance to its nearest point ([`PointIndex`]). The summary
//! ([`PointDistances`]) is the RMS, mean, 99th percentile ([`quantile`]) and maximum, each also
//! divided by the bounding-box diagonal of the truth ([`Truth::bounding_box`]) or reference.
//!
//! For a scan of an exact surface with isotropic Gaussian noise of standard deviation `σ` per
//! coordinate (what `scanflow synth --noise` adds, `σ = noise · diagonal`), the distance of a
//! point is, to first order in `σ / curvature radius`, the absolute value of the noise's normal
//! component, itself `N(0, σ²)`: the RMS distance is `σ` and the mean `σ √(2/π)`, so `rms_rel`
//! reads the noise level back.
//!
//! # Relief ([`relief_scale`])
//!
//! The bumpy sphere is the radial graph `r(u) = R (1 + a g(u))`,
//! `g(u) = sin(k u_x) sin(k u_y) sin(k u_z)` over unit directions `u`. For points `p` with
//! `u = p / |p|`, the relief they carry is fitted as the least-squares scale `s` of
//! `|p| - R ≈ s · R a g(u)`:
//!
//! `s = Σ (|p| - R) R a g(u) / Σ (R a g(u))²`.
//!
//! Points exactly on the surface give `s = 1`; a smoothing that flattens the bumps towards the
//! base sphere gives `s < 1` (0 for the sphere itself). Zero-mean noise along the radius leaves
//! `s` unbiased, but noise across it moves `u` and so `g(u)`, the regressor (errors in
//! variables): `s` is diluted by about `var(g) / (var(g) + var(∇g · δu))`, a fraction of a
//! percent for `synth`'s default bumpy sphere at noise 0.002. Compare a filter's `s` with the
//! noisy input's, not only with 1.
//!
//! Sums are sequential over the points in file order, and the per-point distances are
//! computed in parallel into their own slots: the figures do not depend on the number of
//! threads.

use std::fmt;
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::Serialize;

use super::report::read_points;
use super::{PointIndex, Reference, TriangleIndex, quantile};
use crate::error::{Error, Result};
use crate::geom::vec::norm;
use crate::io::mesh_read::{is_mesh_file, read_any_mesh};
use crate::synth::Truth;
use crate::types::Aabb;

/// Whether `path` holds points rather than a mesh: a PLY file whose header declares no `face`
/// element or a `face` element without records, or any file that is not a PLY (the point
/// readers of [`crate::io::open`] decide whether they can read it).
pub fn is_point_file(path: &Path) -> Result<bool> {
    Ok(!is_mesh_file(path)?)
}

/// Summary of per-point unsigned distances, in input units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PointDistances {
    /// Root mean square distance.
    pub rms: f64,
    /// Mean distance.
    pub mean: f64,
    /// 99th percentile ([`quantile`] with `q = 0.99`).
    pub p99: f64,
    /// Largest distance.
    pub max: f64,
}

impl PointDistances {
    /// Summarise `d` (reordered); NaN everywhere for an empty slice.
    pub fn from_values(d: &mut [f64]) -> PointDistances {
        if d.is_empty() {
            return PointDistances {
                rms: f64::NAN,
                mean: f64::NAN,
                p99: f64::NAN,
                max: f64::NAN,
            };
        }
        let n = d.len() as f64;
        let (s, s2) = d.iter().fold((0.0, 0.0), |a, &x| (a.0 + x, a.1 + x * x));
        let max = d.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        PointDistances {
            rms: (s2 / n).sqrt(),
            mean: s / n,
            p99: quantile(d, 0.99),
            max,
        }
    }

    /// Every distance multiplied by `s` (say `1 / diagonal`).
    pub fn scaled(&self, s: f64) -> PointDistances {
        PointDistances {
            rms: self.rms * s,
            mean: self.mean * s,
            p99: self.p99 * s,
            max: self.max * s,
        }
    }
}

/// What the points are measured against.
#[derive(Debug, Clone, Copy)]
pub enum PointTarget<'a> {
    /// An exact surface.
    Truth(&'a Truth),
    /// A reference mesh or point set.
    Reference(Reference<'a>),
}

/// The distance of every point of `points` to `target`, in the order of `points`.
pub fn point_distances(points: &[[f64; 3]], target: PointTarget<'_>) -> Vec<f64> {
    match target {
        PointTarget::Truth(t) => points.par_iter().map(|&p| t.distance(p)).collect(),
        PointTarget::Reference(Reference::Mesh(m)) => {
            let index = TriangleIndex::new(m);
            points.par_iter().map(|&p| index.distance(p)).collect()
        }
        PointTarget::Reference(Reference::Points(r)) => {
            let index = PointIndex::new(r);
            points
                .par_iter()
                .map(|&p| index.nearest_distance(p))
                .collect()
        }
    }
}

/// The least-squares scale `s` of the bumpy sphere's relief in `points` (see the module docs):
/// `None` unless `t` is a bumpy sphere with a non-zero relief, or when no point (other than
/// the origin) sees any relief.
pub fn relief_scale(points: &[[f64; 3]], t: &Truth) -> Option<f64> {
    let Truth::Bumpy {
        radius,
        amplitude,
        frequency,
    } = *t
    else {
        return None;
    };
    let ra = radius * amplitude;
    let (sxy, sxx) = points.iter().fold((0.0f64, 0.0f64), |(sxy, sxx), &p| {
        let l = norm(p);
        if l <= 0.0 {
            return (sxy, sxx);
        }
        let g = (frequency * p[0] / l).sin()
            * (frequency * p[1] / l).sin()
            * (frequency * p[2] / l).sin();
        let x = ra * g;
        (sxy + x * (l - radius), sxx + x * x)
    });
    (sxx > 0.0).then(|| sxy / sxx)
}

/// What the points of a [`PointsReport`] were compared with.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum PointsAgainst {
    /// Nothing: counts and bounds only.
    Nothing,
    /// The exact surface of a truth file.
    Truth,
    /// A reference mesh.
    ReferenceMesh,
    /// A reference point set.
    ReferencePoints,
}

/// The result of `scanflow check` on a point file. Serialised flat (one JSON object whose
/// distance keys are `rms`, `mean`, `p99`, `max` and the same with `_rel`); figures that were
/// not measured are NaN, written `null` in JSON.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PointsReport {
    /// The point file.
    pub input: PathBuf,
    /// Number of points.
    pub points: usize,
    /// Bounds of the points.
    pub bounds: Aabb,
    /// What the points were compared with.
    pub against: PointsAgainst,
    /// The truth or reference file, if any.
    pub reference: Option<PathBuf>,
    /// The shape of the truth, if one was given (`"sphere"`, `"bumpy"`...).
    pub shape: Option<String>,
    /// Bounding-box diagonal of the truth or reference (input units); NaN without either.
    pub diagonal: f64,
    /// RMS distance to the truth or reference (input units).
    pub rms: f64,
    /// Mean distance.
    pub mean: f64,
    /// 99th percentile of the distances.
    pub p99: f64,
    /// Largest distance.
    pub max: f64,
    /// `rms / diagonal`.
    pub rms_rel: f64,
    /// `mean / diagonal`.
    pub mean_rel: f64,
    /// `p99 / diagonal`.
    pub p99_rel: f64,
    /// `max / diagonal`.
    pub max_rel: f64,
    /// See [`relief_scale`]: only for a bumpy-sphere truth (`null` otherwise).
    pub relief_scale: Option<f64>,
}

/// Check the point file `input`: every point's distance to the exact surface of the truth
/// file `truth` (from `scanflow synth`) or to the reference `reference` (a PLY with faces is
/// read as a mesh, any other file as points), and for a bumpy-sphere truth the relief scale.
/// Giving both a truth and a reference is an [`Error::Usage`]; a file without any point, or
/// one the point readers cannot read, is an input error naming it.
pub fn run_check_points(
    input: &Path,
    truth: Option<&Path>,
    reference: Option<&Path>,
) -> Result<PointsReport> {
    if truth.is_some() && reference.is_some() {
        return Err(Error::Usage(
            "give a truth file or a reference, not both".to_string(),
        ));
    }
    // A bad truth file is reported before a large point file is read.
    let truth = truth
        .map(|path| Truth::load(path).map(|t| (path, t)))
        .transpose()?;
    let pts = read_points(input)?;
    if pts.is_empty() {
        return Err(Error::input(
            input,
            "holds no point: expected a point cloud",
        ));
    }
    let bounds = bounds_of(&pts);
    let mut report = PointsReport {
        input: input.to_path_buf(),
        points: pts.len(),
        bounds,
        against: PointsAgainst::Nothing,
        reference: None,
        shape: None,
        diagonal: f64::NAN,
        rms: f64::NAN,
        mean: f64::NAN,
        p99: f64::NAN,
        max: f64::NAN,
        rms_rel: f64::NAN,
        mean_rel: f64::NAN,
        p99_rel: f64::NAN,
        max_rel: f64::NAN,
        relief_scale: None,
    };
    let (mut d, diagonal) = if let Some((path, t)) = truth {
        report.against = PointsAgainst::Truth;
        report.reference = Some(path.to_path_buf());
        report.shape = Some(t.shape().name().to_string());
        report.relief_scale = relief_scale(&pts, &t);
        (
            point_distances(&pts, PointTarget::Truth(&t)),
            t.bounding_box().diagonal(),
        )
    } else if let Some(path) = reference {
        report.reference = Some(path.to_path_buf());
        if is_mesh_file(path)? {
            let m = read_any_mesh(path)?;
            report.against = PointsAgainst::ReferenceMesh;
            (
                point_distances(&pts, PointTarget::Reference(Reference::Mesh(&m))),
                bounds_of(&m.vertices).diagonal(),
            )
        } else {
            let r = read_points(path)?;
            if r.is_empty() {
                return Err(Error::input(path, "holds no point: expected a reference"));
            }
            report.against = PointsAgainst::ReferencePoints;
            (
                point_distances(&pts, PointTarget::Reference(Reference::Points(&r))),
                bounds_of(&r).diagonal(),
            )
        }
    } else {
        return Ok(report);
    };
    let abs = PointDistances::from_values(&mut d);
    let rel = abs.scaled(1.0 / diagonal);
    report.diagonal = diagonal;
    (report.rms, report.mean, report.p99, report.max) = (abs.rms, abs.mean, abs.p99, abs.max);
    (
        report.rms_rel,
        report.mean_rel,
        report.p99_rel,
        report.max_rel,
    ) = (rel.rms, rel.mean, rel.p99, rel.max);
    Ok(report)
}

/// The bounding box of `pts`.
fn bounds_of(pts: &[[f64; 3]]) -> Aabb {
    pts.iter().fold(Aabb::EMPTY, |mut b, &p| {
        b.add(p);
        b
    })
}

impl fmt::Display for PointsReport {
    /// A readable summary, one fact a line.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let p = |v: [f64; 3]| format!("[{:.6}, {:.6}, {:.6}]", v[0], v[1], v[2]);
        writeln!(f, "points {}", self.input.display())?;
        write!(
            f,
            "  {} points, bounds {} .. {}",
            self.points,
            p(self.bounds.min),
            p(self.bounds.max)
        )?;
        let what = match (self.against, &self.shape) {
            (PointsAgainst::Nothing, _) => return Ok(()),
            (PointsAgainst::Truth, Some(s)) => format!("exact {s} surface"),
            (PointsAgainst::Truth, None) => "exact surface".to_string(),
            (PointsAgainst::ReferenceMesh, _) => "reference mesh".to_string(),
            (PointsAgainst::ReferencePoints, _) => "nearest reference point".to_string(),
        };
        writeln!(f)?;
        writeln!(
            f,
            "distance of every point to the {what} {} (diagonal {:.6}):",
            self.reference
                .as_deref()
                .map_or(String::new(), |r| r.display().to_string()),
            self.diagonal
        )?;
        writeln!(
            f,
            "  {:<10} {:>11} {:>11} {:>11} {:>11}",
            "", "rms", "mean", "p99", "max"
        )?;
        writeln!(
            f,
            "  {:<10} {:>11.4e} {:>11.4e} {:>11.4e} {:>11.4e}",
            "absolute", self.rms, self.mean, self.p99, self.max
        )?;
        write!(
            f,
            "  {:<10} {:>11.4e} {:>11.4e} {:>11.4e} {:>11.4e}",
            "/ diagonal", self.rms_rel, self.mean_rel, self.p99_rel, self.max_rel
        )?;
        if let Some(s) = self.relief_scale {
            write!(
                f,
                "\n  relief scale {s:.6} (1: the bumps kept, 0: flattened to the base sphere)"
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{uv_sphere, write_ascii_mesh};
    use crate::geom::vec::scale;
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;
    use rand_pcg::Pcg64;

    /// A unit direction, uniform on the sphere.
    fn direction(rng: &mut Pcg64) -> [f64; 3] {
        let z: f64 = 2.0 * rng.random::<f64>() - 1.0;
        let phi: f64 = std::f64::consts::TAU * rng.random::<f64>();
        let rho = (1.0 - z * z).sqrt();
        [rho * phi.cos(), rho * phi.sin(), z]
    }

    /// Write `pts` as an XYZ file.
    fn write_xyz(path: &Path, pts: &[[f64; 3]]) {
        let text: String = pts
            .iter()
            .map(|p| format!("{:.17e} {:.17e} {:.17e}\n", p[0], p[1], p[2]))
            .collect();
        std::fs::write(path, text).unwrap();
    }

    fn save_truth(path: &Path, t: Truth) {
        crate::synth::TruthFile {
            truth: t,
            noise: 0.0,
            noise_sigma: 0.0,
            points: 0,
            seed: 0,
            bounding_box: t.bounding_box(),
            sample_bounding_box: None,
        }
        .save(path)
        .unwrap();
    }

    #[test]
    fn relief_scale_recovers_a_scaled_relief() {
        let t = Truth::Bumpy {
            radius: 2.0,
            amplitude: 0.05,
            frequency: 8.0,
        };
        let mut rng = Pcg64::seed_from_u64(11);
        let dirs: Vec<[f64; 3]> = (0..5000).map(|_| direction(&mut rng)).collect();
        // r_s(u) = R (1 + s a g(u)): the fit must return s exactly (up to rounding).
        for s in [1.0, 0.3, 0.0, -0.5] {
            let pts: Vec<[f64; 3]> = dirs
                .iter()
                .map(|&u| {
                    let g = (8.0 * u[0]).sin() * (8.0 * u[1]).sin() * (8.0 * u[2]).sin();
                    scale(u, 2.0 * (1.0 + s * 0.05 * g))
                })
                .collect();
            let got = relief_scale(&pts, &t).unwrap();
            assert!((got - s).abs() < 1e-9, "s = {s}: fitted {got}");
        }
        // Points on the exact surface (its own radial graph) give 1; a flat relief or another
        // shape gives no figure.
        let on: Vec<[f64; 3]> = dirs
            .iter()
            .map(|&u| {
                scale(
                    u,
                    2.0 + 0.1 * (8.0 * u[0]).sin() * (8.0 * u[1]).sin() * (8.0 * u[2]).sin(),
                )
            })
            .collect();
        assert!((relief_scale(&on, &t).unwrap() - 1.0).abs() < 1e-12);
        let flat = Truth::Bumpy {
            radius: 1.0,
            amplitude: 0.0,
            frequency: 8.0,
        };
        assert_eq!(relief_scale(&on, &flat), None);
        assert_eq!(relief_scale(&on, &Truth::Sphere { radius: 1.0 }), None);
        assert_eq!(relief_scale(&[[0.0; 3]], &t), None);
    }

    #[test]
    fn distances_to_a_sphere_match_radial_offsets() {
        let t = Truth::Sphere { radius: 1.0 };
        let mut rng = Pcg64::seed_from_u64(3);
        // Point i at radius 1 + (i - 50) / 1000: distance |i - 50| / 1000.
        let pts: Vec<[f64; 3]> = (0..101)
            .map(|i| scale(direction(&mut rng), 1.0 + (i as f64 - 50.0) / 1000.0))
            .collect();
        let mut d = point_distances(&pts, PointTarget::Truth(&t));
        for (i, di) in d.iter().enumerate() {
            assert!((di - (i as f64 - 50.0).abs() / 1000.0).abs() < 1e-15);
        }
        let s = PointDistances::from_values(&mut d);
        // Closed forms over k = |i - 50| / 1000: sum k = 2 * 1275, sum k² = 2 * 42925.
        assert!((s.mean - 2550.0 / 101.0 / 1000.0).abs() < 1e-15);
        assert!((s.rms - (85850.0f64 / 101.0).sqrt() / 1000.0).abs() < 1e-15);
        // Sorted: 0, then each of 0.001..0.05 twice; the 99th percentile is index
        // round(100 * 0.99) = 99, the first 0.05; index 97 would be 0.049.
        assert!((s.p99 - 0.05).abs() < 1e-15 && (s.max - 0.05).abs() < 1e-15);
        assert!(PointDistances::from_values(&mut []).rms.is_nan());
    }

    #[test]
    fn gaussian_noise_reads_back_as_rms_over_diagonal() {
        // synth's noise: N(0, σ²) on each coordinate, σ = noise · diagonal; the distance is
        // |normal component| to first order, so rms / diagonal = noise, mean = rms √(2/π).
        let t = Truth::Sphere { radius: 1.0 };
        let noise = 0.002;
        let sigma = noise * t.bounding_box().diagonal();
        let mut rng = Pcg64::seed_from_u64(7);
        let pts: Vec<[f64; 3]> = (0..40_000)
            .map(|_| {
                let u = direction(&mut rng);
                let e: [f64; 3] =
                    std::array::from_fn(|_| sigma * rng.sample::<f64, _>(StandardNormal));
                [u[0] + e[0], u[1] + e[1], u[2] + e[2]]
            })
            .collect();
        let mut d = point_distances(&pts, PointTarget::Truth(&t));
        let s = PointDistances::from_values(&mut d).scaled(1.0 / t.bounding_box().diagonal());
        // Standard error of the RMS: noise / √(2n) = 0.35 %.
        assert!((s.rms / noise - 1.0).abs() < 0.015, "rms_rel {}", s.rms);
        let ratio = s.mean / s.rms;
        assert!(
            (ratio - (2.0 / std::f64::consts::PI).sqrt()).abs() < 0.01,
            "{ratio}"
        );
    }

    #[test]
    fn reference_distances_match_brute_force() {
        let mut rng = Pcg64::seed_from_u64(5);
        let cloud = |rng: &mut Pcg64, n| -> Vec<[f64; 3]> {
            (0..n)
                .map(|_| std::array::from_fn(|_| rng.random::<f64>()))
                .collect()
        };
        let (pts, reference) = (cloud(&mut rng, 300), cloud(&mut rng, 500));
        let d = point_distances(&pts, PointTarget::Reference(Reference::Points(&reference)));
        for (p, di) in pts.iter().zip(&d) {
            let brute = reference
                .iter()
                .map(|q| norm([p[0] - q[0], p[1] - q[1], p[2] - q[2]]))
                .fold(f64::INFINITY, f64::min);
            assert!((di - brute).abs() < 1e-12, "{di} vs {brute}");
        }
        // Against a mesh: every vertex of the mesh is at distance 0 from it.
        let sphere = uv_sphere(8, 16);
        let d = point_distances(
            &sphere.vertices,
            PointTarget::Reference(Reference::Mesh(&sphere)),
        );
        assert!(d.iter().all(|&x| x < 1e-12));
    }

    #[test]
    fn run_check_points_end_to_end_and_errors() {
        let dir = tempfile::tempdir().unwrap();
        let mut rng = Pcg64::seed_from_u64(9);
        let pts: Vec<[f64; 3]> = (0..200)
            .map(|i| {
                scale(
                    direction(&mut rng),
                    1.0 + if i % 2 == 0 { 0.01 } else { -0.01 },
                )
            })
            .collect();
        let xp = dir.path().join("p.xyz");
        write_xyz(&xp, &pts);
        let tp = dir.path().join("s.truth.json");
        save_truth(&tp, Truth::Sphere { radius: 1.0 });
        assert!(is_point_file(&xp).unwrap());

        let r = run_check_points(&xp, Some(&tp), None).unwrap();
        assert_eq!((r.points, r.against), (200, PointsAgainst::Truth));
        assert!((r.rms - 0.01).abs() < 1e-12 && (r.max - 0.01).abs() < 1e-12);
        let diag = 2.0 * 3f64.sqrt();
        assert!((r.rms_rel - 0.01 / diag).abs() < 1e-12);
        assert_eq!(r.relief_scale, None);
        let json = serde_json::to_string(&r).unwrap();
        for key in [
            "\"points\":200",
            "\"rms_rel\":",
            "\"p99\":",
            "\"relief_scale\":null",
        ] {
            assert!(json.contains(key), "{key} not in {json}");
        }
        assert!(r.to_string().contains("exact sphere surface"), "{r}");

        // The points as their own reference; a mesh as a reference; no target.
        let r = run_check_points(&xp, None, Some(&xp)).unwrap();
        assert_eq!(r.against, PointsAgainst::ReferencePoints);
        assert_eq!(r.max, 0.0);
        let mp = dir.path().join("m.ply");
        write_ascii_mesh(&mp, &uv_sphere(8, 16));
        assert!(!is_point_file(&mp).unwrap());
        let r = run_check_points(&xp, None, Some(&mp)).unwrap();
        assert_eq!(r.against, PointsAgainst::ReferenceMesh);
        assert!(r.max < 0.2);
        let r = run_check_points(&xp, None, None).unwrap();
        assert!(r.rms.is_nan() && r.against == PointsAgainst::Nothing);
        assert!(serde_json::to_string(&r).unwrap().contains("\"rms\":null"));

        // Errors: both targets, an empty file, garbage.
        let e = run_check_points(&xp, Some(&tp), Some(&xp)).unwrap_err();
        assert!(matches!(e, Error::Usage(_)), "{e}");
        let empty = dir.path().join("e.xyz");
        std::fs::write(&empty, "").unwrap();
        let e = run_check_points(&empty, Some(&tp), None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("e.xyz"), "{e}");
        let bad = dir.path().join("bad.ply");
        std::fs::write(&bad, "this is not a point file\n").unwrap();
        let e = run_check_points(&bad, Some(&tp), None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("bad.ply"), "{e}");
    }
}
