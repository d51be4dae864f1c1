//! The `scanflow` command line: parse, check every option once, run the command (see
//! [`cli`]).

mod cli;

/// glibc's malloc with one arena, or mimalloc where the budget leaves room for it
/// (`scanflow::exec::alloc`: chosen per run).
#[global_allocator]
static ALLOC: scanflow::exec::alloc::Alloc = scanflow::exec::alloc::Alloc;

use std::process::ExitCode;

use cli::args::{Cli, ParseError};
use cli::config::Config;

/// Exit status of a wrong command line (an option's value, an output path), checked before any
/// work.
const USAGE: u8 = 2;

/// Exit status of a run that failed on its inputs or on the system.
const FAILED: u8 = 1;

/// One glibc malloc arena for the whole process. glibc gives each thread that allocates its
/// own arena and keeps what is freed there for that arena, so the solves' large buffers,
/// freed on one worker and wanted on another, were held twice: a 1M-point reconstruction at
/// depth 9 under `--mem 128M` peaked at 185 to 223 MiB with the default arenas and 121 MiB
/// with one, in the same time (10.5 s and 10.1 s without `--mem`). A fixed mmap threshold
/// (1 MiB) also returned the memory but made the run 2.3× slower. On many cores the one
/// arena is the bound; runs with room in their budget take mimalloc instead
/// (`scanflow::exec::alloc`).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn one_malloc_arena() {
    // SAFETY: mallopt only sets a parameter of glibc's allocator; called first in main,
    // before any other thread exists.
    unsafe {
        libc::mallopt(libc::M_ARENA_MAX, 1);
    }
}

fn main() -> ExitCode {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    one_malloc_arena();
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
