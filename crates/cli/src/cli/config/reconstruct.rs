//! `scanflow reconstruct`'s options, checked once: the solver's, the mesh's and the run's, the
//! `--hex` job, the inputs' confidences and the shard.

use super::*;

/// `scanflow reconstruct`.
pub struct ReconstructConfig {
    /// Threads, memory, progress.
    pub run: RunConfig,
    /// What to read.
    pub points: Points,
    /// The mesh to write.
    pub output: PathBuf,
    /// Its format and normals.
    pub mesh: MeshTarget,
    /// The picture and report.
    pub outputs: RunOutputs,
    /// Depth, smoothing, refinement, tiles, GPU, work directory, resume.
    pub params: ReconParams,
    /// Keep the work directory after success.
    pub keep_work: bool,
    /// `--hex`: hexahedra of the reconstructed surface's inside.
    pub hex: Option<scanflow::pipeline::hexmesh::HexJob>,
}

impl ReconstructConfig {
    pub(super) fn new(a: ReconstructArgs) -> Result<ReconstructConfig> {
        let smooth = parse_smooth(&a.smooth)?;
        let point_weight = parse_point_weight(&a.point_weight)?;
        let run = RunConfig::new(&a.common)?;
        let error = a.error;
        if !(error >= 0.0 && error.is_finite()) {
            bail!(
                "--error {error}: expected a non-negative number (relative to the bounding-box diagonal)"
            );
        }
        if !DEPTHS.contains(&a.depth) {
            bail!(
                "--depth {} is out of range: supported depths are {}..={}",
                a.depth,
                DEPTHS.start(),
                DEPTHS.end()
            );
        }
        if let Some(t) = a.tile
            && !(t.is_power_of_two() && TILES.contains(&t))
        {
            bail!(
                "--tile {t}: expected a power of two from {} to {}",
                TILES.start(),
                TILES.end()
            );
        }
        let shallowest = scanflow::recon::plan::MIN_DENSE_DEPTH - 2;
        if let Some(c) = a.coarse_depth
            && !(shallowest..=a.depth.saturating_sub(2)).contains(&c)
        {
            bail!(
                "--coarse-depth {c}: expected {shallowest} to {} (two octaves below --depth {} at most)",
                a.depth.saturating_sub(2),
                a.depth
            );
        }
        let screened = point_weight != PointWeight::Fixed(0.0);
        let least = scanflow::pipeline::reconstruct::least_mem(a.depth, screened);
        if run.mem_bytes < least {
            bail!(
                "--mem {}: a reconstruction at --depth {} needs at least {} (the floor of every reconstruction, where its levels of leaves over the smallest coarse solve fit); raise --mem",
                human_bytes(run.mem_bytes),
                a.depth,
                human_bytes(least)
            );
        }
        let (mesh, outputs) = mesh_target(&a.output, &a.mesh, a.density)?;
        if let Some(d) = a.trim_density
            && !(d >= 0.0 && d.is_finite())
        {
            bail!(
                "--trim-density {d}: expected a density (input points per square unit) of 0 or more"
            );
        }
        let given: Vec<&Path> = a
            .inputs
            .iter()
            .chain(a.conf.as_ref())
            .map(PathBuf::as_path)
            .collect();
        paths::not_an_input(&a.output, &given)?;
        for (opt, extra) in [
            ("--preview", &outputs.preview),
            ("--report", &outputs.report),
        ] {
            if let Some(p) = extra {
                paths::not_an_input_as(opt, p, &given)?;
            }
        }
        let work_dir = work_dir(a.work_dir, &a.output)?;
        if let Some(sp) = a.samples_per_node
            && !(sp > 0.0 && sp.is_finite())
        {
            bail!("--samples-per-node {sp}: expected a positive number of samples per fine voxel");
        }
        let mut params = ReconParams::new(a.depth, work_dir);
        params.solve.coarse_depth = a.coarse_depth;
        params.solve.smoothing = smooth;
        params.solve.point_weight = point_weight;
        params.solve.error = error;
        params.solve.min_points = a.min_points;
        params.solve.samples_per_node = a.samples_per_node;
        params.solve.confidence = a.confidence;
        params.mesh.fit = !a.no_fit;
        params.mesh.trim = a.trim;
        params.mesh.density = a.density;
        params.mesh.trim_density = a.trim_density;
        params.run.tile_voxels = a.tile;
        params.run.resume = a.resume;
        params.run.gpu = a.gpu.into();
        params.run.gpu_solve = a.gpu_solve.into();
        let hex = hex_job(a.hex, a.hex_scale, &mesh, &a.output, &given)?;
        let points = Points::new(a.inputs, a.conf, &a.normal)?;
        if a.confidence {
            check_confidences(&points, a.normal.normals)?;
        }
        if let Some(text) = &a.shard {
            if let Some(p) = &a.mesh.preview {
                bail!(
                    "--preview {}: a shard writes no mesh to draw; give --preview to merge",
                    p.display()
                );
            }
            params.run.shard = Shard::parse(text, |k| std::env::var(k).ok())?;
            if let Points::Files(..) = points {
                bail!(
                    "--shard {text}: shards reconstruct a store: ingest the point files once first (scanflow ingest FILES -o STORE, the job script's first step), then give the store to every shard"
                );
            }
        }
        Ok(ReconstructConfig {
            run,
            points,
            output: a.output,
            mesh,
            outputs,
            params,
            keep_work: a.keep_work,
            hex,
        })
    }
}

