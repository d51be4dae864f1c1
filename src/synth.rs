//! `scanflow synth`: synthetic point clouds sampled from surfaces known exactly.
//!
//! [`synth`] writes a binary PLY with `x y z nx ny nz` (float32) sampled uniformly by area
//! from one of the [`Shape`]s, optionally displaced by isotropic Gaussian noise, and a
//! `OUT.truth.json` next to it describing the exact surface ([`TruthFile`]). [`Truth`] loads
//! that description back and measures the distance from any point to the exact surface, so
//! that a reconstruction can be scored.
//!
//! # Shapes
//!
//! All are centred at the origin:
//!
//! * `sphere`: radius 1.
//! * `torus`: axis z, major radius R = 1, minor radius r = 0.35.
//! * `twosheets`: two concentric spheres of radii 1 and 0.97, the faces of a thin solid shell.
//!   Normals point out of the solid: outward on the outer sphere, toward the centre on the
//!   inner one.
//! * `bumpy`: the radial graph `s(u) = r(u) u` over unit directions `u`, with
//!   `r(u) = R (1 + a sin(k u_x) sin(k u_y) sin(k u_z))`, R = 1, a = 0.05, k = 8. Normals are
//!   the normalised gradient of `F(p) = |p| - r(p/|p|)`.
//!
//! # Sampling
//!
//! Every shape is sampled exactly uniformly with respect to surface area:
//!
//! * sphere: `z` uniform in [-1, 1), longitude uniform (Archimedes).
//! * torus: longitude uniform; the minor angle `v` uniform, kept with probability
//!   `(R + r cos v) / (R + r)` (the area element relative to its maximum).
//! * twosheets: each point picks the outer sphere with probability `R1² / (R1² + R2²)` (its
//!   share of the total area), then a uniform point on that sphere.
//! * bumpy: a uniform direction `u`, kept with probability `dA/dΩ (u) / B` where
//!   `dA/dΩ = r sqrt(r² + |∇r|²) = r² |∇F| / (u·∇F)` is the area element of the radial graph per
//!   unit solid angle (`∇r` the gradient of `r` on the unit sphere) and
//!   `B = R(1+|a|) sqrt(R²(1+|a|)² + (R a k)²)` bounds it (since `|∇g| ≤ k` for
//!   `g = sin sin sin`). Accepted directions are therefore distributed exactly as area.
//!
//! Noise: each coordinate gets an independent normal deviate of standard deviation
//! `noise × diagonal`, where `diagonal` is that of the exact surface's bounding box. Normals are
//! those of the exact surface at the undisplaced sample.
//!
//! # Determinism, streaming, parallelism
//!
//! Points are generated in chunks of [`CHUNK_POINTS`]; chunk `i` draws from its own PCG64
//! generator seeded from `(seed, i)` only, so the output is byte-identical whatever the
//! number of threads. A rayon pool generates groups of `2 × threads` chunks while the calling
//! thread writes the previous group in order; at most two groups (`4 × threads` chunks of about
//! 2.4 MB each) are held at a time, so memory does not depend on the number of points.

use std::fmt;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Instant;

use rand::Rng;
use rand_distr::StandardNormal;
use rand_pcg::Pcg64;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{Error, IoContext, Location, Result};
use crate::io::ply_write::PointPlyWriter;
use crate::types::{Aabb, Attributes, PointBatch};

/// Points generated per chunk; chunk `i` holds points `i × CHUNK_POINTS ..`.
pub const CHUNK_POINTS: u64 = 65536;

/// The surfaces `synth` samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Shape {
    /// Unit sphere.
    Sphere,
    /// Torus around the z axis, R = 1, r = 0.35.
    Torus,
    /// Two concentric spheres, radii 1 and 0.97 (a thin shell).
    TwoSheets,
    /// Unit sphere with a sinusoidal relief.
    Bumpy,
}

impl Shape {
    /// Every shape, in the order of the help text.
    pub const ALL: [Shape; 4] = [Shape::Sphere, Shape::Torus, Shape::TwoSheets, Shape::Bumpy];

    /// The name used on the command line and in truth files.
    pub fn name(self) -> &'static str {
        match self {
            Shape::Sphere => "sphere",
            Shape::Torus => "torus",
            Shape::TwoSheets => "twosheets",
            Shape::Bumpy => "bumpy",
        }
    }
}

impl fmt::Display for Shape {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Shape {
    type Err = Error;

    /// Parse a shape name (ASCII case-insensitive).
    fn from_str(s: &str) -> Result<Shape> {
        let t = s.trim();
        Shape::ALL
            .into_iter()
            .find(|sh| sh.name().eq_ignore_ascii_case(t))
            .ok_or_else(|| {
                let names: Vec<&str> = Shape::ALL.iter().map(|s| s.name()).collect();
                Error::Usage(format!(
                    "unknown shape \"{s}\": expected one of {}",
                    names.join(", ")
                ))
            })
    }
}

/// Parameters of [`synth`].
#[derive(Debug, Clone, PartialEq)]
pub struct SynthParams {
    /// The surface to sample.
    pub shape: Shape,
    /// Number of points, at least 1.
    pub points: u64,
    /// Noise standard deviation relative to the bounding-box diagonal of the exact surface
    /// (finite, non-negative; 0 for points exactly on the surface).
    pub noise: f64,
    /// Seed of the generators; the output is a function of the parameters and the seed only.
    pub seed: u64,
    /// Worker threads; 0 picks one per logical CPU. Does not change the output.
    pub threads: usize,
}

/// What [`synth`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthReport {
    /// Points written.
    pub points: u64,
    /// Bounds of the points as written (float32 positions, noise included).
    pub bounds: Aabb,
    /// Wall-clock seconds.
    pub secs: f64,
}

/// An exact surface with its parameters, as stored under `"shape"` and `"params"` in a truth
/// file (`{"shape":"torus","params":{"major_radius":1.0,"minor_radius":0.35}}`). All surfaces
/// are centred at the origin.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "shape", content = "params", rename_all = "lowercase")]
pub enum Truth {
    /// A sphere.
    Sphere {
        /// Radius.
        radius: f64,
    },
    /// A ring torus around the z axis.
    Torus {
        /// Distance from the centre to the centre of the tube (R).
        major_radius: f64,
        /// Radius of the tube (r < R).
        minor_radius: f64,
    },
    /// Two concentric spheres bounding a shell.
    TwoSheets {
        /// Radius of the outer sphere.
        outer_radius: f64,
        /// Radius of the inner sphere (smaller than the outer one).
        inner_radius: f64,
    },
    /// The radial graph `r(u) = radius (1 + amplitude sin(k u_x) sin(k u_y) sin(k u_z))`,
    /// `k = frequency`, over unit directions `u`.
    Bumpy {
        /// Base radius R.
        radius: f64,
        /// Relative relief amplitude a (|a| < 1).
        amplitude: f64,
        /// Angular frequency k.
        frequency: f64,
    },
}

