//! `--report OUT.html|OUT.json` and `--preview OUT.png`: what a run leaves behind for the
//! morning after an overnight job.
//!
//! The JSON report holds the figures: the command line, when it ran, its inputs (path, size,
//! points, bounds), the options as given, the result's statistics, every stage with its time
//! and the peak memory at its end, the resident memory over time, the leaf map (from
//! above: leaves holding points and refined leaves per column) and the output's `check`
//! summary (counts, watertightness, manifoldness). The HTML report is one self-contained
//! page of the same: tables, the memory timeline and the leaf map as inline SVG, and the
//! preview as an inline PNG; it loads nothing and runs no script.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Result;
use base64::Engine as _;
use serde::Serialize;

use std::time::SystemTime;

use scanflow::exec::progress::{StageRecord, timestamp};
use scanflow::exec::{Ctx, MemoryTimeline, human_bytes};
use scanflow::fs::atomic::{self, Durability};
use scanflow::io::preview::Preview;
use scanflow::pipeline::reconstruct::LeafMap;

use super::config::{ReconstructConfig, RunOutputs};

/// Bytes of memory `check` needs per triangle (mesh, edge map), to decide whether the
/// output's check fits the run's budget.
const CHECK_BYTES_PER_TRIANGLE: u64 = 160;

/// An input and what is known of it.
#[derive(Debug, Clone, Serialize)]
pub struct InputInfo {
    /// The path given.
    pub path: PathBuf,
    /// Size in bytes (a directory: the sum of its files').
    pub bytes: u64,
}

impl InputInfo {
    /// `path` and its size.
    pub fn of(path: &Path) -> InputInfo {
        InputInfo {
            path: path.to_path_buf(),
            bytes: size_of(path),
        }
    }
}

/// Bytes of a file, or of the files under a directory.
fn size_of(path: &Path) -> u64 {
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => std::fs::read_dir(path)
            .map(|rd| rd.flatten().map(|e| size_of(&e.path())).sum())
            .unwrap_or(0),
        Ok(m) => m.len(),
        Err(_) => 0,
    }
}

/// What a finished run gives its picture and report.
pub struct RunEnd<'a> {
    /// The subcommand.
    pub command: &'a str,
    /// The inputs as given (files, a store, a work directory).
    pub inputs: &'a [PathBuf],
    /// Input points, where the run counted them.
    pub points: Option<u64>,
    /// The options that shaped the result, as (name, value).
    pub options: Vec<(String, String)>,
    /// The output written.
    pub output: &'a Path,
    /// The run's statistics.
    pub result: serde_json::Value,
    /// Leaves holding points and refined leaves, where the run solved them.
    pub leaf_map: Option<LeafMap>,
    /// The picture drawn as the mesh was written.
    pub preview: Option<Preview>,
    /// The output's triangles; `None` where no mesh was written (a shard).
    pub triangles: Option<u64>,
    /// Wall time of the run.
    pub secs: f64,
}

/// What a run notes at its start for its picture and report.
pub struct RunStart {
    outputs: RunOutputs,
    started: String,
    timeline: Option<MemoryTimeline>,
}

impl RunStart {
    /// Note the time, and start sampling memory when a report is asked for.
    pub fn now(outputs: &RunOutputs) -> RunStart {
        RunStart {
            outputs: outputs.clone(),
            started: timestamp(SystemTime::now()),
            timeline: outputs.report.is_some().then(MemoryTimeline::start),
        }
    }

