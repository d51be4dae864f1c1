//! `scanflow check`: a mesh's counts and topology, and its distances to a truth or reference;
//! or, for a point file (a PLY without faces, or any other point format), every point's
//! distance to the truth or reference and the relief it keeps of the bumpy sphere.

use anyhow::Result;

use super::config::CheckConfig;
use super::report;

/// Check and print the report: the input is a mesh or points as its file says (a PLY's
/// `face` element), not as an option says.
pub fn run(c: &CheckConfig) -> Result<()> {
    if scanflow::metrics::is_point_file(&c.input)? {
        let rep = scanflow::metrics::run_check_points(
            &c.input,
            c.truth.as_deref(),
            c.reference.as_deref(),
        )?;
        if c.json {
            outln!("{}", serde_json::to_string(&rep)?);
        } else {
            outln!("{rep}");
        }
        return Ok(());
    }
    let rep = scanflow::metrics::run_check(
        &c.input,
        c.truth.as_deref(),
        c.reference.as_deref(),
        c.samples,
    )?;
    report::check(&rep, c.json)
}
