//! The `scanflow` command line: parse, check every option once, run the command (see
//! [`cli`]).

mod cli;

use std::process::ExitCode;

use cli::args::{Cli, ParseError};
use cli::config::Config;

/// Exit status of a wrong command line (an option's value, an output path), checked before any
/// work.
const USAGE: u8 = 2;

/// Exit status of a run that failed on its inputs or on the system.
const FAILED: u8 = 1;

fn main() -> ExitCode {
    cli::logger::install();
    let parsed = match Cli::parse_from_args(std::env::args_os()) {
        Ok(parsed) => parsed,
        Err(ParseError::Choice(msg)) => return fail(&msg, USAGE),
        Err(ParseError::Clap(e)) => e.exit(),
    };
    let config = match Config::new(parsed) {
        Ok(c) => c,
        Err(e) => return fail(&format!("{e:#}"), USAGE),
    };
    cli::signals::install();
    match cli::run(config) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            let usage = matches!(
                e.root_cause().downcast_ref(),
                Some(scanflow::Error::Usage(_))
            );
            fail(&format!("{e:#}"), if usage { USAGE } else { FAILED })
        }
    }
}

/// Report `msg` as the error that ends the run, with exit status `code`.
fn fail(msg: &str, code: u8) -> ExitCode {
    cli::logger::eprintln(&format!("scanflow: error: {msg}"));
    ExitCode::from(code)
}
