//! `merge`: the tiles a split reconstruction left in its work directory, welded in Morton
//! order into one mesh, byte for byte what one process writes (see
//! [`shard`](super::shard)).
//!
//! Every shard writes the same description (`merge.json`: the plan, the iso-value, the
//! vertex attributes and the non-empty tiles) before its tiles; `merge` checks that every
//! listed tile has its checkpoint, then reads them in waves on the pool and feeds them, in
//! order, to the welder and writer the single-process run uses.

use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::tiles::{MeshSink, VertexAttrs};
use super::workdir::{self, MERGE_FILE};
use crate::error::{Error, Result, Setting};
use crate::exec::Ctx;
use crate::fs::atomic::{self, Durability};
use crate::io::mesh_write::MeshTarget;
use crate::io::preview::Preview;
use crate::recon::Plan;
use crate::recon::checkpoint::{read_tile, tile_path};
use crate::types::{Aabb, demorton3};

/// Missing tiles a refused merge names.
const MISSING_SHOWN: usize = 3;

/// Tile meshes read at once per worker thread.
const READ_AHEAD: usize = 4;

/// What a split run's tiles are and how they are written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MergeDescription {
    /// The grids (the tiles' frame and the vertex format follow from it).
    pub plan: Plan,
    /// The iso-value, for the message when no tile holds a triangle.
    pub iso: f64,
    /// Whether vertices carry colours.
    pub with_color: bool,
    /// Whether vertices carry intensities.
    pub with_intensity: bool,
    /// Whether vertices carry sampling densities (`--density`).
    pub with_density: bool,
    /// The store reconstructed, which errors about the result name.
    pub input: PathBuf,
    /// The input points' bounds (what a preview frames).
    pub bounds: Aabb,
    /// The tiles that can hold surface, by Morton index, increasing.
    pub tiles: Vec<u64>,
}

/// Record `d` in the work directory `dir`: written once (the same by every shard); refused
/// when the one there differs (shards given different options).
pub fn describe(dir: &Path, d: &MergeDescription) -> Result<()> {
    let path = dir.join(MERGE_FILE);
    if let Some(old) = read_description(&path)? {
        if old != *d {
            return Err(Error::input(
                &path,
                format!(
                    "another shard of this work directory found other tiles or another iso-value: were the shards given the same store, options and {}?",
                    Setting::Mem
                ),
            ));
        }
        return Ok(());
    }
    let text =
        serde_json::to_string(d).map_err(|e| Error::Internal(format!("{MERGE_FILE}: {e}")))?;
    atomic::write(&path, text.as_bytes(), Durability::Synced)
}

/// The description at `path`, if there is one.
fn read_description(path: &Path) -> Result<Option<MergeDescription>> {
    match std::fs::read_to_string(path) {
        Ok(t) => serde_json::from_str(&t)
            .map(Some)
            .map_err(|e| Error::input(path, format!("unreadable merge description: {e}"))),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(Error::io(path, e)),
    }
}

/// What `merge` did.
#[derive(Debug, Clone, Serialize)]
pub struct MergeStats {
    /// Output vertices.
    pub vertices: u64,
    /// Output triangles.
    pub faces: u64,
    /// Tiles welded.
    pub tiles: usize,
    /// Most vertices held in the welder's frontier at once.
    pub peak_frontier: usize,
    /// Wall time in seconds.
    pub secs: f64,
    /// The picture of the mesh, when asked for.
    #[serde(skip)]
    pub preview: Option<Preview>,
}

/// Weld the tiles a split run left in `work` into the mesh `out`.
pub fn merge(work: &Path, out: &MeshTarget, ctx: &Ctx) -> Result<MergeStats> {
    let t0 = Instant::now();
    if !workdir::is_work_dir(work) {
        return Err(Error::input(
            work,
            format!(
                "not a scanflow work directory (it has no {} marker): give the {} of the run whose shards ran",
                workdir::MARKER,
                Setting::WorkDir
            ),
        ));
    }
    let path = work.join(MERGE_FILE);
    let d = read_description(&path)?.ok_or_else(|| {
        Error::input(
            work,
            format!(
                "no shard of a split run (reconstruct {}) has reached its tiles in this work directory: run merge after the shards",
                Setting::Shard
            ),
        )
    })?;
    // The shards measured densities for --density: only PLY holds them.
    out.format.carries(&out.path, out.normals, d.with_density)?;
    let tiles_dir = workdir::tiles_dir(work);
    let missing: Vec<u64> = d
        .tiles
        .iter()
        .copied()
        .filter(|&t| !tile_path(&tiles_dir, t).exists())
        .collect();
    if !missing.is_empty() {
        let named: Vec<String> = missing
            .iter()
            .take(MISSING_SHOWN)
            .map(|&t| {
                let c = demorton3(t);
                format!("tile {t} at ({}, {}, {})", c[0], c[1], c[2])
            })
            .collect();
        return Err(Error::input(
            work,
            format!(
                "{} of {} tiles have no mesh yet ({}{}): a shard has not finished; run merge once every shard has succeeded (SLURM: sbatch --dependency=afterok:JOBID), or run the missing shards again",
                missing.len(),
                d.tiles.len(),
                named.join(", "),
                if missing.len() > MISSING_SHOWN {
                    ", …"
                } else {
                    ""
                }
            ),
        ));
    }
    let attrs = VertexAttrs {
        color: d.with_color,
        intensity: d.with_intensity,
        density: d.with_density,
    };
    let mut sink = MeshSink::create(&d.plan, &d.bounds, attrs, out)?;
    let stage = ctx
        .progress
        .stage("merge", Some(d.tiles.len() as u64), "tiles");
    for wave in d.tiles.chunks(READ_AHEAD * ctx.threads()) {
        let meshes: Vec<Result<_>> = ctx.pool.install(|| {
            wave.par_iter()
                .map(|&t| read_tile(&tile_path(&tiles_dir, t)))
                .collect()
        });
        for (&t, m) in wave.iter().zip(meshes) {
            sink.add(t, &m?)?;
            stage.inc(1);
        }
    }
    stage.finish(None);
    let ts = sink.finish(&d.input, d.iso, d.plan.depth, ctx)?;
    Ok(MergeStats {
        vertices: ts.vertices,
        faces: ts.faces,
        tiles: d.tiles.len(),
        peak_frontier: ts.peak_frontier,
        secs: t0.elapsed().as_secs_f64(),
        preview: ts.preview,
    })
}
