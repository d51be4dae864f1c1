//! `hexmesh`: a tetrahedral mesh to hexahedra by CubeCover ([`crate::hex`]): read and check
//! the tetrahedra, make the frame field, classify its singular edges (an invalid one stops
//! the run, named), parameterise with greedy rounding, extract the hexahedra, relax them and
//! measure their quality; then write them (only when none is inverted, unless asked).
//!
//! Every failure names the input file and the element: the tetrahedron that is inverted or
//! not manifold, the singular edge whose holonomy no hex mesh has, the rounding that made
//! tetrahedra flip in parameter space, the hexahedra that came out inverted.
//!
//! **Scale.** The hex edge without `--scale` is a twentieth of the bounding box's diagonal, a
//! guess that knows nothing of the shape's features. Where the rounding cannot resolve one
//! (two charts that meet at a corner rounded a hex apart, say), it flips tetrahedra or
//! leaves a corner folded that no vertex placement undoes, and a slightly finer edge rounds
//! differently. So without `--scale` the run tries the default edge and then up to
//! [`SCALE_TRIES`]` − 1` edges each [`SCALE_STEP`] of the last, from the parameterisation
//! on (the tetrahedra and the frame field are kept), and writes the first mesh with no
//! inverted hexahedron; each edge given up is logged and listed in the report's `tries`.
//! A field that flips tetrahedra before any rounding does so at every edge and is not
//! retried. The fandisk at its default edge 2.18 folds two hexahedra at a corner; at 1.85,
//! the next edge, none (measured; 2.0 and 1.4 fold, 1.5 to 1.85 do not: the rounding, not
//! the edge's size, decides). An explicit `--scale` is tried alone.
//!
//! **Grid.** Where the polycube or constant field's aligned map flips tetrahedra before any
//! rounding, no aligned map of that field fits the shape (a labelling that is no polycube:
//! the octopus's curled arms). The run then meshes the grid of the axes without boundary
//! alignment, as octree meshers do (Schneiders, "A grid-based algorithm for the generation of
//! hexahedral element meshes", 1996): the map `x / s` (identity transitions, nothing to
//! round), the cubes wholly inside extracted, those whose boundary would not pillow removed
//! ([`crate::hex::pillow::make_pillowable`]), then the boundary layer and the relaxation onto
//! the surface. Its hexahedra ignore the shape's directions; the warning and the report's
//! `grid_fallback` say why it was used. Its edge is `--scale`, else the smaller of the default
//! edge and the volume over the boundary's area, so that thin parts hold whole cubes.

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::error::{Error, Result, Setting};
use crate::exec::Ctx;
use crate::hex::extract::{ExtractReport, extract};
use crate::hex::frames::{self, Singularities};
use crate::hex::mesh::{Frame, HexMesh, TetMesh};
use crate::hex::param::{Field, GridMap, ParamParams, ParamReport, Transition, parameterise_with};
use crate::hex::pillow::{PillowReport, make_pillowable, pillow};
use crate::hex::polycube::{Polycube, PolycubeParams, PolycubeReport, polycube_frames};
use crate::hex::quality::{HexQuality, MeshQuality, hex_qualities, summarise};
use crate::hex::relax::{RelaxParams, RelaxReport, relax};
use crate::hex::rotation::Rot;
use crate::hex::smooth_frames::{SmoothParams, SmoothReport, smooth_frames};
use crate::hex::stuffing::{StuffingParams, StuffingReport, stuff};
use crate::hex::topology::{Topology, check_tets};
use crate::hex::winding::WindingNumber;
use crate::types::Aabb;

/// Where the frames come from (§3.2).
#[derive(Clone, Debug, PartialEq)]
pub enum FrameChoice {
    /// The coordinate axes everywhere (a polycube map).
    Constant,
    /// Boundary-aligned smooth frames.
    Smooth,
    /// The frames of a coarse hexahedral meta-mesh in this file.
    Meta(PathBuf),
    /// The rotations of a polycube deformation: no interior singularity, the boundary on
    /// axis planes ([`crate::hex::polycube`]).
    Polycube,
}