    /// Write the picture and the report asked for, of the run `end` describes (the report
    /// checks the output when `end.triangles` is given and fits the budget).
    pub fn finish(self, ctx: &Ctx, end: RunEnd) -> Result<()> {
        let RunEnd {
            command,
            inputs,
            points,
            options,
            output,
            result,
            leaf_map,
            preview,
            triangles,
            secs,
        } = end;
        let memory = self.timeline.map(MemoryTimeline::stop).unwrap_or_default();
        if let (Some(path), Some(p)) = (&self.outputs.preview, &preview) {
            p.write_png(path)?;
            log::info!("wrote the preview {}", path.display());
        }
        let Some(path) = &self.outputs.report else {
            return Ok(());
        };
        let mut r = RunReport {
            scanflow: format!("scanflow {}", env!("CARGO_PKG_VERSION")),
            command: command.to_string(),
            argv: std::env::args().collect(),
            started: self.started,
            secs,
            inputs: inputs.iter().map(|p| InputInfo::of(p)).collect(),
            points,
            options,
            output: output.to_path_buf(),
            result,
            stages: ctx.progress.records(),
            mem_budget: ctx.budget.total(),
            peak_rss_bytes: scanflow::exec::peak_rss_bytes(),
            memory,
            leaf_map,
            check: serde_json::Value::Null,
            preview,
        };
        match triangles {
            Some(t) => r.check_output(t),
            None => {
                r.check = serde_json::json!({"skipped": "a shard writes no mesh: merge does"});
            }
        }
        r.write(path)?;
        log::info!("wrote the report {}", path.display());
        Ok(())
    }
}

/// The options of `reconstruct` that shape its result, as the report lists them.
pub fn recon_options(c: &ReconstructConfig) -> Vec<(String, String)> {
    let p = &c.params;
    let mut o = vec![
        ("--depth", p.solve.depth.to_string()),
        ("--point-weight", p.solve.point_weight.to_string()),
        ("--smooth", p.solve.smoothing.to_string()),
        ("--error", p.solve.error.to_string()),
        ("--min-points", p.solve.min_points.to_string()),
        ("--trim", p.mesh.trim.to_string()),
        ("--no-fit", (!p.mesh.fit).to_string()),
        ("--density", p.mesh.density.to_string()),
        ("--confidence", p.solve.confidence.to_string()),
        (
            "--samples-per-node",
            p.solve
                .samples_per_node
                .map_or("none".to_string(), |s| s.to_string()),
        ),
        (
            "--trim-density",
            p.mesh
                .trim_density
                .map_or("none".to_string(), |d| d.to_string()),
        ),
        (
            "--tile",
            p.run
                .tile_voxels
                .map_or("64 (default)".to_string(), |t| t.to_string()),
        ),
        ("--gpu", format!("{:?}", p.run.gpu).to_lowercase()),
        (
            "--gpu-solve",
            format!("{:?}", p.run.gpu_solve).to_lowercase(),
        ),
        ("--shard", p.run.shard.to_string()),
        ("format", c.mesh.format.name().to_string()),
        ("--out-normals", c.mesh.normals.to_string()),
        (
            "--trim-islands",
            c.mesh.islands.map_or("none".to_string(), |r| r.to_string()),
        ),
        (
            "--threads",
            match c.run.threads {
                0 => "one per core".to_string(),
                n => n.to_string(),
            },
        ),
        ("--mem", human_bytes(c.run.mem_bytes)),
    ];
    o.retain(|(k, _)| *k != "--shard" || p.run.shard.is_split());
    o.into_iter().map(|(k, v)| (k.to_string(), v)).collect()
}

/// Everything a report shows.
#[derive(Debug, Serialize)]
pub struct RunReport {
    /// `scanflow` and its version.
    pub scanflow: String,
    /// The command (`reconstruct`, `merge`).
    pub command: String,
    /// The command line as given.
    pub argv: Vec<String>,
    /// When the run started (ISO 8601, UTC).
    pub started: String,
    /// Wall time of the whole command, in seconds.
    pub secs: f64,
    /// What it read.
    pub inputs: Vec<InputInfo>,
    /// Input points, where known.
    pub points: Option<u64>,
    /// The options that shape the result, as name → value.
    pub options: Vec<(String, String)>,
    /// The mesh written.
    pub output: PathBuf,
    /// The command's own statistics.
    pub result: serde_json::Value,
    /// Every stage, in order of finishing.
    pub stages: Vec<StageRecord>,
    /// The memory budget (`--mem`), in bytes.
    pub mem_budget: u64,
    /// The process's peak resident memory, in bytes.
    pub peak_rss_bytes: u64,
    /// Resident memory over time: (seconds since the start, bytes).
    pub memory: Vec<(f64, u64)>,
    /// The leaves from above, for reconstruct.
    pub leaf_map: Option<LeafMap>,
    /// The output's `check` summary, or why it was not made.
    pub check: serde_json::Value,
    /// The picture (embedded in HTML; written by `--preview`).
    #[serde(skip)]
    pub preview: Option<Preview>,
}

