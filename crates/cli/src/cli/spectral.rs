//! `scanflow filter`, `resample` and `spectrum`: their options checked (before any work),
//! then the spectral pipeline run in a work directory, and its summary printed.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};

use scanflow::exec::{Ctx, human_bytes, peak_rss_bytes};
use scanflow::pipeline::spectral::{self, ResampleParams, SpectralParams, SpectralStats};
use scanflow::pipeline::workdir::RunIdentity;
use scanflow::spectral::filter::{Filter, MAX_FREQ};
use scanflow::spectral::layout::LayoutParams;
use scanflow::spectral::patch::Overlap;

use super::args::{FilterArgs, ResampleArgs, SpectralInputs, SpectrumArgs};
use super::config::{Points, RunConfig, work_dir};
use super::paths;
use super::reconstruct::WorkRun;

/// Least band a resampled patch keeps (relative to its grid's Nyquist frequency): flat
/// patches still get a point every ten input spacings.
const MIN_BAND: f64 = 0.1;

/// Fewest points `--patch-size` allows (the layout's clusters hold up to 100 before merging).
const MIN_PATCH: usize = 100;

/// Most images `spectrum --images` writes.
const MAX_IMAGES: usize = 1000;

/// What a spectral command does.
#[derive(Debug, Clone)]
pub enum Job {
    /// `filter`.
    Filter {
        /// The filter.
        filter: Filter,
        /// `--write-parseval`.
        scalar: bool,
    },
    /// `resample`.
    Resample(ResampleParams),
    /// `spectrum`.
    Spectrum {
        /// `--images`.
        images: usize,
    },
}

/// A validated spectral command.
pub struct SpectralConfig {
    /// Threads, memory, progress.
    pub run: RunConfig,
    /// What to read.
    pub points: Points,
    /// What to write.
    pub output: PathBuf,
    /// Layout, overlap, work directory, resume.
    pub params: SpectralParams,
    /// Keep the work directory after success.
    pub keep_work: bool,
    /// The job.
    pub job: Job,
}

impl SpectralConfig {
    fn new(a: SpectralInputs, output: PathBuf, job: Job) -> Result<SpectralConfig> {
        let run = RunConfig::new(&a.common)?;
        if a.patch_size < MIN_PATCH {
            bail!(
                "--patch-size {}: expected at least {MIN_PATCH} points",
                a.patch_size
            );
        }
        if let Job::Spectrum { .. } = job {
            paths::new_dir(&output)?;
        } else {
            paths::output_file(&output, paths::PLY)?;
        }
        let given: Vec<&Path> = a
            .inputs
            .iter()
            .chain(a.conf.as_ref())
            .map(PathBuf::as_path)
            .collect();
        paths::not_an_input(&output, &given)?;
        let work_dir = work_dir(a.work_dir, &output)?;
        let points = Points::new(a.inputs, a.conf, &a.normal)?;
        Ok(SpectralConfig {
            run,
            points,
            params: SpectralParams {
                layout: LayoutParams {
                    patch_max: a.patch_size,
                    ..LayoutParams::default()
                },
                overlap: Overlap::default(),
                work_dir,
                resume: a.resume,
            },
            output,
            keep_work: a.keep_work,
            job,
        })
    }

    /// `scanflow filter`.
    pub fn filter(a: FilterArgs) -> Result<SpectralConfig> {
        let filter = parse_filter(&a)?;
        SpectralConfig::new(
            a.input,
            a.output,
            Job::Filter {
                filter,
                scalar: a.write_parseval,
            },
        )
    }

    /// `scanflow resample`.
    pub fn resample(a: ResampleArgs) -> Result<SpectralConfig> {
        let e = a.max_error;
        if !(e > 0.0 && e < 1.0) {
            bail!("--max-error {e}: expected a fraction of the bounding-box diagonal in (0, 1)");
        }
        if a.points == Some(0) {
            bail!("--points 0: expected at least one point");
        }
        let rp = ResampleParams {
            max_error: e,
            points: a.points,
            min_band: MIN_BAND,
        };
        SpectralConfig::new(a.input, a.output, Job::Resample(rp))
    }