/// One `hexmesh` run.
#[derive(Clone, Debug)]
pub struct HexJob {
    /// The tetrahedral mesh (`.mesh`, `.msh`, `.vtk`), or a closed surface (`.ply`, `.obj`)
    /// to stuff with tetrahedra first.
    pub input: PathBuf,
    /// The hexahedral mesh to write (`.vtk`, `.mesh`, `.msh`).
    pub output: PathBuf,
    /// The frame field.
    pub frames: FrameChoice,
    /// Target hex edge in input units; `None`: a twentieth of the bounding box's diagonal.
    pub scale: Option<f64>,
    /// Edge of the tetrahedra stuffed into a surface input; `None`: half the hex edge.
    pub tet_size: Option<f64>,
    /// Add a layer of hexahedra along the boundary before relaxing ([`crate::hex::pillow`]);
    /// `None`: with polycube frames only.
    pub pillow: Option<bool>,
    /// Where to write the run's figures (JSON): [`HexStats`] on success, what had been
    /// measured and the error on failure.
    pub report: Option<PathBuf>,
    /// Relax the hexahedra after extraction.
    pub relax: bool,
    /// Write the mesh even when some hexahedra are inverted.
    pub keep_inverted: bool,
}

/// What a run measured.
#[derive(Clone, Debug, serde::Serialize)]
pub struct HexStats {
    /// Tetrahedra read.
    pub tets: usize,
    /// Target hex edge used.
    pub scale: f64,
    /// Default edges tried before `scale` and given up (module docs, "Scale").
    pub tries: Vec<ScaleTry>,
    /// The stuffing of a surface input.
    pub stuffing: Option<StuffingReport>,
    /// The smooth field's figures, when it was made.
    pub smooth: Option<SmoothReport>,
    /// The polycube deformation's figures, when it was made.
    pub polycube: Option<PolycubeReport>,
    /// Interior edges between boundary vertices split before the polycube map (new vertices).
    pub chords_split: usize,
    /// What the map's gradients were drawn towards: `frames`, `deformation` (the polycube
    /// deformation's gradients, tried when the frames' map flipped tetrahedra), or `grid`
    /// (the axes, unaligned, when no aligned map fitted: module docs, "Grid").
    pub targets: &'static str,
    /// Why the aligned map was given up for the grid of the axes (module docs, "Grid"); its
    /// figures are `param`'s.
    pub grid_fallback: Option<String>,
    /// The singularity graph.
    pub singularities: Singularities,
    /// Singular edges of valence 3, 5 and 6.
    pub singular_by_valence: [usize; 3],
    /// The parameterisation.
    pub param: ParamReport,
    /// The extraction.
    pub extract: ExtractReport,
    /// The pillowing, when it ran.
    pub pillow: Option<PillowReport>,
    /// The relaxation, when it ran.
    pub relax: Option<RelaxReport>,
    /// The written mesh's quality.
    pub quality: MeshQuality,
    /// Seconds per step: read and check, frames, parameterisation, extraction, relaxation
    /// (the last three summed over the edges tried).
    pub seconds: [f64; 5],
}

/// Whether `path` names a closed surface (PLY, OBJ or STL triangles) rather than tetrahedra.
pub fn is_surface(path: &Path) -> bool {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    ["ply", "obj", "stl"]
        .iter()
        .any(|e| ext.eq_ignore_ascii_case(e))
}

/// Reads a closed surface (PLY, OBJ, STL).
fn read_surface(path: &Path) -> Result<crate::io::mesh_read::Mesh> {
    let surface = crate::io::mesh_read::read_any_mesh(path)?;
    if surface.triangles.is_empty() {
        return Err(Error::input(
            path,
            "has no triangles: expected a closed surface",
        ));
    }
    Ok(surface)
}

/// The inside of `surface` (read from `path`) as tetrahedra of edge about `tet_size`: the
/// points where its generalised winding number exceeds one half (Jacobson et al. 2013, §3),
/// by isosurface stuffing.
fn stuff_surface(
    path: &Path,
    surface: &crate::io::mesh_read::Mesh,
    tet_size: f64,
) -> Result<(TetMesh, StuffingReport)> {
    let w = WindingNumber::new(&surface.vertices, &surface.triangles)
        .map_err(|e| Error::input(path, e))?;
    let b = bounds(&surface.vertices).grown(2.0 * tet_size);
    let f = |p: [f64; 3]| 0.5 - w.eval(p);
    stuff(&f, b.min, b.max, &StuffingParams::new(tet_size))
        .map_err(|e| Error::input(path, format!("isosurface stuffing: {e}")))
}

