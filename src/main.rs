//! The `scanflow` command line: parse, check every option once, run the command (see
//! [`cli`]).

mod cli;

use std::process::ExitCode;

use cli::args::{Cli, ParseError};
use cli::config::Config;

fn main() -> ExitCode {
    cli::logger::install();
    let parsed = match Cli::parse_from_args(std::env::args_os()) {
        Ok(parsed) => parsed,
        Err(ParseError::Choice(msg)) => return fail(&msg),
        Err(ParseError::Clap(e)) => e.exit(),
    };
    match Config::new(parsed).and_then(cli::run) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => fail(&format!("{e:#}")),
    }
}

/// Report `msg` as the error that ends the run; exit status 1.
fn fail(msg: &str) -> ExitCode {
    cli::logger::eprintln(&format!("scanflow: error: {msg}"));
    ExitCode::FAILURE
}
