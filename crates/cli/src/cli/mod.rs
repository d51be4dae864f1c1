//! The command line: clap parses ([`args`]), every option is checked once ([`config`]), then
//! one file per command calls the library and prints its summary ([`report`]).
//!
//! Errors: a usage error clap finds exits 2 (its own message); a bad option value or output
//! path found by [`config`] (before any work) prints `scanflow: error: ...` and exits 2 too;
//! an error of the run itself (inputs, system) exits 1; SIGINT and SIGTERM exit 130 and 143
//! after removing the temporary outputs ([`signals`]). The library
//! logs through [`logger`], which writes past the progress bars. stdout carries only the
//! summaries and `info`/`check` output; a closed stdout (`scanflow ... | head`) ends the
//! process quietly.

/// `println!` that ends the process quietly when stdout is a closed pipe (`scanflow ... | head`)
/// instead of panicking.
macro_rules! outln {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        if let Err(e) = writeln!(std::io::stdout(), $($t)*) {
            if e.kind() == std::io::ErrorKind::BrokenPipe {
                std::process::exit(0);
            }
        }
    }};
}

pub mod args;
pub mod config;
pub mod flags;
pub mod logger;
pub mod signals;

mod check;
mod demo;
mod docs;
mod fit;
mod fit_tiles;
mod hex;
mod info;
mod ingest;
mod merge;
mod paths;
mod reconstruct;
mod report;
mod run_report;
mod spectral;
mod synth;

use anyhow::Result;

use scanflow::exec::Ctx;

use config::{Config, RunConfig};

/// Run one validated command.
pub fn run(config: Config) -> Result<()> {
    match config {
        Config::Synth(c) => synth::run(&c, &start(&c.run)?),
        Config::Ingest(c) => ingest::run(&c, &start(&c.run)?),
        Config::Reconstruct(c) => reconstruct::run(&c, &start(&c.run)?),
        Config::Check(c) => check::run(&c),
        Config::Info(c) => info::run(&c, &start(&c.run)?),
        Config::Demo(c) => demo::run(&c, &start(&c.run)?),
        Config::Spectral(c) => spectral::run(&c, &start(&c.run)?),
        Config::Fit(c) => fit::run(&c, &start(&c.run)?),
        Config::Merge(c) => merge::run(&c, &start(&c.run)?),
        Config::Hexmesh(c) => hex::run(&c, &start(&c.run)?),
        Config::Hexcheck(a) => hex::check(&a),
        Config::Completions(a) => docs::completions(&a),
        Config::Man(a) => docs::man(&a),
    }
}

/// The command's context; from here on log lines go through its progress reporter.
fn start(run: &RunConfig) -> Result<Ctx> {
    let ctx = run.ctx()?;
    logger::attach(&ctx.progress);
    Ok(ctx)
}