/// Reads `path` as a tetrahedral mesh, or stuffs the inside of a closed surface (PLY, OBJ)
/// with tetrahedra of edge `tet_size(diagonal)`; then checks it, errors naming the file and
/// element. Returns the hex edge `scale(diagonal)` too.
fn read_tets(
    path: &Path,
    scale: Option<f64>,
    tet_size: Option<f64>,
) -> Result<(TetMesh, Topology, Option<StuffingReport>, f64)> {
    let (mesh, stuffed, scale) = if is_surface(path) {
        let surface = read_surface(path)?;
        let scale = scale.unwrap_or_else(|| bounds(&surface.vertices).diagonal() / 20.0);
        let size = tet_size.unwrap_or(scale / 2.0);
        let (m, r) = stuff_surface(path, &surface, size)?;
        (m, Some((r, size)), scale)
    } else {
        let m = crate::hex::volume::read(path)?.into_tet_mesh(path)?;
        let scale = scale.unwrap_or_else(|| bounds(&m.verts).diagonal() / 20.0);
        (m, None, scale)
    };
    let topo = check_tets(&mesh).map_err(|e| match &stuffed {
        None => Error::input(path, e.to_string()),
        // The stuffed mesh's indices are ours: say where, and why it happens.
        Some((_, size)) => {
            let at = e
                .vertex()
                .and_then(|v| mesh.verts.get(v as usize))
                .map(|p| format!(" near ({:.6}, {:.6}, {:.6})", p[0], p[1], p[2]))
                .unwrap_or_default();
            Error::input(
                path,
                format!(
                    "the tetrahedra stuffed into the surface at {tet} {} are not a valid \
                     mesh{at}: {e}; the solid is thinner there, or two of its parts are closer, \
                     than the stuffing lattice resolves: try a smaller {tet}",
                    size,
                    tet = Setting::TetSize
                ),
            )
        }
    })?;
    Ok((mesh, topo, stuffed.map(|s| s.0), scale))
}

fn bounds(verts: &[[f64; 3]]) -> Aabb {
    let mut b = Aabb::EMPTY;
    for &p in verts {
        b.add(p);
    }
    b
}

/// What a failed run had measured when it stopped: the report written instead of
/// [`HexStats`], so that a failure is a report as much as a message.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct HexFailure {
    /// The error, as printed.
    pub error: String,
    /// Tetrahedra meshed (after any stuffing and splitting).
    pub tets: usize,
    /// Target hex edge of the last try.
    pub scale: f64,
    /// Default edges tried before it and given up.
    pub tries: Vec<ScaleTry>,
    /// The stuffing of a surface input.
    pub stuffing: Option<StuffingReport>,
    /// The smooth field's figures.
    pub smooth: Option<SmoothReport>,
    /// The polycube deformation's figures.
    pub polycube: Option<PolycubeReport>,
    /// Interior edges between boundary vertices split before the polycube map.
    pub chords_split: usize,
    /// The parameterisation, when it ran (the rounding that flipped tetrahedra is named).
    pub param: Option<ParamReport>,
    /// Why the aligned map was given up for the grid of the axes, when it was.
    pub grid_fallback: Option<String>,
    /// The pillowing, when it ran.
    pub pillow: Option<PillowReport>,
    /// The relaxation, when it ran.
    pub relax: Option<RelaxReport>,
    /// The quality of the extracted hexahedra, when some were inverted.
    pub quality: Option<MeshQuality>,
    /// Seconds per step, as far as the run got.
    pub seconds: [f64; 5],
}

/// Runs `job` (module docs); writes its report (figures or failure) when asked.
pub fn hexmesh(job: &HexJob, ctx: &Ctx) -> Result<HexStats> {
    let mut failure = HexFailure::default();
    let out = run(job, ctx, &mut failure);
    if let Some(p) = &job.report {
        let text = match &out {
            Ok(st) => serde_json::to_string_pretty(st),
            Err(e) => {
                failure.error = e.to_string();
                serde_json::to_string_pretty(&failure)
            }
        }
        .map_err(|e| Error::Internal(format!("report: {e}")))?;
        crate::fs::atomic::write(p, text.as_bytes(), crate::fs::atomic::Durability::Synced)?;
    }
    out
}

