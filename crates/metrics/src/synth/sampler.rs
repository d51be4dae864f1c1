//! Sampling the exact surfaces uniformly by area (the constructions of the module docs of
//! [`crate::synth`]), for the points `synth` writes and the truth samples of
//! [`crate`]. The height field is the exception for `synth`'s points, which are
//! uniform in `(x, y)` as a terrain scan is; its truth samples are uniform by area.

use rand::Rng;
use rand_distr::StandardNormal;

use super::bumpy::Bumpy;
use super::heightfield::HeightField;
use super::rng::chunk_rng;
use super::truth::Truth;
use crate::geom::vec::{dot, norm, scale, sub};
use crate::types::{Aabb, PointBatch};

/// A shape ready to sample.
#[derive(Debug, Clone, Copy)]
// The height field's bumps make it ~300 bytes: one per sampler, never in bulk.
#[allow(clippy::large_enum_variant)]
pub(crate) enum Sampler {
    /// A sphere of radius `radius`.
    Sphere {
        /// Radius.
        radius: f64,
    },
    /// A ring torus around the z axis.
    Torus {
        /// Major radius R.
        major: f64,
        /// Minor radius r.
        minor: f64,
    },
    /// Two concentric spheres.
    TwoSheets {
        /// Outer radius.
        outer: f64,
        /// Inner radius.
        inner: f64,
        /// Probability of the outer sphere, its share of the area.
        p_outer: f64,
    },
    /// The bumpy sphere.
    Bumpy {
        /// The relief.
        model: Bumpy,
        /// Bound of the area element per solid angle ([`Bumpy::area_density_bound`]).
        bound: f64,
    },
    /// The height field.
    HeightField {
        /// The graph.
        model: HeightField,
        /// Bound of the area element per unit of plane area, `sqrt(1 + slope bound²)`.
        bound: f64,
    },
}

impl Sampler {
    /// Parameters and precomputed constants for sampling `truth`.
    pub(crate) fn new(truth: &Truth) -> Sampler {
        match *truth {
            Truth::Sphere { radius } => Sampler::Sphere { radius },
            Truth::Torus {
                major_radius,
                minor_radius,
            } => Sampler::Torus {
                major: major_radius,
                minor: minor_radius,
            },
            Truth::TwoSheets {
                outer_radius,
                inner_radius,
            } => {
                let (a, b) = (outer_radius * outer_radius, inner_radius * inner_radius);
                Sampler::TwoSheets {
                    outer: outer_radius,
                    inner: inner_radius,
                    p_outer: a / (a + b),
                }
            }
            Truth::Bumpy {
                radius,
                amplitude,
                frequency,
            } => {
                let model = Bumpy::new(radius, amplitude, frequency);
                Sampler::Bumpy {
                    model,
                    bound: model.area_density_bound(),
                }
            }
            Truth::HeightField {
                half_width,
                tilt,
                bumps,
            } => {
                let model = HeightField::new(half_width, tilt, bumps);
                Sampler::HeightField {
                    model,
                    bound: model.slope_bound().hypot(1.0),
                }
            }
        }
    }

    /// One point of the surface and its unit normal: uniform by area, but for the height
    /// field, uniform in `(x, y)` over its square (the upward normal).
    pub(crate) fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> ([f64; 3], [f64; 3]) {
        match *self {
            Sampler::Sphere { radius } => {
                let u = uniform_direction(rng);
                (scale(u, radius), u)
            }
            Sampler::TwoSheets {
                outer,
                inner,
                p_outer,
            } => {
                let pick_outer = rng.random::<f64>() < p_outer;
                let u = uniform_direction(rng);
                if pick_outer {
                    (scale(u, outer), u)
                } else {
                    (scale(u, inner), scale(u, -1.0))
                }
            }
            Sampler::Torus { major, minor } => {
                let (su, cu) = (std::f64::consts::TAU * rng.random::<f64>()).sin_cos();
                let (sv, cv) = loop {
                    let v = std::f64::consts::TAU * rng.random::<f64>();
                    let (sv, cv) = v.sin_cos();
                    if rng.random::<f64>() * (major + minor) < major + minor * cv {
                        break (sv, cv);
                    }
                };
                let ring = major + minor * cv;
                ([ring * cu, ring * su, minor * sv], [cv * cu, cv * su, sv])
            }
            Sampler::Bumpy { model, bound } => {
                let (u, r, grad_s) = bumpy_direction(&model, bound, rng);
                let m = sub(u, scale(grad_s, 1.0 / r));
                (scale(u, r), scale(m, 1.0 / norm(m)))
            }
            Sampler::HeightField { model, .. } => {
                let (x, y) = plane_point(&model, rng);
                ([x, y, model.value(x, y)], model.normal(x, y))
            }
        }
    }

