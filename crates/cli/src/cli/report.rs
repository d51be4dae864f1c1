//! What the commands print on stdout: one summary line per finished job, and the text or
//! JSON of `info` and `check`. Nothing else goes to stdout.

use std::path::Path;

use anyhow::Result;

use scanflow::exec::{human_bytes, peak_rss_bytes};
use scanflow::io::las_meta::class_name;
use scanflow::metrics::CheckReport;
use scanflow::pipeline::shard::Shard;
use scanflow::pipeline::{MergeStats, ReconStats};
use scanflow::store::verify::VerifyReport;
use scanflow::store::{FileInfo, IngestStats, LasInfo, Store};
use scanflow::synth::{Shape, SynthReport};
use scanflow::types::Aabb;

use super::info::StoreSummary;

/// Width, in `#`, of the longest bar of the cell-size histogram.
const HISTOGRAM_WIDTH: usize = 40;

/// `synth`'s line.
pub fn synth(r: &SynthReport, shape: Shape, out: &Path) {
    outln!(
        "wrote {} points of {} to {} in {:.2} s",
        r.points,
        shape,
        out.display(),
        r.secs
    );
}

/// `ingest`'s lines: the normal estimation when it ran, then the store.
pub fn ingest(st: &IngestStats, out: &Path) {
    if let Some((n, secs)) = &st.normals {
        outln!(
            "estimated normals for {} points in {:.2} s ({:.2} M points/s; k = {}..{}, {} by viewpoint, {} by propagation, {} degenerate, {} components)",
            st.points,
            secs,
            st.points as f64 / secs / 1e6,
            n.k,
            n.k_max,
            n.by_viewpoint,
            n.by_propagation,
            n.degenerate,
            n.components
        );
    }
    outln!(
        "ingested {} points ({} skipped as invalid) into {} cells of {} in {:.2} s: {:.2} M points/s, store {}, peak memory {}",
        st.points,
        st.skipped_invalid,
        st.cells,
        out.display(),
        st.secs,
        st.points as f64 / st.secs / 1e6,
        human_bytes(st.store_bytes),
        human_bytes(peak_rss_bytes())
    );
}

/// `reconstruct`'s line: the whole run's time `total_secs` (ingest and normal estimation
/// included, where the inputs were point files), then the solve and mesh's own.
pub fn reconstruct(st: &ReconStats, out: &Path, total_secs: f64) {
    let pairs = st
        .pair_noise_voxels
        .map_or_else(String::new, |p| format!(", {p:.3} between close samples"));
    let noise = match (st.noise_voxels, st.jet_noise_voxels) {
        (Some(s), Some(j)) => {
            format!(" (noise {s:.3} voxel within a voxel{pairs}, {j:.3} about local quadrics)")
        }
        (Some(s), None) => format!(" (noise {s:.3} voxel)"),
        _ => String::new(),
    };
    let screened = if st.point_weight > 0.0 && st.leaves_solved > 0 {
        format!(
            ", screened with --point-weight {}{noise}: {:.1} CG iterations a leaf",
            short(st.point_weight),
            st.leaf_iterations as f64 / st.leaves_solved as f64
        )
    } else if st.leaves_solved > 0 && !noise.is_empty() {
        // Where the noise outweighs the relief (`recon::screen::relief_weight`).
        format!(", unscreened{noise}")
    } else {
        String::new()
    };
    // Where the samples lie farther apart than a voxel, how far (the Gaussian widens to 0.4
    // of it, `recon::screen::sparse_floor_voxels`).
    let spacing = match st.sample_spacing_voxels {
        Some(s) if s > 1.0 => format!(" (the samples {s:.2} voxels apart)"),
        _ => String::new(),
    };
    // The levels above the finest, top first: "over 812 leaves (640 refined) at depth 9".
    let above: String = st
        .levels_above
        .iter()
        .map(|l| {
            let summed = if l.points_summed > 0 {
                format!(
                    ", {:.0}% of its reads summed in {} voxels",
                    100.0 * l.points_summed as f64 / l.points_read as f64,
                    l.voxel_sums
                )
            } else {
                String::new()
            };
            format!(
                " over {} leaves ({} refined{summed}) at depth {}",
                l.leaves, l.refined, l.depth
            )
        })
        .rev()
        .collect::<Vec<_>>()
        .join(",");
    outln!(
        "reconstructed {} vertices, {} triangles into {} in {:.2} s (solve and mesh {:.2} s; {} leaves, {} refined{above}{screened}; normals smoothed over {} voxel{spacing}; iso-value of the field {:.4}), peak memory {}",
        st.vertices,
        st.faces,
        out.display(),
        total_secs,
        st.secs,
        st.leaves,
        st.leaves_refined,
        short(st.smooth_voxels),
        st.iso,
        human_bytes(peak_rss_bytes())
    );
}