fn run(job: &HexJob, ctx: &Ctx, failure: &mut HexFailure) -> Result<HexStats> {
    let path = &job.input;
    // Seconds per step accumulate in the failure report, which the success takes over.
    let clock = Instant::now();
    let (mut mesh, mut topo, stuffing, scale) = read_tets(path, job.scale, job.tet_size)?;
    failure.scale = scale;
    failure.stuffing = stuffing.clone();
    let mut chords_split = 0;
    if job.frames == FrameChoice::Polycube {
        // A tetrahedron with all four vertices on one chart would be flattened onto its plane.
        chords_split = mesh.split_edges(&topo.boundary_chords());
        if chords_split > 0 {
            topo = check_tets(&mesh).map_err(|e| Error::input(path, e.to_string()))?;
        }
    }
    failure.seconds[0] = clock.elapsed().as_secs_f64();
    failure.tets = mesh.tets.len();
    failure.chords_split = chords_split;

    let clock = Instant::now();
    let (field, smooth, polycube) = frame_field(job, ctx, &mesh, &topo)?;
    // A polycube field is one rotation per tetrahedron of a single deformation: its
    // matchings are the identity by construction (the closest cube rotation would misread
    // the quarter turns the field makes across the polycube's edges).
    let m = if polycube.is_some() {
        vec![[Rot::ID; 4]; mesh.tets.len()]
    } else {
        frames::matchings(&field, &topo)
    };
    let sing = frames::singularities(&mesh, &topo, &field, &m);
    failure.seconds[1] = clock.elapsed().as_secs_f64();
    failure.smooth = smooth.clone();
    failure.polycube = polycube.as_ref().map(|p| p.report.clone());
    if let Some(first) = sing.invalid.first() {
        return Err(Error::input(
            path,
            format!(
                "the frame field has {} configuration(s) no hexahedral mesh has; the first: {first}; try {frames} polycube, constant or a meta-mesh ({frames} meta:FILE)",
                sing.invalid.len(),
                frames = Setting::Frames
            ),
        ));
    }

    let prepared = Prepared {
        mesh: &mesh,
        topo: &topo,
        field: &field,
        matchings: &m,
        singular: &sing,
        polycube: polycube.as_ref(),
    };
    // The default edge is a guess from the bounding box: where its rounding cannot resolve a
    // feature, a finer one may (module docs, "Scale").
    let scales: Vec<f64> = match job.scale {
        Some(s) => vec![s],
        None => (0..SCALE_TRIES)
            .map(|i| scale * SCALE_STEP.powi(i as i32))
            .collect(),
    };
    // The edges given up, kept in the failure report (and moved into the stats on success).
    failure.tries.clear();
    for (i, &s) in scales.iter().enumerate() {
        let last = i + 1 == scales.len();
        let mut scale_used = s;
        failure.scale = s;
        let meshed = match mesh_at(job, ctx, &prepared, s, None, last, failure) {
            Ok(m) => m,
            Err(f)
                if f.unfit
                    && matches!(job.frames, FrameChoice::Polycube | FrameChoice::Constant) =>
            {
                // No aligned map of this field fits the shape: the axes' grid, unaligned
                // (module docs, "Grid"), at the given edge or one that resolves the solid.
                let g = job.scale.unwrap_or_else(|| grid_scale(&mesh, &topo, s));
                log::warn!(
                    "{}: {}; meshing the grid of the axes at edge {g:.6} instead, its staircase pillowed",
                    path.display(),
                    f.reason
                );
                failure.grid_fallback = Some(f.reason.clone());
                failure.scale = g;
                let aligned = failure.param.clone().unwrap_or_default();
                match mesh_at(job, ctx, &prepared, g, Some(&aligned), true, failure) {
                    Ok(m) => {
                        scale_used = g;
                        m
                    }
                    Err(e) => {
                        return Err(Error::input(
                            path,
                            format!(
                                "{}; the grid of the axes at edge {g:.6} failed too: {}",
                                f.reason, e.reason
                            ),
                        ));
                    }
                }
            }
            Err(f) if f.retry && !last => {
                let next = scales[i + 1];
                log::warn!(
                    "{}: at {} {s:.6}: {}; trying {next:.6}",
                    path.display(),
                    if i == 0 { "the default edge" } else { "edge" },
                    f.reason
                );
                failure.tries.push(ScaleTry {
                    scale: s,
                    error: f.reason,
                });
                continue;
            }
            Err(f) => {
                let tried = tried_before(failure, s);
                return Err(Error::input(path, format!("{}{tried}", f.reason)));
            }
        };
        let sj: Vec<f64> = meshed
            .per_hex
            .iter()
            .map(|q| q.min_scaled_jacobian)
            .collect();
        crate::hex::volume::write_hex(&job.output, &meshed.hexes, &[("scaled_jacobian", &sj)])?;
        return Ok(HexStats {
            tets: mesh.tets.len(),
            scale: scale_used,
            grid_fallback: failure.grid_fallback.take(),
            tries: std::mem::take(&mut failure.tries),
            stuffing,
            smooth,
            polycube: polycube.map(|p| p.report),
            chords_split,
            targets: meshed.targets,
            singular_by_valence: sing.by_valence(),
            singularities: sing,
            param: meshed.param,
            extract: meshed.extract,
            pillow: meshed.pillow,
            relax: meshed.relax,
            quality: meshed.quality,
            seconds: failure.seconds,
        });
    }
    unreachable!("at least one scale is tried")
}