    /// One point of the surface, uniform by area, from the same random numbers as
    /// [`Sampler::sample`]. The bumpy point is placed at [`Bumpy::radius_at`], the form
    /// [`Truth::distance`] measures with (it may differ from [`Sampler::sample`]'s position
    /// in the last bit): `scanflow check`'s figures are computed from these points. The
    /// height field's point is uniform by area (unlike [`Sampler::sample`]'s): a uniform
    /// `(x, y)` kept with probability `sqrt(1 + |∇h|²) / bound`.
    pub(crate) fn sample_point<R: Rng + ?Sized>(&self, rng: &mut R) -> [f64; 3] {
        match *self {
            Sampler::Bumpy { model, bound } => {
                let (u, _, _) = bumpy_direction(&model, bound, rng);
                scale(u, model.radius_at(u))
            }
            Sampler::HeightField { model, bound } => loop {
                let (x, y) = plane_point(&model, rng);
                let (h, g) = model.value_and_gradient(x, y);
                if rng.random::<f64>() * bound < g[0].hypot(g[1]).hypot(1.0) {
                    return [x, y, h];
                }
            },
            _ => self.sample(rng).0,
        }
    }
}

/// A direction `u` of the bumpy sphere kept with probability `dA/dΩ(u) / bound`, with `r(u)`
/// and the gradient of `r` on the unit sphere there.
fn bumpy_direction<R: Rng + ?Sized>(
    model: &Bumpy,
    bound: f64,
    rng: &mut R,
) -> ([f64; 3], f64, [f64; 3]) {
    loop {
        let u = uniform_direction(rng);
        let (r, grad_s) = model.radius_and_surface_gradient(u);
        let density = r * (r * r + dot(grad_s, grad_s)).sqrt();
        if rng.random::<f64>() * bound < density {
            return (u, r, grad_s);
        }
    }
}

/// A point uniform in the height field's square.
fn plane_point<R: Rng + ?Sized>(model: &HeightField, rng: &mut R) -> (f64, f64) {
    let l = model.half_width();
    let x = l * (2.0 * rng.random::<f64>() - 1.0);
    let y = l * (2.0 * rng.random::<f64>() - 1.0);
    (x, y)
}

/// A uniform unit vector (Archimedes: `z` uniform, longitude uniform).
pub(crate) fn uniform_direction<R: Rng + ?Sized>(rng: &mut R) -> [f64; 3] {
    let z = 2.0 * rng.random::<f64>() - 1.0;
    let (s, c) = (std::f64::consts::TAU * rng.random::<f64>()).sin_cos();
    let rho = (1.0 - z * z).max(0.0).sqrt();
    [rho * c, rho * s, z]
}