/// A shard's summary: its share of the leaves and tiles, and what comes next.
pub fn shard(st: &ReconStats, shard: Shard, work: &Path, out: &Path, total_secs: f64) {
    outln!(
        "shard {shard}: {} of {} leaves and {} of {} tiles done here (the others by other shards, or before a requeue), in {:.2} s, peak memory {}; once every shard has finished: scanflow merge {} -o {}",
        st.leaves - st.leaves_reused,
        st.leaves,
        st.tiles,
        st.tiles_total,
        total_secs,
        human_bytes(peak_rss_bytes()),
        work.display(),
        out.display()
    );
}

/// `merge`'s summary.
pub fn merge(st: &MergeStats, out: &Path) {
    outln!(
        "merged {} tiles: {} vertices, {} triangles into {} in {:.2} s, peak memory {}",
        st.tiles,
        st.vertices,
        st.faces,
        out.display(),
        st.secs,
        human_bytes(peak_rss_bytes())
    );
}

/// `x` as written where it is whole, else to 2 decimals.
fn short(x: f64) -> String {
    if x.fract() == 0.0 {
        format!("{x}")
    } else {
        format!("{x:.2}")
    }
}

/// `check`'s report, as text or one JSON line.
pub fn check(rep: &CheckReport, json: bool) -> Result<()> {
    if json {
        outln!("{}", serde_json::to_string(rep)?);
    } else {
        outln!("{rep}");
    }
    Ok(())
}

/// `demo`'s first line: the synthesised scan.
pub fn demo_synth(r: &SynthReport, noise: f64) {
    outln!(
        "synthesised {} points of a bumpy sphere (noise {noise}) in {:.2} s",
        r.points,
        r.secs
    );
}

/// `demo`'s last lines: the mesh, its check, the whole run.
pub fn demo_done(mesh: &Path, depth: u32, st: &ReconStats, check: &CheckReport, secs: f64) {
    outln!(
        "reconstructed {} at depth {depth} in {:.2} s: {} vertices, {} triangles",
        mesh.display(),
        st.secs,
        st.vertices,
        st.faces
    );
    outln!("{check}");
    outln!(
        "demo done in {:.2} s, peak memory {}",
        secs,
        human_bytes(peak_rss_bytes())
    );
}

/// `info` on a store: its manifest and the cells' levels and sizes.
pub fn store(
    path: &Path,
    store: &Store,
    s: &StoreSummary,
    verified: Option<&VerifyReport>,
    json: bool,
) -> Result<()> {
    let m = &store.manifest;
    if json {
        let v = serde_json::json!({
            "kind": "store",
            "path": path.display().to_string(),
            "points": m.point_count,
            "skipped_invalid": m.skipped_invalid,
            "attributes": m.attributes.names(),
            "bounds": m.bounds,
            "cells": m.cells.len(),
            "store_bytes": s.bytes,
            "cells_by_level": s.levels,
            "cell_size_histogram": s.size_bits.iter().map(|(b, n)| {
                let (lo, hi) = StoreSummary::bin_range(*b);
                serde_json::json!({"min_points": lo, "max_points": hi, "cells": n})
            }).collect::<Vec<_>>(),
            "inputs": m.inputs,
            "verified": verified,
        });
        outln!("{v}");
        return Ok(());
    }
    outln!("store       {}", path.display());
    outln!("points      {}", m.point_count);
    if m.skipped_invalid > 0 {
        outln!("skipped     {} invalid points", m.skipped_invalid);
    }
    outln!("attributes  {}", m.attributes.names().join(" "));
    bounds(&m.bounds);
    outln!("inputs      {}", m.inputs.len());
    outln!(
        "cells       {} ({}, {:.2} bytes/point)",
        m.cells.len(),
        human_bytes(s.bytes),
        s.bytes as f64 / m.point_count.max(1) as f64
    );
    let levels: Vec<String> = s.levels.iter().map(|(l, n)| format!("L{l}:{n}")).collect();
    outln!("levels      {}", levels.join(" "));
    outln!("cell sizes (points per cell):");
    let most = s.size_bits.values().copied().max().unwrap_or(1);
    for (b, n) in &s.size_bits {
        let (lo, hi) = StoreSummary::bin_range(*b);
        let bar = "#".repeat((n * HISTOGRAM_WIDTH).div_ceil(most));
        outln!("  {:>10} .. {:<10} {:>6} {}", lo, hi, n, bar);
    }
    if let Some(v) = verified {
        outln!(
            "verified    {} cells read, {} points, {}: record counts and CRC-32s match",
            v.cells,
            v.points,
            human_bytes(v.bytes)
        );
    }
    Ok(())
}