/// The frame field `--frames` asks for, with the smooth field's or the polycube's report.
fn frame_field(
    job: &HexJob,
    ctx: &Ctx,
    mesh: &TetMesh,
    topo: &Topology,
) -> Result<(Vec<Frame>, Option<SmoothReport>, Option<Polycube>)> {
    let path = &job.input;
    Ok(match &job.frames {
        FrameChoice::Constant => (frames::constant_frames(mesh.tets.len()), None, None),
        FrameChoice::Smooth => {
            let (f, r) = ctx
                .pool
                .install(|| smooth_frames(mesh, &topo.neighbours, &SmoothParams::default()))
                .map_err(|e| Error::input(path, format!("smooth frames: {e}")))?;
            (f, Some(r), None)
        }
        FrameChoice::Meta(meta) => {
            let hexes: HexMesh = crate::hex::volume::read(meta)?.into_hex_mesh(meta)?;
            let f =
                frames::meta_frames(mesh, &hexes).map_err(|e| Error::input(meta, e.to_string()))?;
            (f, None, None)
        }
        FrameChoice::Polycube => {
            let p = polycube_frames(mesh, topo, &PolycubeParams::default())
                .map_err(|e| Error::input(path, e.to_string()))?;
            (p.frames.clone(), None, Some(p))
        }
    })
}

/// What a failure at edge `s` adds about the edges tried before it (none: nothing).
fn tried_before(failure: &HexFailure, s: f64) -> String {
    if failure.tries.is_empty() {
        return String::new();
    }
    let list: Vec<String> = failure
        .tries
        .iter()
        .map(|t| format!("{:.6}", t.scale))
        .collect();
    format!(
        " (at edge {s:.6}, after {} failed too: see the report's tries)",
        list.join(", ")
    )
}

/// The grid's edge without `--scale`: the default edge `s`, or the solid's volume over its
/// boundary's area where that is smaller (half a slab's thickness, a quarter of a rod's
/// diameter), so that the cubes wholly inside reach into its thin parts.
fn grid_scale(mesh: &TetMesh, topo: &Topology, s: f64) -> f64 {
    let volume: f64 = (0..mesh.tets.len()).map(|t| mesh.volume(t)).sum();
    let area: f64 = topo
        .boundary_triangles(mesh)
        .iter()
        .map(|t| 0.5 * crate::geom::vec::double_area(&t.map(|v| mesh.verts[v as usize])))
        .sum();
    if area > 0.0 && volume > 0.0 {
        s.min(volume / area)
    } else {
        s
    }
}

/// Default edges tried when `--scale` is not given: the first, then each this much finer.
pub const SCALE_STEP: f64 = 0.85;

/// Most default edges tried (module docs, "Scale").
pub const SCALE_TRIES: usize = 4;

/// A default edge given up, and why.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ScaleTry {
    /// The hex edge tried.
    pub scale: f64,
    /// What failed, as the error would have said.
    pub error: String,
}

/// What the meshing at every scale shares: the checked tetrahedra and the frame field.
struct Prepared<'a> {
    mesh: &'a TetMesh,
    topo: &'a Topology,
    field: &'a [Frame],
    matchings: &'a [[Rot; 4]],
    singular: &'a Singularities,
    polycube: Option<&'a Polycube>,
}

