//! `scanflow ingest`: point files into an on-disk octree store.

use anyhow::{Result, bail};

use scanflow::exec::Ctx;
use scanflow::io::InputSpec;
use scanflow::pipeline::ingest_split::{SplitOutcome, ingest_split};
use scanflow::types::Viewpoint;

use super::config::{IngestConfig, Inputs};
use super::report;

/// Ingest and print the summary.
pub fn run(c: &IngestConfig, ctx: &Ctx) -> Result<()> {
    let specs = input_specs(&c.inputs)?;
    let Some((shard, work)) = &c.split else {
        let st = scanflow::pipeline::ingest::ingest(&specs, &c.output, &c.params, ctx)?;
        report::ingest(&st, &c.output);
        return Ok(());
    };
    let work = scanflow::pipeline::workdir::resolve(work, &c.output)?;
    match ingest_split(&specs, &c.output, &c.params, *shard, &work, ctx)? {
        SplitOutcome::Committed(st) => report::ingest(&st, &c.output),
        SplitOutcome::Done => println!(
            "shard {shard}: {} is complete (written by another task)",
            c.output.display()
        ),
    }
    Ok(())
}

/// The scans of the `.conf` (with their poses), then the point files, each file with its
/// viewpoint; an error when there is nothing to read.
pub fn input_specs(inputs: &Inputs) -> Result<Vec<InputSpec>> {
    let mut specs = Vec::new();
    if let Some(c) = &inputs.conf {
        specs.extend(scanflow::io::conf::read_conf(c)?);
    }
    let from_conf = specs.len();
    // An E57 file is one input per scan, each seen from its scanner's position.
    let mut e57_scans = Vec::new();
    for f in &inputs.files {
        if is_e57(f) {
            let scans = scanflow::io::e57::scan_inputs(f)?;
            e57_scans.push(scans.len());
            specs.extend(scans);
        } else {
            e57_scans.push(0);
            specs.push(InputSpec::plain(f));
        }
    }
    if specs.is_empty() {
        bail!("no input: give point files, a store, or --conf FILE");
    }
    // --viewpoint: once for every input, or once per file (an E57 file's scans share it).
    let per_file: Vec<Option<[f64; 3]>> = match inputs.viewpoints.as_slice() {
        [] => vec![None; inputs.files.len()],
        [one] => vec![Some(*one); inputs.files.len()],
        // `Inputs` holds one per file here.
        each => each.iter().copied().map(Some).collect(),
    };
    let mut at = from_conf;
    for (vp, scans) in per_file.iter().zip(&e57_scans) {
        for s in &mut specs[at..at + (*scans).max(1)] {
            if let Some(p) = vp {
                s.viewpoint = Some(Viewpoint::Point(*p));
            }
        }
        at += (*scans).max(1);
    }
    Ok(specs)
}

/// An E57 file, by its extension.
fn is_e57(path: &std::path::Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("e57"))
}