/// The contents of `OUT.truth.json`: the exact surface and how it was sampled.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthFile {
    /// The exact surface (`"shape"` and `"params"`).
    #[serde(flatten)]
    pub truth: Truth,
    /// Noise relative to the diagonal of `bounding_box`.
    pub noise: f64,
    /// Absolute noise standard deviation per coordinate.
    pub noise_sigma: f64,
    /// Number of points.
    pub points: u64,
    /// Seed.
    pub seed: u64,
    /// Bounding box of the exact surface.
    pub bounding_box: Aabb,
    /// Bounding box of the points written (noise included). Absent in files that do not
    /// carry it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sample_bounding_box: Option<Aabb>,
}

impl TruthFile {
    /// Read and check a truth file.
    pub fn load(path: &Path) -> Result<TruthFile> {
        let bytes = std::fs::read(path).with_path(path)?;
        let file: TruthFile = serde_json::from_slice(&bytes).map_err(|e| {
            let location = if e.line() > 0 {
                Location::Line(e.line() as u64)
            } else {
                Location::File
            };
            Error::format(path, location, format!("not a scanflow truth file: {e}"))
        })?;
        file.truth
            .validate()
            .map_err(|msg| Error::input(path, format!("invalid surface: {msg}")))?;
        Ok(file)
    }

    /// Write to `path` through a temporary file renamed into place.
    pub fn save(&self, path: &Path) -> Result<()> {
        let mut json = serde_json::to_vec_pretty(self)
            .map_err(|e| Error::Internal(format!("cannot encode the truth file: {e}")))?;
        json.push(b'\n');
        write_atomic(path, &json)
    }
}

impl Truth {
    /// The surface `synth` samples for `shape`.
    pub fn standard(shape: Shape) -> Truth {
        match shape {
            Shape::Sphere => Truth::Sphere { radius: 1.0 },
            Shape::Torus => Truth::Torus {
                major_radius: 1.0,
                minor_radius: 0.35,
            },
            Shape::TwoSheets => Truth::TwoSheets {
                outer_radius: 1.0,
                inner_radius: 0.97,
            },
            Shape::Bumpy => Truth::Bumpy {
                radius: 1.0,
                amplitude: 0.05,
                frequency: 8.0,
            },
        }
    }

    /// The kind of surface.
    pub fn shape(&self) -> Shape {
        match self {
            Truth::Sphere { .. } => Shape::Sphere,
            Truth::Torus { .. } => Shape::Torus,
            Truth::TwoSheets { .. } => Shape::TwoSheets,
            Truth::Bumpy { .. } => Shape::Bumpy,
        }
    }

    /// Read the surface from a truth file written by [`synth`].
    pub fn load(path: &Path) -> Result<Truth> {
        TruthFile::load(path).map(|f| f.truth)
    }

    /// Check that the parameters describe a valid surface; the message says what is wrong.
    pub fn validate(&self) -> std::result::Result<(), String> {
        let positive = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("{name} is {v}, expected a finite positive number"))
            }
        };
        match *self {
            Truth::Sphere { radius } => positive("radius", radius),
            Truth::Torus {
                major_radius,
                minor_radius,
            } => {
                positive("major_radius", major_radius)?;
                positive("minor_radius", minor_radius)?;
                if minor_radius >= major_radius {
                    return Err(format!(
                        "minor_radius {minor_radius} is not smaller than major_radius \
                         {major_radius}, expected a ring torus"
                    ));
                }
                Ok(())
            }
            Truth::TwoSheets {
                outer_radius,
                inner_radius,
            } => {
                positive("outer_radius", outer_radius)?;
                positive("inner_radius", inner_radius)?;
                if inner_radius >= outer_radius {
                    return Err(format!(
                        "inner_radius {inner_radius} is not smaller than outer_radius \
                         {outer_radius}"
                    ));
                }
                Ok(())
            }
            Truth::Bumpy {
                radius,
                amplitude,
                frequency,
            } => {
                positive("radius", radius)?;
                if !(amplitude.is_finite() && amplitude.abs() < 1.0) {
                    return Err(format!(
                        "amplitude is {amplitude}, expected a number between -1 and 1"
                    ));
                }
                if !(frequency.is_finite() && frequency >= 0.0) {
                    return Err(format!(
                        "frequency is {frequency}, expected a finite non-negative number"
                    ));
                }
                Ok(())
            }
        }
    }

    /// The bounding box of the surface. For `bumpy` it is computed numerically (to about
    /// 1e-12): the relief's symmetries make it the cube `[-b, b]³` with
    /// `b = max_u r(u) u_x`.
    pub fn bounding_box(&self) -> Aabb {
        let cube = |b: f64| Aabb {
            min: [-b; 3],
            max: [b; 3],
        };
        match *self {
            Truth::Sphere { radius } => cube(radius),
            Truth::TwoSheets { outer_radius, .. } => cube(outer_radius),
            Truth::Torus {
                major_radius,
                minor_radius,
            } => {
                let e = major_radius + minor_radius;
                Aabb {
                    min: [-e, -e, -minor_radius],
                    max: [e, e, minor_radius],
                }
            }
            Truth::Bumpy {
                radius,
                amplitude,
                frequency,
            } => cube(Bumpy::new(radius, amplitude, frequency).max_extent()),
        }
    }

    /// Unsigned Euclidean distance from `p` to the surface.
    ///
    /// Closed form for the sphere, torus and two spheres. For `bumpy` it is found
    /// numerically: the radial projection of `p` bounds the distance and so the cone of
    /// directions where the nearest point can lie; that cone is sampled, and damped Newton
    /// iterations on `|p - s(u)|²` (tangent-plane parameterisation, exact gradient) run from
    /// the radial direction and the best separated samples. The result is never more than the
    /// distance to any surface point tried and, for points within 0.1 of the default surface,
    /// agrees with a brute-force search to better than 1e-9 relative.
    pub fn distance(&self, p: [f64; 3]) -> f64 {
        match *self {
            Truth::Sphere { radius } => (norm(p) - radius).abs(),
            Truth::TwoSheets {
                outer_radius,
                inner_radius,
            } => {
                let l = norm(p);
                (l - outer_radius).abs().min((l - inner_radius).abs())
            }
            Truth::Torus {
                major_radius,
                minor_radius,
            } => {
                let q = p[0].hypot(p[1]) - major_radius;
                (q.hypot(p[2]) - minor_radius).abs()
            }
            Truth::Bumpy {
                radius,
                amplitude,
                frequency,
            } => Bumpy::new(radius, amplitude, frequency).distance(p),
        }
    }

    /// Parameters and precomputed constants for sampling.
    fn sampler(&self) -> Sampler {
        match *self {
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
        }
    }
}

