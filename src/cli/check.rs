//! `scanflow check`: a mesh's counts and topology, and its distances to a truth or reference.

use anyhow::Result;

use super::config::CheckConfig;
use super::report;

/// Check and print the report.
pub fn run(c: &CheckConfig) -> Result<()> {
    let rep = scanflow::metrics::run_check(
        &c.mesh,
        c.truth.as_deref(),
        c.reference.as_deref(),
        c.samples,
    )?;
    report::check(&rep, c.json)
}
