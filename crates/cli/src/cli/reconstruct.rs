//! `scanflow reconstruct`: a store, or point files ingested into the work directory, to a
//! mesh. The work directory is taken through `pipeline::workdir` (made and marked, or
//! resumed after its identity is checked), removed after success, and after a failure kept
//! only when it holds something a resume reuses, with a word on where it is.

use std::path::Path;

use anyhow::{Result, bail};

use scanflow::Error;
use scanflow::exec::Ctx;
use scanflow::fs::atomic;
use scanflow::io::mesh_write::MeshTarget;
use scanflow::normals::{NormalParams, NormalsMode};
use scanflow::pipeline::ingest::open_or_ingest;
use scanflow::pipeline::workdir::{self, Lease, RunIdentity};
use scanflow::pipeline::workdir::{StoreSource, WORK_STORE};
use scanflow::pipeline::{ReconParams, ReconStats};
use scanflow::store::Store;

use super::config::{Points, ReconstructConfig};
use super::ingest::input_specs;
use super::run_report::{RunEnd, RunStart, recon_options};
use super::{paths, report, signals};

/// Reconstruct and print the summary; write the picture and the report when asked.
pub fn run(c: &ReconstructConfig, ctx: &Ctx) -> Result<()> {
    let t0 = std::time::Instant::now();
    let run = RunStart::now(&c.outputs);
    let st = reconstruct(ctx, &c.points, &c.mesh, &c.params, c.keep_work)?;
    let secs = t0.elapsed().as_secs_f64();
    let inputs = match &c.points {
        Points::Store { dir, .. } => vec![dir.clone()],
        Points::Files(inputs, _) => inputs.paths().iter().map(|p| p.to_path_buf()).collect(),
    };
    let outputs = || {
        run.finish(
            ctx,
            RunEnd {
                command: "reconstruct",
                inputs: &inputs,
                points: Some(st.points),
                options: recon_options(c),
                output: &c.output,
                result: serde_json::to_value(&st).unwrap_or_default(),
                leaf_map: Some(st.leaf_map.clone()),
                preview: st.preview.clone(),
                triangles: (!c.params.run.shard.is_split()).then_some(st.faces),
                secs,
            },
        )
    };
    if c.params.run.shard.is_split() {
        let work = workdir::resolve(&c.params.run.work_dir, &c.output)?;
        report::shard(&st, c.params.run.shard, &work, &c.output, secs);
        return outputs();
    }
    report::reconstruct(&st, &c.output, secs);
    let mut fields = serde_json::to_value(&st).unwrap_or_default();
    if let Some(o) = fields.as_object_mut() {
        o.remove("leaf_map");
        o.insert("output".into(), c.output.display().to_string().into());
    }
    ctx.progress.summary("reconstruct", secs, &fields);
    outputs()?;
    if let Some(job) = &c.hex {
        let st = scanflow::pipeline::hexmesh::hexmesh(job, ctx)?;
        super::hex::summary(&st, &job.output)?;
    }
    Ok(())
}

/// Open the store, or ingest the point files into the work directory (unless a resumed run
/// already did), reconstruct into `mesh`, and remove the work directory unless
/// `keep_work`.
pub fn reconstruct(
    ctx: &Ctx,
    points: &Points,
    mesh: &MeshTarget,
    params: &ReconParams,
    keep_work: bool,
) -> Result<ReconStats> {
    let job = WorkRun {
        points,
        output: &mesh.path,
        work_dir: &params.run.work_dir,
        resume: params.run.resume,
        keep_work,
        shared: params.run.shard.is_split(),
    };
    job.run(
        ctx,
        |source, mode, normal_params| params.identity(source, mode, normal_params),
        |store, work| {
            let mut params = params.clone();
            params.run.work_dir = work.to_path_buf();
            scanflow::pipeline::reconstruct(store, mesh, &params, ctx)
        },
    )
}

/// A command that reads a store, or point files ingested into a work directory, and writes
/// `output`.
pub struct WorkRun<'a> {
    /// What to read.
    pub points: &'a Points,
    /// What to write (a file, or a directory that must not exist).
    pub output: &'a Path,
    /// The work directory asked for.
    pub work_dir: &'a Path,
    /// `--resume`.
    pub resume: bool,
    /// `--keep-work`.
    pub keep_work: bool,
    /// The work directory is shared with the other shards of a split run: joined, never
    /// removed (by success or failure), and its temporary files left alone (another task
    /// may be writing them); `merge` removes it.
    pub shared: bool,
}

