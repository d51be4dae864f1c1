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
//!   `r(u) = R (1 + a sin(k u_x) sin(k u_y) sin(k u_z))`, R = 1, a = 0.05, k = 8 (a and k
//!   chosen by [`SynthParams::relief`]). Normals are
//!   the normalised gradient of `F(p) = |p| - r(p/|p|)`.
//! * `heightfield`: the graph `z = h(x, y)` over the square `[-1, 1]²`, `h` a plane tilt
//!   `0.05 x - 0.03 y` plus eight Gaussian bumps of widths 0.08 to 0.4 and heights ±0.05 to
//!   ±0.25 (the parameters are written in the truth file). Normals are the upward graph
//!   normals `(-h_x, -h_y, 1) / |…|`. A surface with a boundary, like a terrain tile.
//!
//! # Sampling
//!
//! Every closed shape is sampled exactly uniformly with respect to surface area:
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
//! The height field is not: its points are uniform in `(x, y)` (`x` and `y` uniform in
//! `[-1, 1)`), which is how a terrain scan samples the ground (so steep flanks get fewer points
//! per unit of area than flat ground). The truth samples of [`crate`] for it are
//! uniform by area: a uniform `(x, y)` kept with probability `sqrt(1 + |∇h|²) / B`, where
//! `B = sqrt(1 + S²)` and `S = |t| + Σ |a_i| / (w_i √e)` bounds the slope.
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
//!
//! # Files
//!
//! * `mod.rs`: the shapes, the parameters and the driver [`synth`];
//! * `truth.rs`: the exact surfaces ([`Truth`]), their distances and the truth file;
//! * `bumpy.rs`: the bumpy sphere's relief, bounding box and numerical distance;
//! * `heightfield.rs`: the height field's value, derivatives, range and numerical distance;
//! * `sampler.rs`: sampling uniformly by area (also used by [`crate`]);
//! * `rng.rs`, `vec.rs`: the seeded generators and small vector helpers, shared with
//!   [`crate`].

mod bumpy;
mod heightfield;
pub(crate) mod rng;
pub(crate) mod sampler;
mod truth;

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Instant;

use rayon::prelude::*;

use crate::error::{Error, Result, Setting};
use crate::io::ply_write::PointPlyWriter;
use crate::types::{Aabb, Attributes, PointBatch};
use sampler::{Sampler, generate_chunk};

pub use heightfield::{Bump, HEIGHTFIELD_BUMPS};
pub use truth::{BUMPY_RELIEF, Truth, TruthFile};

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
    /// The graph of a sum of Gaussian bumps over `[-1, 1]²`, sampled uniformly in `(x, y)`.
    HeightField,
}

impl Shape {
    /// Every shape, in the order of the help text.
    pub const ALL: [Shape; 5] = [
        Shape::Sphere,
        Shape::Torus,
        Shape::TwoSheets,
        Shape::Bumpy,
        Shape::HeightField,
    ];