/// `info` on a point file.
pub fn file(fi: &FileInfo, json: bool) -> Result<()> {
    if json {
        outln!("{}", serde_json::to_string(fi)?);
        return Ok(());
    }
    outln!("file        {}", fi.path);
    outln!("format      {}", fi.format.name());
    outln!("points      {}", fi.points);
    outln!("attributes  {}", fi.attributes.join(" "));
    bounds(&fi.bounds);
    if fi.invalid_points > 0 {
        outln!(
            "invalid     {} points with NaN/infinite coordinates",
            fi.invalid_points
        );
    }
    if let Some(l) = &fi.las {
        las(l);
    }
    if let Some(e) = &fi.e57 {
        e57(e);
    }
    Ok(())
}

/// The E57 lines of `info` on a file: version, CRS, and each scan's pose and sensor.
fn e57(e: &scanflow::io::e57::E57Meta) {
    outln!(
        "e57         version {}, guid {}{}",
        e.version,
        e.guid,
        e.library
            .as_ref()
            .map(|l| format!(", written by {l}"))
            .unwrap_or_default()
    );
    outln!(
        "crs         {}",
        e.crs.as_deref().unwrap_or("(none recorded)")
    );
    for (i, s) in e.scans.iter().enumerate() {
        let [w, x, y, z] = s.rotation;
        outln!(
            "scan {i:<6} {}{} points, {}{}{}; scanner at ({}, {}, {}), rotation (w x y z) {w} {x} {y} {z}{}",
            s.name
                .as_ref()
                .map(|n| format!("{n}: "))
                .unwrap_or_default(),
            s.points,
            s.coordinates,
            if s.color { ", colour" } else { "" },
            if s.intensity { ", intensity" } else { "" },
            s.position[0],
            s.position[1],
            s.position[2],
            s.sensor
                .as_ref()
                .map(|v| format!("; sensor {v}"))
                .unwrap_or_default()
        );
    }
    for w in &e.warnings {
        outln!("warning     {w}");
    }
}

/// The LAS lines of `info` on a file: header, CRS, classes and returns, warnings.
fn las(l: &LasInfo) {
    let m = &l.meta;
    outln!(
        "las         version {}, point format {}{}",
        m.version,
        m.point_format,
        if m.compressed {
            ", LASzip-compressed"
        } else {
            ""
        }
    );
    outln!("scale       {} {} {}", m.scale[0], m.scale[1], m.scale[2]);
    outln!(
        "offset      {} {} {}",
        m.offset[0],
        m.offset[1],
        m.offset[2]
    );
    let date = m
        .creation_date
        .as_ref()
        .map(|d| format!(", created {d}"))
        .unwrap_or_default();
    outln!(
        "software    {:?} (system {:?}){date}",
        m.generating_software,
        m.system_identifier
    );
    outln!("crs         {}", m.crs.summary());
    let classes: Vec<String> = l
        .classes
        .iter()
        .map(|(c, n)| match class_name(*c) {
            Some(name) => format!("{c} {name}: {n}"),
            None => format!("{c}: {n}"),
        })
        .collect();
    outln!("classes     {}", classes.join(", "));
    let returns: Vec<String> = l.returns.iter().map(|(r, n)| format!("{r}: {n}")).collect();
    outln!("returns     {}", returns.join(", "));
    for w in &l.warnings {
        outln!("warning     {w}");
    }
}

/// The `bounds` line of `info`.
fn bounds(b: &Aabb) {
    outln!(
        "bounds      [{:.6}, {:.6}, {:.6}] .. [{:.6}, {:.6}, {:.6}]",
        b.min[0],
        b.min[1],
        b.min[2],
        b.max[0],
        b.max[1],
        b.max[2]
    );
}
