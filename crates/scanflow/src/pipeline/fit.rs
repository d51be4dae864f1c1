//! `scanflow fit`: one hierarchical B-spline surface per disc-like patch of points
//! (Greiner & Hormann 1997), exported as IGES, with a tessellated preview and a JSON report.
//!
//! A single surface holds its points in memory (admitted by the budget), and its sparse
//! factorisations may take what the budget has left (checked symbolically before each one,
//! [`crate::sparse::factor_bytes`]; a system too large for `--mem` ends the run with
//! the bytes it needs). Its neighbourhood
//! graph comes from the input's triangles (a PLY's `face` element or a range scan's
//! `range_grid`) when there is one input that has them, else from the points' k nearest
//! neighbours ([`crate::spline::graph`]); the parameterisation ([`crate::spline::param`])
//! maps it to the plane, and [`crate::spline::fit`] fits and refines until the tolerance
//! holds. Terrain larger than memory goes through tiles (`fit_tiles`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::error::{Error, Result};
use crate::exec::Ctx;
use crate::io::mesh_write::{MeshFormat, MeshWriter, VertexFormat};
use crate::spline::fit::{Fit, FitParams, fit};
use crate::spline::graph::Graph;
use crate::spline::iges::{IgesMeta, write_iges};
use crate::spline::param::{Method, Param, parameterise_facing};
use crate::spline::tensor;
use crate::types::TensorSurface;

/// Bytes a point of a single surface costs in memory: position, parameters, foot point,
/// distance, graph edges (about 12 per point, both ways), grouping, and the fit's
/// per-iteration arrays.
pub const BYTES_PER_POINT: u64 = 320;

/// Bytes a point costs when the spring model parameterises it (every method but `project`):
/// its graph, the Laplacian and its sparse Cholesky factor on top of [`BYTES_PER_POINT`].
/// Measured: 1.03 KiB per point on 65,000 height-field points with 10 nearest neighbours
/// (chord springs), peak resident memory over the process's baseline.
pub const BYTES_PER_POINT_SPRINGS: u64 = 1280;

/// Bytes a point of a surface costs with the parameterisation `method`.
pub fn bytes_per_point(method: Method) -> u64 {
    if method == Method::Project {
        BYTES_PER_POINT
    } else {
        BYTES_PER_POINT_SPRINGS
    }
}

/// Neighbours per point of the k-nearest-neighbour graph.
pub const KNN: usize = 10;

/// The tolerance: in input units or relative to the bounding box's diagonal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Tolerance {
    /// Input units.
    Absolute(f64),
    /// A fraction of the diagonal of the points' bounding box.
    Relative(f64),
}

impl Tolerance {
    /// In input units, for a bounding box of diagonal `diag`.
    pub fn resolve(self, diag: f64) -> f64 {
        match self {
            Tolerance::Absolute(t) => t,
            Tolerance::Relative(r) => r * diag,
        }
    }
}

/// Everything a fit run needs besides its inputs.
#[derive(Clone, Debug)]
pub struct FitJob {
    /// The fit's options; its tolerance is set from [`FitJob::tolerance`].
    pub fit: FitParams,
    /// The tolerance as given.
    pub tolerance: Tolerance,
    /// The parameterisation.
    pub method: Method,
    /// Where to write the tessellated preview.
    pub preview: Option<PathBuf>,
    /// Where to write the JSON report.
    pub report: Option<PathBuf>,
    /// Points a terrain tile aims at (`--tiles`).
    pub tile_points: u64,
}

/// One fitted surface and where its points came from.
#[derive(Debug)]
pub struct Surface {
    /// The fit.
    pub fit: Fit,
    /// Number of points.
    pub points: usize,
    /// Whether the graph came from triangles (else k nearest neighbours).
    pub from_triangles: bool,
    /// Parameter triangles that flipped orientation (0 for a valid parameterisation).
    pub flips: usize,
    /// Seconds for the graph and parameterisation, and for the fit.
    pub secs: [f64; 2],
}