impl RunReport {
    /// Check the output mesh when that fits in `mem_budget`, and record it.
    pub fn check_output(&mut self, triangles: u64) {
        if triangles.saturating_mul(CHECK_BYTES_PER_TRIANGLE) > self.mem_budget {
            self.check = serde_json::json!({
                "skipped": format!(
                    "{triangles} triangles: checking them needs about {}, more than --mem {}; run scanflow check on the output",
                    human_bytes(triangles * CHECK_BYTES_PER_TRIANGLE),
                    human_bytes(self.mem_budget)
                )
            });
            return;
        }
        self.check = match scanflow::io::mesh_read::read_any_mesh(&self.output) {
            Ok(m) => serde_json::to_value(scanflow::metrics::check_mesh(&m))
                .unwrap_or(serde_json::Value::Null),
            Err(e) => serde_json::json!({ "skipped": e.to_string() }),
        };
    }

    /// Write the report to `path`: HTML or JSON by its extension.
    pub fn write(&self, path: &Path) -> Result<()> {
        let html = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("html"));
        let text = if html {
            self.html()
        } else {
            let mut v = serde_json::to_string_pretty(self)?;
            v.push('\n');
            v
        };
        atomic::write(path, text.as_bytes(), Durability::Synced)?;
        Ok(())
    }

    /// The HTML page.
    pub fn html(&self) -> String {
        let mut h = String::new();
        let title = format!("scanflow {} → {}", self.command, self.output.display());
        let _ = write!(
            h,
            "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title>\n<style>{CSS}</style></head><body>\n<h1>{}</h1>\n",
            esc(&title),
            esc(&title)
        );
        let _ = write!(
            h,
            "<p class=\"meta\">{} · started {} · {:.2} s · peak memory {} of --mem {}</p>\n<pre class=\"cmd\">{}</pre>\n",
            esc(&self.scanflow),
            esc(&self.started),
            self.secs,
            human_bytes(self.peak_rss_bytes),
            human_bytes(self.mem_budget),
            esc(&self.argv.join(" "))
        );
        if let Some(p) = &self.preview {
            let b64 = base64::engine::general_purpose::STANDARD.encode(p.png());
            let _ = write!(
                h,
                "<h2>Preview</h2>\n<img class=\"preview\" alt=\"front, side and isometric views of the mesh\" src=\"data:image/png;base64,{b64}\">\n"
            );
        }
        h.push_str("<h2>Inputs</h2>\n<table><tr><th>path</th><th>size</th></tr>\n");
        for i in &self.inputs {
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td>{}</td></tr>",
                esc(&i.path.display().to_string()),
                human_bytes(i.bytes)
            );
        }
        if let Some(n) = self.points {
            let _ = writeln!(h, "<tr><td>points</td><td>{n}</td></tr>");
        }
        h.push_str("</table>\n<h2>Options</h2>\n<table>\n");
        for (k, v) in &self.options {
            let _ = writeln!(h, "<tr><td>{}</td><td>{}</td></tr>", esc(k), esc(v));
        }
        h.push_str("</table>\n<h2>Stages</h2>\n");
        h.push_str(&self.stages_table());
        h.push_str("<h2>Memory</h2>\n");
        h.push_str(&self.memory_svg());
        if let Some(m) = &self.leaf_map
            && m.n > 0
        {
            h.push_str("<h2>Leaves from above</h2>\n");
            h.push_str(&leaf_map_svg(m));
        }
        h.push_str("<h2>Output check</h2>\n<table>\n");
        if let serde_json::Value::Object(o) = &self.check {
            for (k, v) in o {
                let _ = writeln!(h, "<tr><td>{}</td><td>{}</td></tr>", esc(k), esc(&plain(v)));
            }
        }
        h.push_str("</table>\n<h2>Result</h2>\n<table>\n");
        if let serde_json::Value::Object(o) = &self.result {
            for (k, v) in o.iter().filter(|(k, _)| *k != "leaf_map") {
                let _ = writeln!(h, "<tr><td>{}</td><td>{}</td></tr>", esc(k), esc(&plain(v)));
            }
        }
        h.push_str("</table>\n</body></html>\n");
        h
    }

    /// The stages as a table with a bar of each one's share of the run.
    fn stages_table(&self) -> String {
        let total = self.secs.max(1e-9);
        let mut h = String::from(
            "<table><tr><th>stage</th><th>done</th><th>seconds</th><th>share</th><th>peak memory after</th></tr>\n",
        );
        for s in &self.stages {
            let share = (100.0 * s.secs / total).clamp(0.0, 100.0);
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td>{} {}</td><td>{:.2}</td><td><div class=\"bar\" style=\"width:{:.1}%\"></div></td><td>{}</td></tr>",
                esc(&s.name),
                s.done,
                esc(&s.unit),
                s.secs,
                share,
                human_bytes(s.peak_rss_bytes)
            );
        }
        h.push_str("</table>\n");
        h
    }

    /// Resident memory over time, with the budget as a line.
    fn memory_svg(&self) -> String {
        let (w, hgt) = (800.0, 200.0);
        let t_max = self
            .memory
            .iter()
            .map(|s| s.0)
            .fold(self.secs, f64::max)
            .max(1e-9);
        // The budget sets the scale unless it dwarfs what was used (a default --mem of
        // most of the machine): then the peak does, and the budget is named above.
        let used = self
            .memory
            .iter()
            .map(|s| s.1)
            .max()
            .unwrap_or(0)
            .max(self.peak_rss_bytes)
            .max(1);
        let budget_shown = self.mem_budget <= 4 * used;
        let top = if budget_shown {
            used.max(self.mem_budget) as f64
        } else {
            1.15 * used as f64
        };
        let x = |t: f64| 40.0 + (w - 50.0) * t / t_max;
        let y = |b: f64| hgt - 20.0 - (hgt - 30.0) * b / top;
        let mut pts = String::new();
        for (t, b) in &self.memory {
            let _ = write!(pts, "{:.1},{:.1} ", x(*t), y(*b as f64));
        }
        format!(
            "<svg class=\"chart\" width=\"{w}\" height=\"{hgt}\" viewBox=\"0 0 {w} {hgt}\" xmlns=\"http://www.w3.org/2000/svg\" role=\"img\" aria-label=\"resident memory over time\">\
{budget_line}\
<polyline points=\"{pts}\" class=\"rss\"/>\
<text x=\"40\" y=\"{yl}\">0 s</text><text x=\"{xe:.1}\" y=\"{yl}\" text-anchor=\"end\">{t_max:.1} s</text>\
<text x=\"2\" y=\"{yp:.1}\">{peak}</text></svg>\n",
            budget_line = if budget_shown {
                format!(
                    "<line x1=\"40\" y1=\"{yb:.1}\" x2=\"{xe:.1}\" y2=\"{yb:.1}\" class=\"budget\"/><text x=\"42\" y=\"{ybt:.1}\">--mem {budget}</text>",
                    yb = y(self.mem_budget as f64),
                    ybt = y(self.mem_budget as f64) - 4.0,
                    xe = w - 10.0,
                    budget = human_bytes(self.mem_budget)
                )
            } else {
                format!(
                    "<text x=\"42\" y=\"12\">--mem {} (above the chart)</text>",
                    human_bytes(self.mem_budget)
                )
            },
            xe = w - 10.0,
            yl = hgt - 4.0,
            yp = y(self.peak_rss_bytes as f64) + 4.0,
            peak = human_bytes(self.peak_rss_bytes),
        )
    }
}

