//! `scanflow merge`: the tiles of a split reconstruction welded into one mesh
//! (`pipeline::merge`), then the shared work directory removed (only what scanflow made in
//! it) unless `--keep-work`.

use anyhow::Result;

use scanflow::exec::Ctx;
use scanflow::pipeline::workdir;

use super::config::MergeConfig;
use super::run_report::{RunEnd, RunStart};
use super::{report, signals};

/// Merge and print the summary.
pub fn run(c: &MergeConfig, ctx: &Ctx) -> Result<()> {
    signals::set_note(Some(format!(
        "no output written; the work directory {} is kept: run merge again",
        c.work_dir.display()
    )));
    let run = RunStart::now(&c.outputs);
    let st = scanflow::pipeline::merge(&c.work_dir, &c.mesh, ctx)?;
    signals::set_note(Some(format!("{} is complete", c.output.display())));
    report::merge(&st, &c.output);
    let mut fields = serde_json::to_value(&st).unwrap_or_default();
    if let Some(o) = fields.as_object_mut() {
        o.insert("output".into(), c.output.display().to_string().into());
    }
    ctx.progress.summary("merge", st.secs, &fields);
    let options = vec![(
        "work directory".to_string(),
        c.work_dir.display().to_string(),
    )];
    run.finish(
        ctx,
        RunEnd {
            command: "merge",
            inputs: std::slice::from_ref(&c.work_dir),
            points: None,
            options,
            output: &c.output,
            result: serde_json::to_value(&st).unwrap_or_default(),
            leaf_map: None,
            preview: st.preview.clone(),
            triangles: Some(st.faces),
            secs: st.secs,
        },
    )?;
    if !c.keep_work {
        let left = workdir::remove_owned(&c.work_dir)?;
        if !left.is_empty() {
            log::warn!(
                "{}: kept: it holds {} entries scanflow did not make",
                c.work_dir.display(),
                left.len()
            );
        }
    }
    Ok(())
}