/// The truth file that goes with `out`: `.ply` (any case) removed, `.truth.json` appended
/// (`scan.ply` → `scan.truth.json`, `scan` → `scan.truth.json`).
pub fn truth_path(out: &Path) -> PathBuf {
    let is_ply = out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ply"));
    let base = if is_ply {
        out.file_stem()
    } else {
        out.file_name()
    };
    match base {
        Some(b) => {
            let mut name = b.to_os_string();
            name.push(".truth.json");
            out.with_file_name(name)
        }
        None => out.join("truth.json"),
    }
}

/// Check the parameters of [`synth`].
fn validate(params: &SynthParams, out: &Path) -> Result<()> {
    if out.file_name().is_none() {
        return Err(Error::Usage(format!(
            "output \"{}\" is not a file name, expected e.g. out.ply",
            out.display()
        )));
    }
    if params.points == 0 {
        return Err(Error::Usage(
            "--points is 0, expected at least 1 point".to_string(),
        ));
    }
    if !(params.noise.is_finite() && params.noise >= 0.0) {
        return Err(Error::Usage(format!(
            "--noise is {}, expected a finite number >= 0 (a fraction of the bounding-box \
             diagonal)",
            params.noise
        )));
    }
    Ok(())
}

/// Sample `params.points` points of `params.shape`, write them to `out` (binary PLY, float32
/// `x y z nx ny nz`) and the exact surface to [`truth_path`]`(out)`. `progress` receives the
/// number of points written so far after every chunk.
///
/// Both files are written to temporary names and renamed into place, the PLY first. The
/// truth file's `bounding_box` is that of the exact surface (the one `noise` is relative to);
/// `sample_bounding_box` that of the points written. Bad parameters (no points, negative or
/// non-finite noise, an output path without a file name) are [`Error::Usage`]s, reported
/// before any file is touched.
pub fn synth(
    params: &SynthParams,
    out: &Path,
    progress: &mut dyn FnMut(u64),
) -> Result<SynthReport> {
    validate(params, out)?;
    let started = Instant::now();
    let truth = Truth::standard(params.shape);
    let sampler = truth.sampler();
    let exact_box = truth.bounding_box();
    let sigma = params.noise * exact_box.diagonal();
    let truth_out = truth_path(out);

    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(params.threads)
        .thread_name(|i| format!("synth-{i}"))
        .build()
        .map_err(|e| Error::Internal(format!("cannot start the synth threads: {e}")))?;
    let group = 2 * pool.current_num_threads().max(1) as u64;
    let n_chunks = params.points.div_ceil(CHUNK_POINTS);
    let total = params.points;
    let seed = params.seed;

    let attrs = Attributes {
        normal: true,
        ..Default::default()
    };
    let mut writer = PointPlyWriter::create(out, total, attrs)?;
    let mut bounds = Aabb::EMPTY;
    let mut written = 0u64;

    let (tx, rx) = std::sync::mpsc::sync_channel::<Vec<(PointBatch, Aabb)>>(0);
    let streamed: Result<()> = std::thread::scope(|s| {
        let pool = &pool;
        let sampler = &sampler;
        let producer = s.spawn(move || {
            let mut first = 0u64;
            while first < n_chunks {
                let last = first.saturating_add(group).min(n_chunks);
                let chunks: Vec<(PointBatch, Aabb)> = pool.install(|| {
                    (first..last)
                        .into_par_iter()
                        .map(|c| {
                            let n = (total - c * CHUNK_POINTS).min(CHUNK_POINTS) as usize;
                            generate_chunk(sampler, seed, c, n, sigma)
                        })
                        .collect()
                });
                if tx.send(chunks).is_err() {
                    // The writer gave up; its error is what gets reported.
                    return;
                }
                first = last;
            }
        });
        let mut result = Ok(());
        'groups: for chunks in rx.iter() {
            for (batch, b) in chunks {
                if let Err(e) = writer.write(&batch) {
                    result = Err(e);
                    break 'groups;
                }
                written += batch.len() as u64;
                bounds = bounds.union(&b);
                progress(written);
            }
        }
        // Unblock the producer if it is waiting to hand over a group.
        drop(rx);
        if producer.join().is_err() {
            return Err(Error::Internal(
                "a synth worker thread panicked".to_string(),
            ));
        }
        result
    });
    streamed?;
    if written != total {
        return Err(Error::Internal(format!(
            "synth generated {written} points instead of {total}"
        )));
    }
    writer.finish()?;

    let record = TruthFile {
        truth,
        noise: params.noise,
        noise_sigma: sigma,
        points: total,
        seed,
        bounding_box: exact_box,
        sample_bounding_box: Some(bounds),
    };
    record.save(&truth_out)?;

    Ok(SynthReport {
        points: written,
        bounds,
        secs: started.elapsed().as_secs_f64(),
    })
}

/// Write `bytes` to `path` through `path.tmp-<pid>`, synced, then renamed.
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(format!(".tmp-{}", std::process::id()));
    let tmp = PathBuf::from(tmp);
    let attempt = (|| -> Result<()> {
        let mut f = File::create(&tmp).with_path(&tmp)?;
        f.write_all(bytes).with_path(&tmp)?;
        f.sync_all().with_path(&tmp)?;
        drop(f);
        std::fs::rename(&tmp, path).with_path(path)
    })();
    if attempt.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    attempt
}

// ---------------------------------------------------------------------------------------------
// Sampling.

/// A shape ready to sample.
#[derive(Debug, Clone, Copy)]
enum Sampler {
    Sphere {
        radius: f64,
    },
    Torus {
        major: f64,
        minor: f64,
    },
    TwoSheets {
        outer: f64,
        inner: f64,
        p_outer: f64,
    },
    Bumpy {
        model: Bumpy,
        bound: f64,
    },
}

impl Sampler {
    /// One point of the surface, uniform by area, and its unit normal.
    fn sample<R: Rng>(&self, rng: &mut R) -> ([f64; 3], [f64; 3]) {
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
            Sampler::Bumpy { model, bound } => loop {
                let u = uniform_direction(rng);
                let (r, grad_s) = model.radius_and_surface_gradient(u);
                let density = r * (r * r + dot(grad_s, grad_s)).sqrt();
                if rng.random::<f64>() * bound < density {
                    let m = sub(u, scale(grad_s, 1.0 / r));
                    break (scale(u, r), scale(m, 1.0 / norm(m)));
                }
            },
        }
    }
}