/// `--smooth`: `measured` or a width in voxels.
pub(super) fn parse_smooth(s: &str) -> Result<Smoothing> {
    Ok(match s {
        "measured" => Smoothing::Measured,
        w => match w.parse::<f64>() {
            Ok(s) if s > 0.0 && s <= MAX_SMOOTH_VOXELS => Smoothing::Fixed(s),
            _ => bail!(
                "--smooth {w}: expected measured or a width in voxels in (0, {MAX_SMOOTH_VOXELS}]"
            ),
        },
    })
}

/// `--point-weight`: `standard`, `auto` or a screening weight.
pub(super) fn parse_point_weight(s: &str) -> Result<PointWeight> {
    Ok(match s {
        "standard" => PointWeight::Standard,
        "auto" => PointWeight::Auto,
        w => match w.parse::<f64>() {
            Ok(a) if (0.0..=MAX_POINT_WEIGHT).contains(&a) => PointWeight::Fixed(a),
            _ => bail!(
                "--point-weight {w}: expected standard, auto or a screening weight in [0, {MAX_POINT_WEIGHT}]"
            ),
        },
    })
}

/// `--hex`: the hexahedra of the reconstructed surface `output` (a PLY or OBJ `mesh`), none of
/// the `given` inputs.
pub(super) fn hex_job(
    hex: Option<PathBuf>,
    hex_scale_opt: Option<f64>,
    mesh: &MeshTarget,
    output: &Path,
    given: &[&Path],
) -> Result<Option<scanflow::pipeline::hexmesh::HexJob>> {
    Ok(match hex {
        Some(h) => {
            if mesh.format == MeshFormat::Stl {
                bail!(
                    "--hex {}: hexmesh reads the surface as PLY or OBJ; name -o *.ply or *.obj",
                    h.display()
                );
            }
            hex_scale(hex_scale_opt, "--hex-scale")?;
            paths::output_file_as("--hex", &h, VOLUME_EXTS, "a hexahedral mesh")?;
            paths::not_an_input(&h, given)?;
            if h == output {
                bail!("--hex {}: the same file as -o", h.display());
            }
            Some(scanflow::pipeline::hexmesh::HexJob {
                input: output.to_path_buf(),
                output: h,
                frames: scanflow::pipeline::hexmesh::FrameChoice::Polycube,
                scale: hex_scale_opt,
                tet_size: None,
                pillow: None,
                relax: true,
                keep_inverted: false,
                report: None,
            })
        }
        None => None,
    })
}

/// `--confidence` on point files: each must carry confidences, or normals kept from the file
/// whose lengths are (headers only: refused before any work).
pub(super) fn check_confidences(
    points: &Points,
    normals: crate::cli::args::NormalsChoice,
) -> Result<()> {
    let Points::Files(inputs, _) = points else {
        return Ok(());
    };
    // Headers only: refused before any work.
    let attrs = inputs
        .files
        .iter()
        .map(|f| Ok(scanflow::io::open(f)?.attributes()))
        .collect::<Result<Vec<_>>>()?;
    // Normals come from the inputs (so their lengths can be confidences) unless they
    // are estimated: always with `estimate`, with `auto` when one input has none.
    let kept = match normals {
        crate::cli::args::NormalsChoice::Estimate => false,
        crate::cli::args::NormalsChoice::Use => true,
        crate::cli::args::NormalsChoice::Auto => attrs.iter().all(|at| at.normal),
    };
    for (f, at) in inputs.files.iter().zip(&attrs) {
        if !(at.confidence || (at.normal && kept)) {
            bail!(
                "--confidence: {} carries no confidence (a PLY vertex property \"confidence\") and no normals whose lengths could be the confidences, so there is nothing to weigh its points by",
                f.display()
            );
        }
    }
    Ok(())
}