/// The hexahedra of one scale, and what made them.
struct Meshed {
    hexes: HexMesh,
    per_hex: Vec<HexQuality>,
    quality: MeshQuality,
    targets: &'static str,
    param: ParamReport,
    extract: ExtractReport,
    pillow: Option<PillowReport>,
    relax: Option<RelaxReport>,
}

/// Why one scale gave no hexahedra to write, and whether a finer edge may: the rounding
/// flipped tetrahedra, no hexahedron fits, or some came out inverted. A field that flips
/// tetrahedra before any rounding does so at every scale.
struct Failed {
    reason: String,
    retry: bool,
    /// The field's map flipped tetrahedra before any rounding: it does not fit the shape.
    unfit: bool,
}

/// Parameterise at hex edge `scale`, extract, pillow, relax and measure. Inverted hexahedra
/// are a failure unless `--keep-inverted` and this is the `last` scale tried.
fn mesh_at(
    job: &HexJob,
    ctx: &Ctx,
    p: &Prepared,
    scale: f64,
    grid: Option<&ParamReport>,
    last: bool,
    failure: &mut HexFailure,
) -> std::result::Result<Meshed, Failed> {
    // Seconds per step accumulate in the failure report, which the success takes over.
    let seconds = &mut failure.seconds;
    let fatal = |e: String| Failed {
        reason: e,
        retry: false,
        unfit: false,
    };
    let clock = Instant::now();
    let params = ParamParams {
        scale,
        ..ParamParams::default()
    };
    let mut input = Field {
        frames: p.field,
        targets: p.field,
        axes: p.polycube.map(|c| c.axes.as_slice()),
        matchings: p.matchings,
        singular: &p.singular.edges,
    };
    let mut targets = "frames";
    let (mut map, mut param) = match grid {
        // The axes' grid, unaligned (module docs, "Grid"): the map is `x / scale`.
        Some(aligned) => {
            targets = "grid";
            let map = GridMap {
                uvw: (0..p.mesh.tets.len())
                    .map(|t| p.mesh.corners(t).map(|x| x.map(|c| c / scale)))
                    .collect(),
                transitions: vec![[Transition::ID; 4]; p.mesh.tets.len()],
            };
            (map, aligned.clone())
        }
        None => {
            parameterise_with(p.mesh, p.topo, &input, &params).map_err(|e| fatal(e.to_string()))?
        }
    };
    if grid.is_none()
        && param.flipped_final > 0
        && let Some(c) = p.polycube
    {
        input.targets = &c.gradients;
        let (map2, param2) =
            parameterise_with(p.mesh, p.topo, &input, &params).map_err(|e| fatal(e.to_string()))?;
        if param2.flipped_final < param.flipped_final {
            (map, param, targets) = (map2, param2, "deformation");
        }
    }
    seconds[2] += clock.elapsed().as_secs_f64();
    failure.param = Some(param.clone());
    if grid.is_none() && param.flipped_final > 0 {
        return Err(flip_failure(&param, scale, p.mesh.tets.len()));
    }

    let clock = Instant::now();
    let (mut hexes, ext) = extract(p.mesh, &map).map_err(|e| fatal(e.to_string()))?;
    seconds[3] += clock.elapsed().as_secs_f64();
    if hexes.hexes.is_empty() {
        return Err(Failed {
            reason: format!(
                "no hexahedron fits inside at {s} {scale}: choose a smaller {s}",
                s = Setting::Scale
            ),
            retry: true,
            unfit: false,
        });
    }

    let clock = Instant::now();
    // A polycube map's corners, and a grid's staircase, need the boundary layer; the grid's
    // staircase first loses the cubes that touch along an edge or wrap around a vertex.
    let polycube_run = job.frames == FrameChoice::Polycube || grid.is_some();
    let pillowed = job.pillow.unwrap_or(polycube_run).then(|| {
        let removed = if grid.is_some() {
            make_pillowable(&mut hexes)
        } else {
            0
        };
        PillowReport {
            removed,
            ..pillow(&mut hexes)
        }
    });
    let relaxed = job.relax.then(|| {
        let tris = p.topo.boundary_triangles(p.mesh);
        // A polycube map's corners and edges lie where the solid is smooth: the boundary
        // quadrilaterals bend there without a feature of the solid, so only a much sharper
        // bend holds a vertex.
        let params = RelaxParams {
            feature_angle_deg: if polycube_run { 100.0 } else { 30.0 },
            ..RelaxParams::default()
        };
        ctx.pool
            .install(|| relax(&mut hexes, &p.mesh.verts, &tris, &params))
    });
    seconds[4] += clock.elapsed().as_secs_f64();

    let per_hex = ctx.pool.install(|| hex_qualities(&hexes));
    let quality = summarise(&per_hex);
    failure.quality = Some(quality.clone());
    failure.pillow = pillowed.clone();
    failure.relax = relaxed.clone();
    if quality.inverted > 0 && !(job.keep_inverted && last) {
        return Err(inverted_failure(&quality, relaxed.as_ref()));
    }
    Ok(Meshed {
        hexes,
        per_hex,
        quality,
        targets,
        param,
        extract: ext,
        pillow: pillowed,
        relax: relaxed,
    })
}