    /// `scanflow spectrum`.
    pub fn spectrum(a: SpectrumArgs) -> Result<SpectralConfig> {
        if a.images > MAX_IMAGES {
            bail!("--images {}: expected at most {MAX_IMAGES}", a.images);
        }
        SpectralConfig::new(a.input, a.output, Job::Spectrum { images: a.images })
    }
}

/// A number given to `opt` in `s`.
fn number(opt: &str, s: &str, what: &str, x: &str) -> Result<f64> {
    x.trim()
        .parse()
        .map_err(|_| anyhow::anyhow!("{opt} {s}: {what} \"{x}\" is not a number"))
}

/// `A,B,G`: a band from `A` to `B` and its gain.
fn band(opt: &str, s: &str) -> Result<(f64, f64, f64)> {
    let v: Vec<&str> = s.split(',').collect();
    if v.len() != 3 {
        bail!("{opt} {s}: expected A,B,G (band from A to B, gain G)");
    }
    Ok((
        number(opt, s, "frequency", v[0])?,
        number(opt, s, "frequency", v[1])?,
        number(opt, s, "gain", v[2])?,
    ))
}

/// The one filter the options name, checked by [`Filter::check`] (the library's rules, its
/// message prefixed with the option).
fn parse_filter(a: &FilterArgs) -> Result<Filter> {
    let given = [
        a.lowpass.is_some(),
        a.bandstop.is_some(),
        a.enhance.is_some(),
        a.wiener.is_some(),
    ];
    match given.iter().filter(|&&g| g).count() {
        0 => bail!("no filter: give one of --lowpass, --bandstop, --enhance, --wiener"),
        1 => {}
        _ => bail!(
            "one filter at a time: give only one of --lowpass, --bandstop, --enhance, --wiener"
        ),
    }
    let (opt, s, filter) = if let Some(s) = &a.lowpass {
        let Some((kind, f)) = s.split_once(':') else {
            bail!("--lowpass {s}: expected gauss:F or ideal:F");
        };
        let cut = number("--lowpass", s, "frequency", f)?;
        let filter = match kind {
            "gauss" => Filter::Gauss { cut },
            "ideal" => Filter::Ideal { cut },
            k => bail!("--lowpass {s}: unknown kind \"{k}\": expected gauss or ideal"),
        };
        ("--lowpass", s.as_str(), filter)
    } else if let Some(s) = &a.bandstop {
        let (lo, hi, gain) = band("--bandstop", s)?;
        ("--bandstop", s.as_str(), Filter::BandStop { lo, hi, gain })
    } else if let Some(s) = &a.enhance {
        let (lo, hi, gain) = band("--enhance", s)?;
        ("--enhance", s.as_str(), Filter::Enhance { lo, hi, gain })
    } else {
        let s = a.wiener.as_deref().unwrap_or("auto");
        let snr = match s {
            "auto" => None,
            x => Some(x.parse::<f64>().map_err(|_| {
                anyhow::anyhow!("--wiener {s}: expected a signal-to-noise power ratio (a number), or nothing to estimate the noise")
            })?),
        };
        ("--wiener", s, Filter::Wiener { snr })
    };
    filter
        .check()
        .map_err(|e| anyhow::anyhow!("{opt} {s}: {e}"))?;
    Ok(filter)
}

/// The options that change a spectral run's output, for its identity.
fn options(c: &SpectralConfig) -> Vec<(&'static str, String)> {
    let mut o = vec![("--patch-size", c.params.layout.patch_max.to_string())];
    match &c.job {
        Job::Filter { filter, scalar } => {
            o.push(("command", "filter".into()));
            o.push(("filter", format!("{filter:?}")));
            o.push(("--write-parseval", scalar.to_string()));
        }
        Job::Resample(r) => {
            o.push(("command", "resample".into()));
            o.push(("--max-error", r.max_error.to_string()));
            o.push(("--points", format!("{:?}", r.points)));
        }
        Job::Spectrum { images } => {
            o.push(("command", "spectrum".into()));
            o.push(("--images", images.to_string()));
        }
    }
    o
}