/// What a fit run did.
#[derive(Debug)]
pub struct FitStats {
    /// The surfaces.
    pub surfaces: Vec<Surface>,
    /// Points read (a surface's count includes the overlap it shares with its neighbours).
    pub input_points: usize,
    /// Diagonal of the points' bounding box.
    pub diagonal: f64,
    /// The tolerance in input units.
    pub tolerance: f64,
    /// Seconds reading the input.
    pub secs_read: f64,
    /// Seconds in all.
    pub secs: f64,
    /// Largest gap between neighbouring surfaces along their shared edges (tiles, patches).
    pub seam_gap: Option<f64>,
    /// The gaps between neighbouring patches (`--patches`).
    pub gaps: Vec<super::fit_patches::PatchGap>,
    /// Largest and RMS deviation over the points read, each to the nearest surface fitted to
    /// it, where surfaces share points (`--patches`); else the surfaces' own figures count.
    pub point_deviation: Option<[f64; 2]>,
}

fn diagonal(pts: &[[f64; 3]]) -> f64 {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in pts {
        for x in 0..3 {
            lo[x] = lo[x].min(p[x]);
            hi[x] = hi[x].max(p[x]);
        }
    }
    (0..3).map(|x| (hi[x] - lo[x]).powi(2)).sum::<f64>().sqrt()
}

/// Reads the points of `inputs` as a mesh's vertices, with the triangles when there is one
/// PLY input that has them (faces or a range grid); none otherwise.
pub fn read_points(inputs: &[PathBuf], ctx: &Ctx) -> Result<crate::io::mesh_read::Mesh> {
    if let [one] = inputs {
        let is_ply = std::fs::File::open(one)
            .ok()
            .and_then(|mut f| {
                let mut m = [0u8; 3];
                std::io::Read::read_exact(&mut f, &mut m).ok()?;
                Some(&m == b"ply")
            })
            .unwrap_or(false);
        if is_ply {
            let mesh = crate::io::mesh_read::read_scan_mesh(one)?;
            if !mesh.triangles.is_empty() {
                return Ok(mesh);
            }
        }
    }
    let mut pts = Vec::new();
    for path in inputs {
        let mut r = crate::io::open(path)?;
        r.ignore_normals();
        let n = r.len();
        let _permit = ctx
            .budget
            .acquire(n * BYTES_PER_POINT, "the points of one surface")?;
        let mut batch = crate::types::PointBatch::default();
        for chunk in r.chunks(1 << 20)? {
            batch.clear();
            r.read_chunk(&chunk, false, &mut batch)?;
            pts.extend_from_slice(&batch.pos);
        }
    }
    Ok(crate::io::mesh_read::Mesh {
        vertices: pts,
        triangles: Vec::new(),
    })
}

/// Fits one surface to `pts` (with `tris`, their triangles, when known), parameterised over
/// the plane normal to `facing` when given (else their best-fit plane).
pub fn fit_one(
    pts: &[[f64; 3]],
    tris: &[[u32; 3]],
    facing: Option<[f64; 3]>,
    job: &FitJob,
    tolerance: f64,
    max_factor_bytes: u64,
    name: &Path,
) -> Result<Surface> {
    let t0 = Instant::now();
    let graph = if tris.is_empty() {
        if job.method == Method::Project {
            Graph {
                edges: Vec::new(),
                boundary: vec![true; pts.len()],
                triangles: Vec::new(),
                non_manifold_edges: 0,
            }
        } else {
            Graph::from_knn(name, pts, KNN)?
        }
    } else {
        Graph::from_triangles(name, pts.len(), tris)?
    };
    let param: Param =
        parameterise_facing(pts, &graph, job.method, facing).map_err(|e| match e {
            Error::Usage(m) | Error::Internal(m) => Error::input(name, m),
            e => e,
        })?;
    let t1 = Instant::now();
    let params = FitParams {
        tolerance,
        max_factor_bytes,
        ..job.fit.clone()
    };
    let fit =
        fit(pts, &param.uv, param.size, &params).map_err(|e| Error::input(name, e.to_string()))?;
    Ok(Surface {
        fit,
        points: pts.len(),
        from_triangles: !tris.is_empty(),
        flips: param.folds,
        secs: [(t1 - t0).as_secs_f64(), t1.elapsed().as_secs_f64()],
    })
}