/// Why a map that flips tetrahedra yields no hexahedra (`tets` in all), and whether
/// another edge may help: flips before any rounding are the field's, at every edge.
fn flip_failure(param: &ParamReport, scale: f64, tets: usize) -> Failed {
    let cause = match &param.first_flip {
        Some(c) if param.flipped_continuous == 0 => format!(
            "; the first flips came with rounding round {} ({}), tetrahedra {:?}",
            c.round,
            c.fixed
                .iter()
                .map(|(what, k)| format!("{what} to {k}"))
                .collect::<Vec<_>>()
                .join(", "),
            c.tets
        ),
        _ => format!(
            "; {} were flipped before any rounding: the frame field does not fit the shape at scale {scale}",
            param.flipped_continuous
        ),
    };
    Failed {
        reason: format!(
            "the parameterisation flips {} of {} tetrahedra, so no valid hexahedra can be extracted{cause}; try a larger {} or other {}",
            param.flipped_final,
            tets,
            Setting::Scale,
            Setting::Frames
        ),
        // Flips before any rounding are the field's, at every edge.
        retry: param.flipped_continuous == 0,
        unfit: param.flipped_continuous > 0,
    }
}

/// Why hexahedra that came out inverted are not written, naming the worst and a fold
/// the untangling could not undo.
fn inverted_failure(quality: &MeshQuality, relaxed: Option<&RelaxReport>) -> Failed {
    let worst: Vec<String> = quality
        .worst_hexes
        .iter()
        .take(5)
        .map(|w| format!("{} ({:.3})", w.hex, w.scaled_jacobian))
        .collect();
    let folded = relaxed
        .and_then(|r| r.untangle.as_ref())
        .and_then(|u| u.conflicts.first())
        .map_or(String::new(), |&[a, b]| {
            format!(
                "; hexahedra {} and {} are folded onto each other at a corner (they share its three edges with opposite orientations), which no placement of the vertices undoes",
                a / 8,
                b / 8
            )
        });
    Failed {
        reason: format!(
            "{} of {} hexahedra are inverted (scaled Jacobian ≤ 0), worst: {}{folded}; nothing written ({} writes them anyway)",
            quality.inverted,
            quality.hexes,
            worst.join(", "),
            Setting::KeepInverted
        ),
        retry: true,
        unfit: false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_grid_edge_is_the_volume_over_the_area_where_that_is_finer() {
        // A 4 × 3 × 2 box: volume 24 over area 52 = 0.4615.
        let m = TetMesh::grid_box([4, 3, 2], 1.0);
        let topo = check_tets(&m).unwrap();
        assert!((grid_scale(&m, &topo, 1.0) - 24.0 / 52.0).abs() < 1e-12);
        // A coarser volume over area leaves the default edge.
        assert_eq!(grid_scale(&m, &topo, 0.25), 0.25);
        // A slab 0.1 thick: half its thickness (the sides' area counts a little).
        let mut slab = TetMesh::grid_box([4, 4, 1], 1.0);
        for p in &mut slab.verts {
            p[2] *= 0.1;
        }
        let topo = check_tets(&slab).unwrap();
        let g = grid_scale(&slab, &topo, 1.0);
        assert!((g - 1.6 / (32.0 + 1.6)).abs() < 1e-12, "{g}");
    }
}
