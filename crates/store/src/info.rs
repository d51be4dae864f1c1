//! `info` on a point file: one parallel read that measures its bounds and invalid points
//! and, for LAS and LAZ, the classes and returns present beside the header's metadata and CRS
//! ([`crate::io::las_meta`]).

use std::collections::BTreeMap;
use std::path::Path;

use rayon::prelude::*;

use crate::cell_file::batch_bounds;
use crate::error::Result;
use crate::exec::Ctx;
use crate::io::las_meta::{Crs, LasMeta, LasTally};
use crate::types::{Aabb, PointBatch};
use crate::{CHUNK_BYTES_PER_POINT, MAX_CHUNK_POINTS};

/// What `info` reports about a point file.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FileInfo {
    /// Path.
    pub path: String,
    /// Format.
    pub format: crate::io::Format,
    /// Points (records).
    pub points: u64,
    /// Attributes carried.
    pub attributes: Vec<&'static str>,
    /// Bounds of the points (NaN points excluded).
    pub bounds: Aabb,
    /// Points with a non-finite coordinate.
    pub invalid_points: u64,
    /// LAS and LAZ: the header's metadata and CRS, the classes and returns present, and
    /// warnings where the CRS contradicts the coordinates.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub las: Option<LasInfo>,
    /// E57: the header, every scan's pose and sensor, and warnings where the CRS contradicts
    /// the coordinates.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub e57: Option<crate::io::e57::E57Meta>,
}

/// What `info` adds for a LAS or LAZ file.
#[derive(Debug, Clone, serde::Serialize)]
pub struct LasInfo {
    /// Header metadata and CRS.
    #[serde(flatten)]
    pub meta: LasMeta,
    /// Points per classification value present.
    pub classes: BTreeMap<u8, u64>,
    /// Points per return number present.
    pub returns: BTreeMap<u8, u64>,
    /// Where the CRS contradicts the coordinates.
    pub warnings: Vec<String>,
}

/// Read a file once to describe it.
pub fn file_info(path: &Path, ctx: &Ctx) -> Result<FileInfo> {
    let r = crate::io::open(path)?;
    let chunks = r.chunks(MAX_CHUNK_POINTS)?;
    let stage = ctx.progress.stage("scan", Some(r.len()), "points");
    let res: Vec<Result<(Aabb, u64, Option<LasTally>)>> = ctx.pool.install(|| {
        chunks
            .par_iter()
            .map_init(PointBatch::default, |b, spec| {
                let _p = ctx
                    .budget
                    .acquire(spec.count * CHUNK_BYTES_PER_POINT, "a chunk of points")?;
                b.clear();
                let (st, tally) = r.read_chunk_tally(spec, true, b)?;
                stage.inc(spec.count);
                Ok((batch_bounds(b), st.skipped_invalid, tally))
            })
            .collect()
    });
    stage.finish(None);
    let mut bounds = Aabb::EMPTY;
    let mut invalid = 0;
    let mut tally: Option<LasTally> = None;
    for x in res {
        let (b, s, t) = x?;
        bounds = bounds.union(&b);
        invalid += s;
        if let Some(t) = t {
            tally.get_or_insert_with(LasTally::default).merge(&t);
        }
    }
    let las = r.las_meta().map(|meta| {
        let t = tally.unwrap_or_default();
        LasInfo {
            meta: meta.clone(),
            classes: t.classes_present(),
            returns: t.returns_present(),
            warnings: meta.warnings(bounds.min, bounds.max),
        }
    });
    Ok(FileInfo {
        path: path.display().to_string(),
        format: r.format(),
        points: r.len(),
        attributes: r.attributes().names(),
        bounds,
        invalid_points: invalid,
        las,
        e57: match r.format() {
            crate::io::Format::E57 => {
                let mut m = crate::io::e57::file_meta(path)?;
                if let Some(t) = &m.crs {
                    m.warnings = Crs::from_text(t).warnings(bounds.min, bounds.max);
                }
                Some(m)
            }
            _ => None,
        },
    })
}