/// `scanflow fit` on point files: one surface, written as IGES (and preview, report).
pub fn fit_files(inputs: &[PathBuf], output: &Path, job: &FitJob, ctx: &Ctx) -> Result<FitStats> {
    let t0 = Instant::now();
    let stage = ctx.progress.stage("read", None, "points");
    let crate::io::mesh_read::Mesh {
        vertices: pts,
        triangles: tris,
    } = read_points(inputs, ctx)?;
    stage.finish(None);
    let secs_read = t0.elapsed().as_secs_f64();
    let name = inputs.first().map_or(output, PathBuf::as_path);
    if pts.len() < 3 {
        return Err(Error::input(
            name,
            format!("{} points: a surface needs at least 3", pts.len()),
        ));
    }
    let diag = diagonal(&pts);
    let tolerance = job.tolerance.resolve(diag);
    let _points = ctx.budget.acquire(
        pts.len() as u64 * bytes_per_point(job.method),
        "the points of one surface",
    )?;
    // The factorisation may take what the budget has left.
    let factor = ctx.budget.total().saturating_sub(ctx.budget.used());
    let stage = ctx.progress.stage("fit", None, "surfaces");
    let surface = ctx
        .pool
        .install(|| fit_one(&pts, &tris, None, job, tolerance, factor, name))?;
    stage.finish(None);
    let surfaces = vec![surface];
    write_outputs(output, job, &surfaces, input_stamp(inputs))?;
    Ok(FitStats {
        surfaces,
        input_points: pts.len(),
        diagonal: diag,
        tolerance,
        secs_read,
        secs: t0.elapsed().as_secs_f64(),
        seam_gap: None,
        gaps: Vec::new(),
        point_deviation: None,
    })
}

/// The IGES file's date: the latest modification time of the inputs (seconds since the Unix
/// epoch), so that the same inputs give the same bytes.
pub fn input_stamp(inputs: &[PathBuf]) -> i64 {
    inputs
        .iter()
        .filter_map(|p| std::fs::metadata(p).ok()?.modified().ok())
        .filter_map(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map(|d| d.as_secs() as i64)
        .max()
        .unwrap_or(0)
}

/// Writes the IGES file (dated `stamp`, see [`input_stamp`]) and the preview; the report is
/// written by [`write_report`].
pub fn write_outputs(output: &Path, job: &FitJob, surfaces: &[Surface], stamp: i64) -> Result<()> {
    let tensors: Vec<TensorSurface> = surfaces.iter().map(|s| s.fit.surface.clone()).collect();
    let name = output
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    write_iges(output, &tensors, &IgesMeta::new(name, stamp))?;
    if let Some(p) = &job.preview {
        write_preview(p, &tensors)?;
    }
    Ok(())
}

/// Samples per knot span of the preview along each axis, and most samples per axis.
const PREVIEW_PER_SPAN: usize = 4;
const PREVIEW_MAX: usize = 1024;

/// A triangle mesh sampling every surface on a grid of its parameter domain.
pub fn write_preview(path: &Path, surfaces: &[TensorSurface]) -> Result<()> {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for s in surfaces {
        for c in &s.ctrl {
            for x in 0..3 {
                lo[x] = lo[x].min(c[x]);
                hi[x] = hi[x].max(c[x]);
            }
        }
    }
    let size = (0..3)
        .map(|x| hi[x] - lo[x])
        .fold(0.0, f64::max)
        .max(1e-300);
    let vf = VertexFormat::for_cube(lo, size, false, false);
    let mut w = MeshWriter::create(path, MeshFormat::Ply, vf)?;
    let mut base = 0u64;
    for s in surfaces {
        let dom = s.domain();
        let n = [0, 1].map(|d| {
            let spans = s.knots[d].windows(2).filter(|w| w[1] > w[0]).count();
            (spans * PREVIEW_PER_SPAN).clamp(2, PREVIEW_MAX)
        });
        for j in 0..=n[1] {
            let v = dom[1][0] + (dom[1][1] - dom[1][0]) * j as f64 / n[1] as f64;
            for i in 0..=n[0] {
                let u = dom[0][0] + (dom[0][1] - dom[0][0]) * i as f64 / n[0] as f64;
                w.vertex(tensor::eval(s, [u, v])[0], None)?;
            }
        }
        let row = n[0] as u64 + 1;
        for j in 0..n[1] as u64 {
            for i in 0..n[0] as u64 {
                let a = base + j * row + i;
                w.triangle([a, a + 1, a + row + 1])?;
                w.triangle([a, a + row + 1, a + row])?;
            }
        }
        base += row * (n[1] as u64 + 1);
    }
    w.finish()?;
    Ok(())
}

/// A run's figures summed over its surfaces.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Totals {
    /// Points the surfaces were fitted to (overlaps counted in each).
    pub points: usize,
    /// Control points of the hierarchies.
    pub control_points: usize,
    /// Control points of the exported surfaces.
    pub tensor_control_points: usize,
    /// Largest deviation of a point read ([`FitStats::point_deviation`]).
    pub max_deviation: f64,
    /// Root mean square deviation over the points read.
    pub rms_deviation: f64,
}