    /// The name used on the command line and in truth files.
    pub fn name(self) -> &'static str {
        match self {
            Shape::Sphere => "sphere",
            Shape::Torus => "torus",
            Shape::TwoSheets => "twosheets",
            Shape::Bumpy => "bumpy",
            Shape::HeightField => "heightfield",
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

/// Largest relative relief amplitude of `bumpy` (`--amplitude`).
pub const MAX_AMPLITUDE: f64 = 0.5;

/// Largest relief frequency of `bumpy` (`--frequency`): a wavelength of about 0.006, finer
/// than a depth-11 voxel of the unit sphere's cube.
pub const MAX_FREQUENCY: f64 = 1000.0;

/// Parameters of [`synth`].
#[derive(Debug, Clone, PartialEq)]
pub struct SynthParams {
    /// The surface to sample.
    pub shape: Shape,
    /// `bumpy`'s relief as (amplitude relative to the radius, frequency), instead of the
    /// standard (0.05, 8); `None` for every other shape.
    pub relief: Option<[f64; 2]>,
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
        return Err(Error::Usage(format!(
            "{} is 0, expected at least 1 point",
            Setting::Points
        )));
    }
    if let Some([a, k]) = params.relief {
        if params.shape != Shape::Bumpy {
            return Err(Error::Usage(format!(
                "{} and {} shape the relief of bumpy, not of {}",
                Setting::Amplitude,
                Setting::Frequency,
                params.shape.name()
            )));
        }
        if !(a.is_finite() && (0.0..=MAX_AMPLITUDE).contains(&a)) {
            return Err(Error::Usage(format!(
                "{} is {a}, expected a number from 0 to {MAX_AMPLITUDE} (relative to \
                 the radius)",
                Setting::Amplitude
            )));
        }
        if !(k.is_finite() && k > 0.0 && k <= MAX_FREQUENCY) {
            return Err(Error::Usage(format!(
                "{} is {k}, expected a number above 0 and at most {MAX_FREQUENCY} \
                 (a wavelength of 2π/K on the unit sphere)",
                Setting::Frequency
            )));
        }
    }
    if !(params.noise.is_finite() && params.noise >= 0.0) {
        return Err(Error::Usage(format!(
            "{} is {}, expected a finite number >= 0 (a fraction of the bounding-box \
             diagonal)",
            Setting::Noise,
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
    let truth = match (Truth::standard(params.shape), params.relief) {
        (Truth::Bumpy { radius, .. }, Some([amplitude, frequency])) => Truth::Bumpy {
            radius,
            amplitude,
            frequency,
        },
        (t, _) => t,
    };
    let sampler = Sampler::new(&truth);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::vec::{dot, norm, scale, sub};
    use crate::synth::bumpy::Bumpy;

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
            relief: None,
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
                    Shape::HeightField => {
                        // The upward normal (-h_x, -h_y, 1) / |…| by central differences.
                        let m = heightfield::HeightField::new(
                            1.0,
                            heightfield::STANDARD_TILT,
                            heightfield::STANDARD_BUMPS,
                        );
                        assert!((m.value(p[0], p[1]) - p[2]).abs() < 1e-6);
                        let e = 1e-6;
                        let h = |x: f64, y: f64| m.value(x, y);
                        let hx = (h(p[0] + e, p[1]) - h(p[0] - e, p[1])) / (2.0 * e);
                        let hy = (h(p[0], p[1] + e) - h(p[0], p[1] - e)) / (2.0 * e);
                        let l = (hx * hx + hy * hy + 1.0).sqrt();
                        let expect = [-hx / l, -hy / l, 1.0 / l];
                        assert!(norm(sub(expect, *nrm)) < 1e-5, "{p:?} {nrm:?}");
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
                relief: None,
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
            relief: None,
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
            relief: None,
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
    fn noise_has_the_requested_sigma() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("n.ply");
        let p = SynthParams {
            shape: Shape::Sphere,
            relief: None,
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
    fn a_chosen_relief_is_sampled_and_described() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("r.ply");
        let (a, k) = (0.01, 80.0);
        let p = SynthParams {
            relief: Some([a, k]),
            ..params(Shape::Bumpy, 2000)
        };
        run(&p, &out);
        let file = TruthFile::load(&truth_path(&out)).unwrap();
        assert_eq!(
            file.truth,
            Truth::Bumpy {
                radius: 1.0,
                amplitude: a,
                frequency: k
            }
        );
        let (_, pts) = read_points(&out);
        let m = Bumpy::new(1.0, a, k);
        for (p, _) in &pts {
            let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            assert!((1.0 - a - 1e-6..=1.0 + a + 1e-6).contains(&r), "{r}");
            let u = [p[0] / r, p[1] / r, p[2] / r];
            assert!((r - m.radius_at(u)).abs() < 1e-6, "{p:?}");
        }
        // Only bumpy has a relief, and only a sane one.
        for (shape, relief, what) in [
            (Shape::Sphere, [0.01, 8.0], "not of sphere"),
            (Shape::Bumpy, [0.6, 8.0], "`amplitude` is 0.6"),
            (Shape::Bumpy, [f64::NAN, 8.0], "`amplitude` is NaN"),
            (Shape::Bumpy, [0.01, 0.0], "`frequency` is 0"),
            (Shape::Bumpy, [0.01, 2000.0], "`frequency` is 2000"),
        ] {
            let p = SynthParams {
                relief: Some(relief),
                ..params(shape, 10)
            };
            let bad = dir.path().join("bad.ply");
            let e = synth(&p, &bad, &mut |_| {}).unwrap_err().to_string();
            assert!(e.contains(what), "{e}");
            assert!(!bad.exists());
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