/// Generate the `n` points of chunk `chunk`: positions rounded to float32 (as written), unit
/// normals, and the bounds of the positions.
pub(super) fn generate_chunk(
    sampler: &Sampler,
    seed: u64,
    chunk: u64,
    n: usize,
    sigma: f64,
) -> (PointBatch, Aabb) {
    let mut rng = chunk_rng(seed, chunk);
    let mut batch = PointBatch {
        pos: Vec::with_capacity(n),
        normal: Vec::with_capacity(n),
        ..Default::default()
    };
    let mut bounds = Aabb::EMPTY;
    for _ in 0..n {
        let (mut p, nrm) = sampler.sample(&mut rng);
        if sigma > 0.0 {
            for c in &mut p {
                let z: f64 = rng.sample(StandardNormal);
                *c += sigma * z;
            }
        }
        let p = p.map(|c| c as f32 as f64);
        bounds.add(p);
        batch.pos.push(p);
        batch.normal.push(nrm.map(|c| c as f32));
    }
    (batch, bounds)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::Shape;

    #[test]
    fn torus_is_uniform_by_area() {
        let mut rng = chunk_rng(3, 0);
        let s = Sampler::new(&Truth::standard(Shape::Torus));
        let n = 200_000;
        // Share of the outer half (cos v > 0): (pi R + 2 r) / (2 pi R).
        let outer = (0..n)
            .filter(|_| {
                let (p, _) = s.sample(&mut rng);
                p[0].hypot(p[1]) > 1.0
            })
            .count() as f64
            / n as f64;
        let expect = 0.5 + 0.35 / std::f64::consts::PI;
        let sd = (expect * (1.0 - expect) / n as f64).sqrt();
        assert!((outer - expect).abs() < 5.0 * sd, "{outer} vs {expect}");
    }

    #[test]
    fn heightfield_points_are_uniform_in_the_plane() {
        let s = Sampler::new(&Truth::standard(Shape::HeightField));
        let mut rng = chunk_rng(5, 1);
        let n = 160_000;
        let mut cells = [0u32; 16];
        for _ in 0..n {
            let (p, _) = s.sample(&mut rng);
            assert!(
                p[0] >= -1.0 && p[0] < 1.0 && p[1] >= -1.0 && p[1] < 1.0,
                "{p:?}"
            );
            let (i, k) = (((p[0] + 1.0) * 2.0) as usize, ((p[1] + 1.0) * 2.0) as usize);
            cells[4 * i.min(3) + k.min(3)] += 1;
        }
        // Equal shares of the 4 x 4 cells of the square: chi-square, 15 degrees of freedom
        // (the 0.999 quantile is 37.7).
        let e = n as f64 / 16.0;
        let chi2: f64 = cells.iter().map(|&c| (c as f64 - e).powi(2) / e).sum();
        assert!(chi2 < 37.7, "{chi2} {cells:?}");
    }

    #[test]
    fn heightfield_truth_samples_are_uniform_by_area() {
        let t = Truth::standard(Shape::HeightField);
        let Truth::HeightField {
            half_width,
            tilt,
            bumps,
        } = t
        else {
            panic!("{t:?}")
        };
        let m = HeightField::new(half_width, tilt, bumps);
        // Area-weighted mean of |∇h|² by the midpoint rule (a mean uniform in the plane is
        // smaller: steep ground has more area per unit of plane).
        let q = 1000;
        let (mut num, mut den, mut plain) = (0.0, 0.0, 0.0);
        for i in 0..q {
            for k in 0..q {
                let x = -1.0 + 2.0 * (i as f64 + 0.5) / q as f64;
                let y = -1.0 + 2.0 * (k as f64 + 0.5) / q as f64;
                let (_, g) = m.value_and_gradient(x, y);
                let g2 = g[0] * g[0] + g[1] * g[1];
                let w = (1.0 + g2).sqrt();
                num += w * g2;
                den += w;
                plain += g2;
            }
        }
        let expect = num / den;
        let plain = plain / (q * q) as f64;
        let s = Sampler::new(&t);
        let mut rng = chunk_rng(13, 2);
        let n = 200_000;
        let (mut sum, mut sum2) = (0.0, 0.0);
        for _ in 0..n {
            let p = s.sample_point(&mut rng);
            let (h, g) = m.value_and_gradient(p[0], p[1]);
            assert_eq!(h, p[2]);
            let g2 = g[0] * g[0] + g[1] * g[1];
            sum += g2;
            sum2 += g2 * g2;
        }
        let mean = sum / n as f64;
        let sd = ((sum2 / n as f64 - mean * mean) / n as f64).sqrt();
        assert!(
            (mean - expect).abs() < 5.0 * sd,
            "{mean} vs {expect} (sd {sd})"
        );
        // The test tells the two samplings apart.
        assert!(expect - plain > 20.0 * sd, "{expect} vs {plain} (sd {sd})");
    }

    #[test]
    fn bumpy_is_uniform_by_area() {
        let m = Bumpy::new(1.0, 0.05, 8.0);
        let g = |u: [f64; 3]| (8.0 * u[0]).sin() * (8.0 * u[1]).sin() * (8.0 * u[2]).sin();
        // Area-weighted mean of g by quadrature (uniform directions would give 0).
        let (nt, np) = (1200, 2400);
        let (mut num, mut den) = (0.0, 0.0);
        for i in 0..nt {
            let t = std::f64::consts::PI * (i as f64 + 0.5) / nt as f64;
            for j in 0..np {
                let ph = std::f64::consts::TAU * (j as f64 + 0.5) / np as f64;
                let u = [t.sin() * ph.cos(), t.sin() * ph.sin(), t.cos()];
                let (r, gs) = m.radius_and_surface_gradient(u);
                let w = r * (r * r + dot(gs, gs)).sqrt() * t.sin();
                num += w * g(u);
                den += w;
            }
        }
        let expect = num / den;
        assert!(expect > 0.005, "{expect}");
        let s = Sampler::new(&Truth::standard(Shape::Bumpy));
        let mut rng = chunk_rng(11, 5);
        let n = 400_000;
        let (mut sum, mut sum2) = (0.0, 0.0);
        for _ in 0..n {
            let (p, _) = s.sample(&mut rng);
            let v = g(scale(p, 1.0 / norm(p)));
            sum += v;
            sum2 += v * v;
        }
        let mean = sum / n as f64;
        let sd = ((sum2 / n as f64 - mean * mean) / n as f64).sqrt();
        assert!(
            (mean - expect).abs() < 5.0 * sd,
            "{mean} vs {expect} (sd {sd})"
        );
    }
}