/// The leaf map as a grid of squares: grey where leaves hold points, coloured by the share
/// refined.
fn leaf_map_svg(m: &LeafMap) -> String {
    let n = m.n as usize;
    let cell = (480 / n.max(1)).clamp(2, 24);
    let side = cell * n;
    let mut h = format!(
        "<svg class=\"map\" width=\"{side}\" height=\"{side}\" viewBox=\"0 0 {side} {side}\" xmlns=\"http://www.w3.org/2000/svg\" role=\"img\" aria-label=\"leaves from above: refined share per column\">"
    );
    for y in 0..n {
        for x in 0..n {
            let i = y * n + x;
            let (o, r) = (m.occupied[i], m.refined[i]);
            if o == 0 {
                continue;
            }
            let share = r as f64 / o as f64;
            let fill = format!(
                "rgb({},{},{})",
                (200.0 - 150.0 * share) as u8,
                (200.0 - 60.0 * share) as u8,
                (200.0 + 40.0 * share) as u8
            );
            // y grows upward in the scan, downward on the page.
            let _ = write!(
                h,
                "<rect x=\"{}\" y=\"{}\" width=\"{cell}\" height=\"{cell}\" fill=\"{fill}\"><title>({x}, {y}): {r} of {o} refined</title></rect>",
                x * cell,
                (n - 1 - y) * cell
            );
        }
    }
    h.push_str("</svg>\n<p class=\"meta\">Grey: leaves holding points; blue: refined by a fine solve (the share of the column's leaves).</p>\n");
    h
}