impl FitStats {
    /// The figures summed over the surfaces.
    pub fn totals(&self) -> Totals {
        let s = &self.surfaces;
        let points: usize = s.iter().map(|s| s.points).sum();
        let sq: f64 = s
            .iter()
            .map(|s| s.fit.report.rms_deviation.powi(2) * s.points as f64)
            .sum();
        Totals {
            points,
            control_points: s.iter().map(|s| s.fit.report.control_points).sum(),
            tensor_control_points: s.iter().map(|s| s.fit.report.tensor_control_points).sum(),
            max_deviation: self.point_deviation.map_or_else(
                || {
                    s.iter()
                        .map(|s| s.fit.report.max_deviation)
                        .fold(0.0, f64::max)
                },
                |d| d[0],
            ),
            rms_deviation: self
                .point_deviation
                .map_or_else(|| (sq / points.max(1) as f64).sqrt(), |d| d[1]),
        }
    }
}

/// The JSON report of a run (the fields `scanflow fit --report` documents).
pub fn report_json(st: &FitStats, job: &FitJob) -> serde_json::Value {
    let t = st.totals();
    let levels = st.surfaces.iter().fold(Vec::<usize>::new(), |mut acc, s| {
        for (l, c) in s.fit.report.per_level.iter().enumerate() {
            if acc.len() <= l {
                acc.push(0);
            }
            acc[l] += c;
        }
        acc
    });
    let detail: Vec<serde_json::Value> = st
        .surfaces
        .iter()
        .map(|s| {
            let r = &s.fit.report;
            serde_json::json!({
                "points": s.points,
                "graph": if s.from_triangles { "triangles" } else { "knn" },
                "parameter_flips": s.flips,
                "control_points": r.control_points,
                "levels": r.per_level,
                "tensor_control_points": r.tensor_control_points,
                "tensor_size": s.fit.surface.count,
                "max_deviation": r.max_deviation,
                "rms_deviation": r.rms_deviation,
                "max_residual": r.max_residual,
                "fairness_energy": r.fairness_energy,
                "iterations": r.iterations,
                "omega": r.omega,
                "met": r.met,
                "missed": r.missed.iter().map(|m| serde_json::json!({
                    "parameter_rect": m.rect, "bounds": m.bounds,
                    "points": m.points, "max_deviation": m.max_deviation})).collect::<Vec<_>>(),
                "seconds": {"parameterisation": s.secs[0], "fit": s.secs[1]},
            })
        })
        .collect();
    serde_json::json!({
        "points": t.points,
        "surfaces": st.surfaces.len(),
        "control_points": t.control_points,
        "tensor_control_points": t.tensor_control_points,
        "max_deviation": t.max_deviation,
        "rms_deviation": t.rms_deviation,
        "diagonal": st.diagonal,
        "tolerance": st.tolerance,
        "met": st.surfaces.iter().all(|s| s.fit.report.met),
        "levels": levels,
        "fairness": format!("{:?}", job.fit.fairness).to_lowercase(),
        "fairness_energy": st.surfaces.iter().map(|s| s.fit.report.fairness_energy).sum::<f64>(),
        "iterations": st.surfaces.iter().map(|s| s.fit.report.iterations).max().unwrap_or(0),
        "interpolate": job.fit.interpolate,
        "input_points": st.input_points,
        "seam_max_gap": st.seam_gap,
        "patch_gaps": st.gaps.iter().map(|g| serde_json::json!({
            "patches": g.patches, "points": g.points,
            "max_gap": g.max_gap, "rms_gap": g.rms_gap})).collect::<Vec<_>>(),
        "seconds": st.secs,
        "seconds_read": st.secs_read,
        "surfaces_detail": detail,
    })
}

/// Writes the report through the atomic writer.
pub fn write_report(path: &Path, st: &FitStats, job: &FitJob) -> Result<()> {
    let text = serde_json::to_string_pretty(&report_json(st, job))
        .map_err(|e| Error::Internal(e.to_string()))?;
    crate::fs::atomic::write(path, text.as_bytes(), crate::fs::atomic::Durability::Synced)
}