impl WorkRun<'_> {
    /// Take the work directory (made and marked, or resumed after `identity`'s check), open
    /// or ingest the store, run `body` on it, and remove the work directory unless
    /// `keep_work`; after a failure keep it only when a resume can reuse it.
    pub fn run<T>(
        &self,
        ctx: &Ctx,
        identity: impl FnOnce(&StoreSource, NormalsMode, &NormalParams) -> scanflow::Result<RunIdentity>,
        body: impl FnOnce(&Store, &Path) -> scanflow::Result<T>,
    ) -> Result<T> {
        let output = self.output;
        let (source, normals) = match self.points {
            Points::Store {
                dir,
                ignores_normal_options,
            } => {
                if *ignores_normal_options {
                    log::warn!(
                        "{}: a store keeps the normals it was ingested with; --normals and --viewpoint apply to `ingest`",
                        dir.display()
                    );
                }
                (StoreSource::Store(dir.clone()), None)
            }
            Points::Files(inputs, normals) => {
                (StoreSource::Points(input_specs(inputs)?), Some(normals))
            }
        };
        let (mode, normal_params) = normals.map(|n| (n.mode, n.params)).unwrap_or_default();
        let work = workdir::resolve(self.work_dir, output)?;
        check_paths(&source, output, &work)?;
        let identity = identity(&source, mode, &normal_params)?;
        if self.shared {
            let lease = workdir::join(&work, &identity)?;
            return open_or_ingest(&source, &work, true, mode, normal_params, ctx)
                .and_then(|store| body(&store, lease.dir()))
                .map_err(Into::into);
        }
        for p in atomic::remove_stale_temps(output, false) {
            log::info!("removed {}, left by a killed run", p.display());
        }
        let lease = workdir::claim(&work, &identity, self.resume)?;
        signals::set_note(Some(kept_note(&work)));
        let run = open_or_ingest(&source, &work, self.resume, mode, normal_params, ctx)
            .and_then(|store| body(&store, &work))
            .map_err(|e| name_inputs(e, &work.join(WORK_STORE), &source));
        match run {
            Ok(st) => {
                signals::set_note(Some(format!("{} is complete", output.display())));
                if !self.keep_work {
                    let left = lease.remove()?;
                    if !left.is_empty() {
                        log::warn!(
                            "{}: kept: it holds {} entries scanflow did not make",
                            work.display(),
                            left.len()
                        );
                    }
                }
                Ok(st)
            }
            Err(e) => {
                signals::set_note(None);
                Err(after_failure(lease, e))
            }
        }
    }
}

/// Most input names an error about the whole input lists.
const NAMES_SHOWN: usize = 3;

/// An error about the work directory's store as a whole (its points: too few, on a plane, no
/// normals) is about the point files it was ingested from: name them instead.
fn name_inputs(e: Error, store: &Path, source: &StoreSource) -> Failure {
    match (e, source) {
        (Error::Input { path, msg }, StoreSource::Points(specs)) if path == store => {
            let mut names: Vec<String> = specs
                .iter()
                .take(NAMES_SHOWN)
                .map(|s| s.path.display().to_string())
                .collect();
            if specs.len() > NAMES_SHOWN {
                names.push(format!("and {} more", specs.len() - NAMES_SHOWN));
            }
            Failure::Inputs(Error::input(names.join(", "), msg))
        }
        (e, _) => Failure::Run(e),
    }
}

/// Why a run failed: its inputs as a whole (nothing in the work directory can help), or
/// anything else.
enum Failure {
    Inputs(Error),
    Run(Error),
}

/// The inputs and the output are never inside the work directory (what success removes),
/// and the output is never an input.
fn check_paths(source: &StoreSource, output: &Path, work: &Path) -> Result<()> {
    let inputs: Vec<&Path> = match source {
        StoreSource::Store(dir) => vec![dir.as_path()],
        StoreSource::Points(specs) => specs.iter().map(|s| s.path.as_path()).collect(),
    };
    paths::not_an_input(output, &inputs)?;
    for p in inputs.iter().copied().chain([output]) {
        if paths::inside(p, work) || paths::same_file(p, work) {
            bail!(
                "{}: lies inside the work directory {}, which scanflow removes after the run; choose another --work-dir",
                p.display(),
                work.display()
            );
        }
    }
    Ok(())
}

/// The interrupt and failure note for a work directory kept for `--resume`.
fn kept_note(work: &Path) -> String {
    format!(
        "no output written; the work directory {} is kept: run the same command with --resume to continue",
        work.display()
    )
}

/// After a failed run: keep the work directory when a resume can reuse it (and say so),
/// else remove what scanflow made there.
fn after_failure(lease: Lease, f: Failure) -> anyhow::Error {
    let (e, reusable) = match f {
        Failure::Inputs(e) => (e, false),
        Failure::Run(e) => (e, lease.has_checkpoints()),
    };
    if reusable {
        log::warn!("{}", kept_note(lease.dir()));
        return e.into();
    }
    match lease.remove() {
        Ok(_) => e.into(),
        Err(r) => anyhow::Error::from(e)
            .context(format!("and the work directory could not be removed: {r}")),
    }
}
