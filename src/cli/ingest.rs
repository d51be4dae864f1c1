//! `scanflow ingest`: point files into an on-disk octree store.

use anyhow::{Result, bail};

use scanflow::exec::Ctx;
use scanflow::io::InputSpec;
use scanflow::types::Viewpoint;

use super::config::{IngestConfig, Inputs};
use super::report;

/// Ingest and print the summary.
pub fn run(c: &IngestConfig, ctx: &Ctx) -> Result<()> {
    let specs = input_specs(&c.inputs)?;
    let st = scanflow::pipeline::ingest::ingest(&specs, &c.output, &c.params, ctx)?;
    report::ingest(&st, &c.output);
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
    specs.extend(inputs.files.iter().map(InputSpec::plain));
    if specs.is_empty() {
        bail!("no input: give point files, a store, or --conf FILE");
    }
    let files = &mut specs[from_conf..];
    match inputs.viewpoints.as_slice() {
        [] => {}
        [one] => files
            .iter_mut()
            .for_each(|s| s.viewpoint = Some(Viewpoint::Point(*one))),
        each => {
            // `Inputs` holds one per file here.
            for (s, p) in files.iter_mut().zip(each) {
                s.viewpoint = Some(Viewpoint::Point(*p));
            }
        }
    }
    Ok(specs)
}