/// A uniform unit vector.
fn uniform_direction<R: Rng>(rng: &mut R) -> [f64; 3] {
    let z = 2.0 * rng.random::<f64>() - 1.0;
    let (s, c) = (std::f64::consts::TAU * rng.random::<f64>()).sin_cos();
    let rho = (1.0 - z * z).max(0.0).sqrt();
    [rho * c, rho * s, z]
}

/// The SplitMix64 finaliser, a bijection of `u64`.
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The generator of chunk `chunk`: its 128-bit state is an injective function of
/// `(seed, chunk)` built from SplitMix64 steps, so no two chunks or seeds share a stream start.
fn chunk_rng(seed: u64, chunk: u64) -> Pcg64 {
    const GOLDEN: u64 = 0x9e37_79b9_7f4a_7c15;
    let hi = mix64(seed.wrapping_add(GOLDEN));
    let lo = mix64(chunk.wrapping_add(GOLDEN) ^ mix64(seed ^ 0x5851_f42d_4c95_7f2d));
    Pcg64::new(
        ((hi as u128) << 64) | lo as u128,
        0xa02b_dbf7_bb3c_0a7a_c28f_a16a_64ab_f96f,
    )
}

/// Generate the `n` points of chunk `chunk`: positions rounded to float32 (as written), unit
/// normals, and the bounds of the positions.
fn generate_chunk(
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

// ---------------------------------------------------------------------------------------------
// The bumpy sphere.

/// `r(u) = radius (1 + amplitude g(u))`, `g(u) = sin(k u_x) sin(k u_y) sin(k u_z)`.
#[derive(Debug, Clone, Copy)]
struct Bumpy {
    radius: f64,
    amplitude: f64,
    k: f64,
}

/// Most directions sampled when looking for starting points of the distance search.
const MAX_DISTANCE_SAMPLES: f64 = 200_000.0;

impl Bumpy {
    fn new(radius: f64, amplitude: f64, k: f64) -> Bumpy {
        Bumpy {
            radius,
            amplitude,
            k,
        }
    }

    /// `r(u)` and the Euclidean gradient of `x ↦ radius (1 + a g(x))` at `u` (its tangential
    /// part is the gradient of `r` on the unit sphere).
    #[inline]
    fn radius_and_gradient(&self, u: [f64; 3]) -> (f64, [f64; 3]) {
        let k = self.k;
        let (sx, cx) = (k * u[0]).sin_cos();
        let (sy, cy) = (k * u[1]).sin_cos();
        let (sz, cz) = (k * u[2]).sin_cos();
        let g = sx * sy * sz;
        let ra = self.radius * self.amplitude;
        let f = ra * k;
        (
            self.radius + ra * g,
            [f * cx * sy * sz, f * sx * cy * sz, f * sx * sy * cz],
        )
    }

    /// `r(u)`.
    #[inline]
    fn radius_at(&self, u: [f64; 3]) -> f64 {
        let k = self.k;
        self.radius
            * (1.0 + self.amplitude * (k * u[0]).sin() * (k * u[1]).sin() * (k * u[2]).sin())
    }

    /// `r(u)` and the gradient of `r` on the unit sphere (tangent to it at `u`).
    #[inline]
    fn radius_and_surface_gradient(&self, u: [f64; 3]) -> (f64, [f64; 3]) {
        let (r, g) = self.radius_and_gradient(u);
        (r, sub(g, scale(u, dot(u, g))))
    }

    /// An upper bound of the area element per solid angle, `r sqrt(r² + |∇r|²)`.
    fn area_density_bound(&self) -> f64 {
        let r_max = self.radius * (1.0 + self.amplitude.abs());
        let grad_max = self.radius * self.amplitude.abs() * self.k;
        r_max * (r_max * r_max + grad_max * grad_max).sqrt()
    }

    /// `max_u r(u) u_x`, the half-width of the bounding cube.
    fn max_extent(&self) -> f64 {
        let a = self.amplitude.abs();
        if a == 0.0 || self.k == 0.0 {
            return self.radius;
        }
        // r(e_x) = R, so the maximum lies where u_x >= 1 / (1 + |a|).
        let t_max = (1.0 / (1.0 + a)).acos();
        let f = |t: f64, phi: f64| {
            let (st, ct) = t.sin_cos();
            let (sp, cp) = phi.sin_cos();
            self.radius_at([ct, st * cp, st * sp]) * ct
        };
        let n_t = ((t_max * self.k * 40.0).ceil() as usize).clamp(64, 2000);
        let n_p = ((std::f64::consts::TAU * t_max * self.k * 40.0).ceil() as usize).clamp(64, 4000);
        let dt = t_max / n_t as f64;
        let dp = std::f64::consts::TAU / n_p as f64;
        let (mut bt, mut bp, mut best) = (0.0, 0.0, f(0.0, 0.0));
        for i in 0..=n_t {
            let t = i as f64 * dt;
            for j in 0..n_p {
                let phi = j as f64 * dp;
                let v = f(t, phi);
                if v > best {
                    (bt, bp, best) = (t, phi, v);
                }
            }
        }
        // Pattern search around the best grid node.
        let (mut st, mut sp) = (dt, dp);
        while st > 1e-14 || sp > 1e-14 {
            let mut moved = false;
            for (ot, op) in [
                (st, 0.0),
                (-st, 0.0),
                (0.0, sp),
                (0.0, -sp),
                (st, sp),
                (st, -sp),
                (-st, sp),
                (-st, -sp),
            ] {
                let v = f(bt + ot, bp + op);
                if v > best {
                    (bt, bp, best) = (bt + ot, bp + op, v);
                    moved = true;
                    break;
                }
            }
            if !moved {
                st *= 0.5;
                sp *= 0.5;
            }
        }
        best
    }

    /// `½ |s(u) - p|²` with `u = normalise(u0 + α e1 + β e2)`, and its gradient in `(α, β)`.
    #[inline]
    fn objective(&self, p: [f64; 3], frame: &Frame, ab: [f64; 2]) -> (f64, [f64; 2]) {
        let w = add(frame.u, add(scale(frame.e1, ab[0]), scale(frame.e2, ab[1])));
        let nw = norm(w);
        let u = scale(w, 1.0 / nw);
        let (r, grad) = self.radius_and_gradient(u);
        let res = sub(scale(u, r), p);
        let h = 0.5 * dot(res, res);
        let mut g = [0.0; 2];
        for (gi, e) in g.iter_mut().zip([frame.e1, frame.e2]) {
            let du = scale(sub(e, scale(u, dot(u, e))), 1.0 / nw);
            let ds = add(scale(u, dot(grad, du)), scale(du, r));
            *gi = dot(res, ds);
        }
        (h, g)
    }

    /// `½ |s(u) - p|²`.
    #[inline]
    fn half_sq(&self, p: [f64; 3], u: [f64; 3]) -> f64 {
        let res = sub(scale(u, self.radius_at(u)), p);
        0.5 * dot(res, res)
    }

    /// Damped Newton descent of `½ |s(u) - p|²` from `u`; returns the value reached.
    fn descend(&self, p: [f64; 3], start: [f64; 3]) -> f64 {
        const FD: f64 = 1e-5;
        const MAX_STEP: f64 = 0.2;
        let mut u = start;
        let mut h = self.half_sq(p, u);
        for _ in 0..100 {
            let frame = Frame::at(u);
            let (h0, g) = self.objective(p, &frame, [0.0, 0.0]);
            h = h0;
            if g[0] == 0.0 && g[1] == 0.0 {
                break;
            }
            // Hessian by central differences of the exact gradient.
            let (_, gap) = self.objective(p, &frame, [FD, 0.0]);
            let (_, gam) = self.objective(p, &frame, [-FD, 0.0]);
            let (_, gbp) = self.objective(p, &frame, [0.0, FD]);
            let (_, gbm) = self.objective(p, &frame, [0.0, -FD]);
            let h00 = (gap[0] - gam[0]) / (2.0 * FD);
            let h11 = (gbp[1] - gbm[1]) / (2.0 * FD);
            let h01 = 0.25 * ((gap[1] - gam[1]) + (gbp[0] - gbm[0])) / FD;
            let half_tr = 0.5 * (h00 + h11);
            let disc = (0.25 * (h00 - h11) * (h00 - h11) + h01 * h01).sqrt();
            let (lmin, lmax) = (half_tr - disc, half_tr + disc);
            let size = lmin.abs().max(lmax.abs()).max(1e-12);
            // Shift to positive definite where the model is not convex.
            let mu = if lmin < 1e-3 * size {
                1e-3 * size - lmin + 0.05 * size
            } else {
                0.0
            };
            let (a, b, c) = (h00 + mu, h01, h11 + mu);
            let det = a * c - b * b;
            let mut step = [-(c * g[0] - b * g[1]) / det, -(a * g[1] - b * g[0]) / det];
            if !(step[0].is_finite() && step[1].is_finite()) {
                let gn = (g[0] * g[0] + g[1] * g[1]).sqrt();
                step = [-g[0] / gn * 1e-3, -g[1] / gn * 1e-3];
            }
            let len = step[0].hypot(step[1]);
            if len > MAX_STEP {
                step = [step[0] * MAX_STEP / len, step[1] * MAX_STEP / len];
            }
            let slope = g[0] * step[0] + g[1] * step[1];
            if slope >= 0.0 {
                break;
            }
            let mut t = 1.0;
            let mut accepted = None;
            for _ in 0..40 {
                let w = add(
                    frame.u,
                    add(scale(frame.e1, t * step[0]), scale(frame.e2, t * step[1])),
                );
                let un = scale(w, 1.0 / norm(w));
                let ht = self.half_sq(p, un);
                if ht <= h0 + 1e-4 * t * slope {
                    accepted = Some((un, ht));
                    break;
                }
                t *= 0.5;
                if t * len < 1e-17 {
                    break;
                }
            }
            match accepted {
                Some((un, ht)) => {
                    u = un;
                    h = ht;
                    if t * step[0].hypot(step[1]) < 1e-14 {
                        break;
                    }
                }
                None => break,
            }
        }
        h
    }

    /// Distance from `p` to the surface; see [`Truth::distance`].
    fn distance(&self, p: [f64; 3]) -> f64 {
        let rp = norm(p);
        let up = if rp > 0.0 {
            scale(p, 1.0 / rp)
        } else {
            [0.0, 0.0, 1.0]
        };
        // The radial point is on the surface: its distance bounds the answer.
        let d_radial = (rp - self.radius_at(up)).abs();
        let mut best_h = 0.5 * d_radial * d_radial;
        if self.amplitude == 0.0 || self.k == 0.0 {
            return d_radial;
        }

        // Sample the directions where the nearest point can lie.
        let mut spacing = (0.25 / self.k).min(0.03);
        let global = d_radial >= rp * 0.999 || (d_radial / rp).asin() > 1.0;
        let mut samples: Vec<([f64; 3], f64)> = Vec::new();
        if global {
            let mut n = (4.0 * std::f64::consts::PI / (spacing * spacing)).ceil();
            if n > MAX_DISTANCE_SAMPLES {
                n = MAX_DISTANCE_SAMPLES;
                spacing = (4.0 * std::f64::consts::PI / n).sqrt();
            }
            let n = n as usize;
            let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
            for i in 0..n {
                let z = 1.0 - (2 * i + 1) as f64 / n as f64;
                let rho = (1.0 - z * z).max(0.0).sqrt();
                let (s, c) = (golden * i as f64).sin_cos();
                let u = [rho * c, rho * s, z];
                samples.push((u, self.half_sq(p, u)));
            }
        } else {
            let theta_max = (d_radial / rp).asin() * 1.01 + 1e-12;
            let area = std::f64::consts::PI * theta_max * theta_max;
            if area / (spacing * spacing) > MAX_DISTANCE_SAMPLES {
                spacing = (area / MAX_DISTANCE_SAMPLES).sqrt();
            }
            let frame = Frame::at(up);
            let rings = (theta_max / spacing).ceil() as usize;
            for j in 1..=rings {
                let th = theta_max * j as f64 / rings as f64;
                let (st, ct) = th.sin_cos();
                let m = ((std::f64::consts::TAU * st / spacing).ceil() as usize).max(6);
                for i in 0..m {
                    let (sp, cp) = (std::f64::consts::TAU * (i as f64 + 0.5 * (j % 2) as f64)
                        / m as f64)
                        .sin_cos();
                    let u = add(
                        scale(frame.u, ct),
                        add(scale(frame.e1, st * cp), scale(frame.e2, st * sp)),
                    );
                    samples.push((u, self.half_sq(p, u)));
                }
            }
        }
        samples.sort_by(|a, b| a.1.total_cmp(&b.1));

        // Starts: the radial direction and the best samples, pairwise apart.
        const MAX_STARTS: usize = 8;
        let min_cos = (2.0 * spacing).cos();
        let mut starts: Vec<[f64; 3]> = vec![up];
        for (u, _) in &samples {
            if starts.len() > MAX_STARTS {
                break;
            }
            if starts.iter().all(|s| dot(*s, *u) < min_cos) {
                starts.push(*u);
            }
        }
        if let Some((_, h)) = samples.first() {
            best_h = best_h.min(*h);
        }
        for s in starts {
            best_h = best_h.min(self.descend(p, s));
        }
        (2.0 * best_h).sqrt()
    }
}

/// A unit vector and an orthonormal basis of its tangent plane.
struct Frame {
    u: [f64; 3],
    e1: [f64; 3],
    e2: [f64; 3],
}

impl Frame {
    fn at(u: [f64; 3]) -> Frame {
        // The axis least aligned with u.
        let a = [u[0].abs(), u[1].abs(), u[2].abs()];
        let axis = if a[0] <= a[1] && a[0] <= a[2] {
            [1.0, 0.0, 0.0]
        } else if a[1] <= a[2] {
            [0.0, 1.0, 0.0]
        } else {
            [0.0, 0.0, 1.0]
        };
        let t = sub(axis, scale(u, dot(u, axis)));
        let e1 = scale(t, 1.0 / norm(t));
        let e2 = cross(u, e1);
        Frame { u, e1, e2 }
    }
}

#[inline]
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

#[inline]
fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

#[inline]
fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline]
fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