/// Run the command and print its summary.
pub fn run(c: &SpectralConfig, ctx: &Ctx) -> Result<()> {
    let job = WorkRun {
        points: &c.points,
        output: &c.output,
        work_dir: &c.params.work_dir,
        resume: c.params.resume,
        keep_work: c.keep_work,
        shared: false,
    };
    let opts = options(c);
    // The parameters with the work directory the run was given.
    let in_work = |work: &Path| SpectralParams {
        work_dir: work.to_path_buf(),
        ..c.params.clone()
    };
    let identity = |src: &_, mode, np: &_| RunIdentity::with_options(src, mode, np, &opts);
    match &c.job {
        Job::Filter { filter, scalar } => {
            let st = job.run(ctx, identity, |store, work| {
                spectral::filter(store, &c.output, *filter, *scalar, &in_work(work), ctx)
            })?;
            summary("filtered", &st, &c.output);
        }
        Job::Resample(rp) => {
            let st = job.run(ctx, identity, |store, work| {
                spectral::resample(store, &c.output, rp, &in_work(work), ctx)
            })?;
            summary("resampled", &st, &c.output);
        }
        Job::Spectrum { images } => {
            let r = job.run(ctx, identity, |store, work| {
                scanflow::pipeline::spectrum::spectrum(
                    store,
                    &c.output,
                    *images,
                    &in_work(work),
                    ctx,
                )
            })?;
            summary("analysed", &r.stats, &c.output);
            let bands: Vec<String> = r
                .band_edges
                .windows(2)
                .zip(&r.band_energy)
                .map(|(w, e)| format!("{:.3}-{:.3}: {:.2}%", w[0], w[1].min(MAX_FREQ), 100.0 * e))
                .collect();
            outln!("energy by band (of Nyquist): {}", bands.join(", "));
            outln!(
                "wrote {} spectrum images, layout.ply and summary.json",
                r.images.len()
            );
        }
    }
    Ok(())
}

/// Print what a run did.
fn summary(verb: &str, st: &SpectralStats, output: &Path) {
    let secs = st.secs_patches + st.secs_blend;
    outln!(
        "{verb} {} points into {} in {:.2} s ({:.0} points/s; patches {:.2} s, of which layout {:.2} s; blending {:.2} s); peak memory {}",
        st.points_in,
        output.display(),
        secs,
        st.points_in as f64 / secs.max(1e-9),
        st.secs_patches,
        st.secs_layout,
        st.secs_blend,
        human_bytes(peak_rss_bytes())
    );
    outln!(
        "patches: {} (members min {:.0}, mean {:.0}, max {:.0}; normal cone mean {:.1}°, max {:.1}°)",
        st.patches,
        st.patch_members[0],
        st.patch_members[1],
        st.patch_members[2],
        st.aperture_deg[0],
        st.aperture_deg[1]
    );
    outln!(
        "height fields: RMS approximation error mean {:.3e}, max {:.3e} of the diagonal",
        st.sda_rms_rel[0],
        st.sda_rms_rel[1]
    );
    if st.parseval_rel[1] > 0.0 {
        outln!(
            "Parseval error (RMS change per patch): mean {:.3e}, max {:.3e} of the diagonal",
            st.parseval_rel[0],
            st.parseval_rel[1]
        );
    }
    if st.noise_rel > 0.0 {
        outln!(
            "estimated noise: {:.3e} of the diagonal (mean over patches)",
            st.noise_rel
        );
    }
    if st.points_out != st.points_in {
        outln!(
            "points written: {} ({:.3}× the input)",
            st.points_out,
            st.points_out as f64 / st.points_in.max(1) as f64
        );
    }
    outln!(
        "normals from the least-squares fallback: {} ({:.3}%); points no patch admitted: {}; in patches too small to fit: {}",
        st.normal_fallback,
        100.0 * st.normal_fallback as f64 / st.points_out.max(1) as f64,
        st.unblended,
        st.unpatched
    );
    if st.resumed_cells > 0 {
        outln!(
            "reused the patches of {} cells from the interrupted run",
            st.resumed_cells
        );
    }
}
