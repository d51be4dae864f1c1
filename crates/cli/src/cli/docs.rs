//! `scanflow completions SHELL` and `scanflow man -o DIR`: shell completions and man pages
//! generated from the clap definitions (`clap_complete`, `clap_mangen`), so they never
//! drift from the options.

use anyhow::{Context, Result};
use clap::CommandFactory;

use scanflow::fs::atomic::{self, Durability};

use super::args::{Cli, CompletionsArgs, ManArgs};

/// Print the completion script for `a.shell` on stdout.
pub fn completions(a: &CompletionsArgs) -> Result<()> {
    let mut cmd = Cli::command();
    let mut out = Vec::new();
    clap_complete::generate(a.shell, &mut cmd, "scanflow", &mut out);
    use std::io::Write as _;
    std::io::stdout()
        .write_all(&out)
        .context("writing the completion script")?;
    Ok(())
}

/// Write `scanflow.1` and `scanflow-COMMAND.1` for every command into `a.output`.
pub fn man(a: &ManArgs) -> Result<()> {
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("{}: cannot create the directory", a.output.display()))?;
    let cmd = Cli::command();
    let mut pages = vec![("scanflow".to_string(), cmd.clone())];
    for sub in cmd.get_subcommands() {
        let name = format!("scanflow-{}", sub.get_name());
        pages.push((name.clone(), sub.clone().name(name)));
    }
    for (name, page) in &pages {
        let mut buf = Vec::new();
        clap_mangen::Man::new(page.clone())
            .render(&mut buf)
            .with_context(|| format!("rendering the man page {name}"))?;
        atomic::write(
            &a.output.join(format!("{name}.1")),
            &buf,
            Durability::Synced,
        )?;
    }
    outln!(
        "wrote {} man pages into {}",
        pages.len(),
        a.output.display()
    );
    Ok(())
}