#[inline]
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// A position and its normal.
    type Record = ([f64; 3], [f64; 3]);

    /// Header text and `x y z nx ny nz` records of a PLY written by `synth`.
    fn read_points(path: &Path) -> (String, Vec<Record>) {
        let bytes = std::fs::read(path).unwrap();
        let tag = b"end_header\n";
        let end = bytes.windows(tag.len()).position(|w| w == tag).unwrap() + tag.len();
        let header = String::from_utf8(bytes[..end].to_vec()).unwrap();
        let data = &bytes[end..];
        assert_eq!(data.len() % 24, 0);
        let f =
            |i: usize| f32::from_le_bytes([data[i], data[i + 1], data[i + 2], data[i + 3]]) as f64;
        let pts = (0..data.len() / 24)
            .map(|k| {
                let o = k * 24;
                (
                    [f(o), f(o + 4), f(o + 8)],
                    [f(o + 12), f(o + 16), f(o + 20)],
                )
            })
            .collect();
        (header, pts)
    }

    fn params(shape: Shape, points: u64) -> SynthParams {
        SynthParams {
            shape,
            points,
            noise: 0.0,
            seed: 7,
            threads: 2,
        }
    }

    fn run(p: &SynthParams, out: &Path) -> SynthReport {
        synth(p, out, &mut |_| {}).unwrap()
    }

    #[test]
    fn shape_names() {
        for s in Shape::ALL {
            assert_eq!(s.name().parse::<Shape>().unwrap(), s);
            assert_eq!(s.to_string(), s.name());
            assert_eq!(Truth::standard(s).shape(), s);
        }
        assert_eq!("TwoSheets".parse::<Shape>().unwrap(), Shape::TwoSheets);
        let err = "cube".parse::<Shape>().unwrap_err();
        assert!(matches!(err, Error::Usage(_)));
        let msg = err.to_string();
        for s in Shape::ALL {
            assert!(msg.contains(s.name()), "{msg}");
        }
    }

    #[test]
    fn truth_paths() {
        assert_eq!(truth_path(Path::new("s.ply")), Path::new("s.truth.json"));
        assert_eq!(
            truth_path(Path::new("dir/a.b.PLY")),
            Path::new("dir/a.b.truth.json")
        );
        assert_eq!(truth_path(Path::new("/x/s")), Path::new("/x/s.truth.json"));
        assert_eq!(
            truth_path(Path::new("s.xyz")),
            Path::new("s.xyz.truth.json")
        );
    }

    #[test]
    fn bad_params_are_usage_errors() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("bad.ply");
        let mut p = params(Shape::Sphere, 0);
        let e = synth(&p, &out, &mut |_| {}).unwrap_err();
        assert!(
            matches!(e, Error::Usage(_)) && e.to_string().contains("points"),
            "{e}"
        );
        p.points = 10;
        for noise in [-0.1, f64::NAN, f64::INFINITY] {
            p.noise = noise;
            let e = synth(&p, &out, &mut |_| {}).unwrap_err();
            assert!(
                matches!(e, Error::Usage(_)) && e.to_string().contains("noise"),
                "{e}"
            );
        }
        p.noise = 0.0;
        let e = synth(&p, Path::new("/"), &mut |_| {}).unwrap_err();
        assert!(matches!(e, Error::Usage(_)), "{e}");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn samples_lie_on_the_surface_with_outward_normals() {
        let dir = tempfile::tempdir().unwrap();
        for shape in Shape::ALL {
            let out = dir.path().join(format!("{shape}.ply"));
            let n = 20_000;
            let report = run(&params(shape, n), &out);
            assert_eq!(report.points, n);
            let (header, pts) = read_points(&out);
            assert!(
                header.contains(&format!("element vertex {n}\n")),
                "{header}"
            );
            assert!(
                header.contains("property float nz\nend_header\n"),
                "{header}"
            );
            assert_eq!(pts.len() as u64, n);
            let truth = Truth::load(&truth_path(&out)).unwrap();
            assert_eq!(truth, Truth::standard(shape));
            let bbox = truth.bounding_box();
            let mut seen = Aabb::EMPTY;
            let mut inner = 0;
            for (p, nrm) in &pts {
                seen.add(*p);
                let d = truth.distance(*p);
                assert!(d < 1e-6, "{shape}: {p:?} at distance {d}");
                assert!((norm(*nrm) - 1.0).abs() < 1e-6, "{shape}: normal {nrm:?}");
                for ((c, lo), hi) in p.iter().zip(bbox.min).zip(bbox.max) {
                    assert!(*c >= lo - 1e-6 && *c <= hi + 1e-6, "{shape}: {p:?} outside");
                }
                let u = scale(*p, 1.0 / norm(*p));
                match shape {
                    Shape::Sphere => assert!(dot(u, *nrm) > 1.0 - 1e-6),
                    Shape::Torus => {
                        let rho = p[0].hypot(p[1]);
                        let ring = [p[0] / rho, p[1] / rho, 0.0];
                        let expect = scale(sub(*p, ring), 1.0 / 0.35);
                        assert!(norm(sub(expect, *nrm)) < 1e-5, "{p:?} {nrm:?}");
                    }
                    Shape::TwoSheets => {
                        if norm(*p) < 0.985 {
                            inner += 1;
                            assert!(dot(u, *nrm) < -1.0 + 1e-6, "inner normal {nrm:?}");
                        } else {
                            assert!(dot(u, *nrm) > 1.0 - 1e-6);
                        }
                    }
                    Shape::Bumpy => {
                        // The normalised gradient of F at the point.
                        let m = Bumpy::new(1.0, 0.05, 8.0);
                        let (r, gs) = m.radius_and_surface_gradient(u);
                        let grad = sub(u, scale(gs, 1.0 / r));
                        let expect = scale(grad, 1.0 / norm(grad));
                        assert!(norm(sub(expect, *nrm)) < 1e-5);
                        assert!(dot(u, *nrm) > 0.0);
                    }
                }
            }
            assert_eq!(report.bounds, seen);
            if shape == Shape::TwoSheets {
                // Area share of the inner sphere: 0.97² / (1 + 0.97²).
                let share = inner as f64 / n as f64;
                let expect = 0.9409 / 1.9409;
                let sd = (expect * (1.0 - expect) / n as f64).sqrt();
                assert!((share - expect).abs() < 5.0 * sd, "inner share {share}");
            }
            // The samples come close to the exact bounding box.
            for i in 0..3 {
                assert!(seen.max[i] > bbox.max[i] - 0.05 && seen.min[i] < bbox.min[i] + 0.05);
            }
        }
    }

    #[test]
    fn output_is_identical_for_any_thread_count() {
        let dir = tempfile::tempdir().unwrap();
        let n = 3 * CHUNK_POINTS + 1000;
        let mut outputs = Vec::new();
        for threads in [1, 3] {
            let out = dir.path().join(format!("t{threads}.ply"));
            let p = SynthParams {
                shape: Shape::Bumpy,
                points: n,
                noise: 0.002,
                seed: 42,
                threads,
            };
            let mut calls = Vec::new();
            let report = synth(&p, &out, &mut |k| calls.push(k)).unwrap();
            assert_eq!(report.points, n);
            assert_eq!(
                calls,
                vec![CHUNK_POINTS, 2 * CHUNK_POINTS, 3 * CHUNK_POINTS, n]
            );
            outputs.push((
                std::fs::read(&out).unwrap(),
                std::fs::read(truth_path(&out)).unwrap(),
                report.bounds,
            ));
        }
        assert!(
            outputs[0] == outputs[1],
            "outputs differ between thread counts"
        );
        // A different seed gives different points.
        let out = dir.path().join("other.ply");
        let p = SynthParams {
            shape: Shape::Bumpy,
            points: n,
            noise: 0.002,
            seed: 43,
            threads: 2,
        };
        run(&p, &out);
        assert!(std::fs::read(&out).unwrap() != outputs[0].0);
        // No temporary file is left behind.
        let names: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert!(names.iter().all(|n| !n.contains(".tmp-")), "{names:?}");
        assert_eq!(names.len(), 6);
    }

    #[test]
    fn truth_file_contents() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("b.ply");
        let p = SynthParams {
            shape: Shape::Bumpy,
            points: 1000,
            noise: 0.01,
            seed: u64::MAX,
            threads: 1,
        };
        let report = run(&p, &out);
        let text = std::fs::read_to_string(dir.path().join("b.truth.json")).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["shape"], "bumpy");
        assert_eq!(v["params"]["radius"], 1.0);
        assert_eq!(v["params"]["amplitude"], 0.05);
        assert_eq!(v["params"]["frequency"], 8.0);
        assert_eq!(v["points"], 1000);
        assert_eq!(v["seed"], u64::MAX);
        assert_eq!(v["noise"], 0.01);
        let b = v["bounding_box"]["max"][0].as_f64().unwrap();
        assert!(b > 1.0 && b < 1.05, "{b}");
        let sigma = v["noise_sigma"].as_f64().unwrap();
        assert!((sigma - 0.01 * 2.0 * 3f64.sqrt() * b).abs() < 1e-15);
        let file = TruthFile::load(&dir.path().join("b.truth.json")).unwrap();
        assert_eq!(file.points, 1000);
        assert_eq!(file.seed, u64::MAX);
        assert_eq!(file.sample_bounding_box, Some(report.bounds));
        assert_eq!(file.truth, Truth::standard(Shape::Bumpy));

        let torus = serde_json::to_value(Truth::standard(Shape::Torus)).unwrap();
        assert_eq!(
            torus,
            serde_json::json!({"shape":"torus","params":{"major_radius":1.0,"minor_radius":0.35}})
        );
        let two = serde_json::to_value(Truth::standard(Shape::TwoSheets)).unwrap();
        assert_eq!(two["shape"], "twosheets");
    }

    #[test]
    fn bad_truth_files_are_reported() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.truth.json");
        std::fs::write(&path, "{\"shape\":\"cube\"}").unwrap();
        let e = Truth::load(&path).unwrap_err();
        assert!(matches!(e, Error::Format { .. }), "{e}");
        std::fs::write(
            &path,
            r#"{"shape":"torus","params":{"major_radius":1,"minor_radius":2},
                "noise":0,"noise_sigma":0,"points":1,"seed":0,
                "bounding_box":{"min":[0,0,0],"max":[1,1,1]}}"#,
        )
        .unwrap();
        let e = Truth::load(&path).unwrap_err();
        assert!(
            matches!(e, Error::Input { .. }) && e.to_string().contains("minor_radius"),
            "{e}"
        );
        let e = Truth::load(&dir.path().join("missing.json")).unwrap_err();
        assert!(matches!(e, Error::Io { .. }), "{e}");
    }

    #[test]
    fn noise_has_the_requested_sigma() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("n.ply");
        let p = SynthParams {
            shape: Shape::Sphere,
            points: 100_000,
            noise: 0.01,
            seed: 1,
            threads: 2,
        };
        run(&p, &out);
        let sigma = 0.01 * 2.0 * 3f64.sqrt();
        let (_, pts) = read_points(&out);
        // The radial part of isotropic noise has the same sigma (up to O(sigma²)).
        let r: Vec<f64> = pts.iter().map(|(p, _)| norm(*p) - 1.0).collect();
        let mean = r.iter().sum::<f64>() / r.len() as f64;
        let sd = (r.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / r.len() as f64).sqrt();
        assert!((sd / sigma - 1.0).abs() < 0.02, "sd {sd} sigma {sigma}");
        assert!(mean.abs() < 0.003, "mean {mean}");
        // Normals stay exact.
        for (p, n) in pts.iter().take(100) {
            assert!((norm(*n) - 1.0).abs() < 1e-6);
            assert!(dot(*p, *n) > 0.8);
        }
    }

    #[test]
    fn torus_is_uniform_by_area() {
        let mut rng = chunk_rng(3, 0);
        let s = Truth::standard(Shape::Torus).sampler();
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
        let s = Truth::standard(Shape::Bumpy).sampler();
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

    #[test]
    fn bumpy_bounding_box_is_tight() {
        let m = Bumpy::new(1.0, 0.05, 8.0);
        let b = m.max_extent();
        // Brute force over a fine grid of directions near +x, and the -x side.
        let mut best = f64::NEG_INFINITY;
        let mut least = f64::INFINITY;
        let n = 1500;
        for i in 0..=n {
            let t = 0.35 * i as f64 / n as f64;
            for j in 0..n {
                let ph = std::f64::consts::TAU * j as f64 / n as f64;
                let u = [t.cos(), t.sin() * ph.cos(), t.sin() * ph.sin()];
                best = best.max(m.radius_at(u) * u[0]);
                let v = [-u[0], u[1], u[2]];
                least = least.min(m.radius_at(v) * v[0]);
            }
        }
        assert!(b >= best - 1e-12 && b - best < 1e-5, "{b} vs {best}");
        assert!((least + b).abs() < 1e-5, "{least} vs {b}");
    }

    /// Brute force: dense directions in a cone around `p`'s direction, then repeated local
    /// grid refinement around the best few.
    fn brute_distance(m: &Bumpy, p: [f64; 3], cone: f64) -> f64 {
        let up = scale(p, 1.0 / norm(p));
        let f = Frame::at(up);
        let dir = |a: f64, b: f64| {
            let w = add(up, add(scale(f.e1, a), scale(f.e2, b)));
            scale(w, 1.0 / norm(w))
        };
        let n = 300;
        let step = 2.0 * cone / n as f64;
        let mut cands: Vec<(f64, f64, f64)> = Vec::new();
        for i in 0..=n {
            for j in 0..=n {
                let (a, b) = (-cone + i as f64 * step, -cone + j as f64 * step);
                cands.push((m.half_sq(p, dir(a, b)), a, b));
            }
        }
        cands.sort_by(|x, y| x.0.total_cmp(&y.0));
        let mut best = f64::INFINITY;
        let mut picked: Vec<(f64, f64)> = Vec::new();
        for &(_, a0, b0) in &cands {
            if picked.len() == 6 {
                break;
            }
            if picked.iter().any(|&(a, b)| (a - a0).hypot(b - b0) < 0.05) {
                continue;
            }
            picked.push((a0, b0));
            let (mut a, mut b, mut h) = (a0, b0, m.half_sq(p, dir(a0, b0)));
            let mut s = step;
            for _ in 0..12 {
                let (ca, cb) = (a, b);
                for i in -10..=10 {
                    for j in -10..=10 {
                        let (x, y) = (ca + i as f64 * s / 5.0, cb + j as f64 * s / 5.0);
                        let v = m.half_sq(p, dir(x, y));
                        if v < h {
                            (a, b, h) = (x, y, v);
                        }
                    }
                }
                s /= 5.0;
            }
            best = best.min(h);
        }
        (2.0 * best).sqrt()
    }

    #[test]
    fn bumpy_distance_matches_brute_force() {
        let truth = Truth::standard(Shape::Bumpy);
        let m = Bumpy::new(1.0, 0.05, 8.0);
        let mut rng = Pcg64::seed_from_u64(99);
        for i in 0..40 {
            let u = uniform_direction(&mut rng);
            let s = scale(u, m.radius_at(u));
            let off = scale(uniform_direction(&mut rng), 0.1 * rng.random::<f64>());
            let p = if i < 5 { s } else { add(s, off) };
            let d = truth.distance(p);
            let brute = brute_distance(&m, p, 0.16);
            assert!(
                (d - brute).abs() <= 1e-9 * brute.max(1e-3),
                "{p:?}: {d} vs brute {brute}"
            );
        }
    }

    #[test]
    fn bumpy_distance_far_and_degenerate() {
        // Flat relief: the sphere's closed form.
        let flat = Truth::Bumpy {
            radius: 1.0,
            amplitude: 0.0,
            frequency: 8.0,
        };
        for p in [[0.3, -0.2, 0.1], [2.0, 1.0, -1.0], [0.0; 3]] {
            let e = (norm(p) - 1.0).abs();
            assert!((flat.distance(p) - e).abs() < 1e-15);
        }
        let truth = Truth::standard(Shape::Bumpy);
        let m = Bumpy::new(1.0, 0.05, 8.0);
        // The centre: the smallest radius.
        let mut rmin = f64::INFINITY;
        let n = 600;
        for i in 0..n {
            let t = std::f64::consts::PI * (i as f64 + 0.5) / n as f64;
            for j in 0..2 * n {
                let ph = std::f64::consts::PI * j as f64 / n as f64;
                rmin = rmin.min(m.radius_at([t.sin() * ph.cos(), t.sin() * ph.sin(), t.cos()]));
            }
        }
        let d0 = truth.distance([0.0; 3]);
        assert!(d0 <= rmin + 1e-12 && d0 > rmin - 1e-5, "{d0} vs {rmin}");
        // Far away: never more than the radial distance, close to |p| - 1.
        let p = [3.0, -2.0, 1.5];
        let d = truth.distance(p);
        assert!(d <= (norm(p) - m.radius_at(scale(p, 1.0 / norm(p)))).abs() + 1e-15);
        assert!((d - (norm(p) - 1.0)).abs() < 0.06);
    }

    #[test]
    fn closed_form_distances_match_brute_force() {
        let mut rng = Pcg64::seed_from_u64(5);
        for shape in [Shape::Sphere, Shape::Torus, Shape::TwoSheets] {
            let truth = Truth::standard(shape);
            let s = truth.sampler();
            let surface: Vec<[f64; 3]> = (0..200_000).map(|_| s.sample(&mut rng).0).collect();
            for _ in 0..20 {
                let p = [
                    2.0 * rng.random::<f64>() - 1.0,
                    2.0 * rng.random::<f64>() - 1.0,
                    2.0 * rng.random::<f64>() - 1.0,
                ];
                let d = truth.distance(p);
                let brute = surface
                    .iter()
                    .map(|q| norm(sub(*q, p)))
                    .fold(f64::INFINITY, f64::min);
                assert!(
                    d <= brute + 1e-12 && brute - d < 0.02,
                    "{shape} {p:?}: {d} vs {brute}"
                );
            }
        }
    }

    #[test]
    fn overwrites_existing_output() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("o.ply");
        std::fs::write(&out, b"old").unwrap();
        std::fs::write(truth_path(&out), b"old").unwrap();
        run(&params(Shape::Sphere, 10), &out);
        let (_, pts) = read_points(&out);
        assert_eq!(pts.len(), 10);
        assert!(Truth::load(&truth_path(&out)).is_ok());
    }

    #[test]
    fn missing_output_directory_is_an_io_error() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("nope/o.ply");
        let e = synth(&params(Shape::Sphere, 10), &out, &mut |_| {}).unwrap_err();
        assert!(matches!(e, Error::Io { .. }), "{e}");
    }
}