/// A JSON value as plain text: strings without quotes.
fn plain(v: &serde_json::Value) -> String {
    match v {
        serde_json::Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// Text escaped for HTML.
fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            c => o.push(c),
        }
    }
    o
}

const CSS: &str = "body{font-family:system-ui,sans-serif;margin:2em;color:#222;max-width:1300px}\
h1{font-size:1.4em}h2{font-size:1.1em;margin-top:1.5em}\
table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:2px 8px;text-align:left;font-size:0.9em}\
.meta{color:#555}.cmd{background:#f4f4f4;padding:0.5em;white-space:pre-wrap}\
.bar{background:#4a7fd0;height:0.8em;min-width:1px}.preview{max-width:100%;border:1px solid #ccc}\
.chart .rss{fill:none;stroke:#4a7fd0;stroke-width:2}.chart .budget{stroke:#c33;stroke-dasharray:4}\
.chart text{font-size:11px;fill:#555}";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn html_escapes_and_embeds_the_picture() {
        let b = scanflow::types::Aabb {
            min: [0.0; 3],
            max: [1.0; 3],
        };
        let mut p = Preview::new(&b, 16);
        p.triangle([[0.0; 3], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], None);
        let r = RunReport {
            scanflow: "scanflow 0".into(),
            command: "reconstruct".into(),
            argv: vec!["scanflow".into(), "<a&b>".into()],
            started: "2026-01-01T00:00:00.000Z".into(),
            secs: 2.0,
            inputs: vec![],
            points: Some(5),
            options: vec![("--depth".into(), "9".into())],
            output: PathBuf::from("m.ply"),
            result: serde_json::json!({"vertices": 3}),
            stages: vec![],
            mem_budget: 1 << 30,
            peak_rss_bytes: 1 << 20,
            memory: vec![(0.0, 1 << 20), (2.0, 1 << 21)],
            leaf_map: Some(LeafMap {
                n: 2,
                occupied: vec![1, 0, 2, 1],
                refined: vec![1, 0, 1, 0],
            }),
            check: serde_json::json!({"watertight": true}),
            preview: Some(p),
        };
        let h = r.html();
        assert!(h.contains("&lt;a&amp;b&gt;") && !h.contains("<a&b>"));
        assert!(h.contains("data:image/png;base64,iVBOR"));
        assert_eq!(h.matches("<rect").count(), 3);
        assert!(h.contains("1 of 2 refined"));
        assert!(!h.contains("<script"));
        let j = serde_json::to_value(&r).unwrap();
        assert_eq!(j["memory"][1][1], 1 << 21);
        assert!(j.get("preview").is_none());
    }
}
