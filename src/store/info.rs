//! `info` on a point file: one parallel read that measures its bounds and invalid points.

use std::path::Path;

use rayon::prelude::*;

use crate::error::Result;
use crate::exec::Ctx;
use crate::store::cell_file::batch_bounds;
use crate::store::{CHUNK_BYTES_PER_POINT, MAX_CHUNK_POINTS};
use crate::types::{Aabb, PointBatch};

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
}

/// Read a file once to describe it.
pub fn file_info(path: &Path, ctx: &Ctx) -> Result<FileInfo> {
    let r = crate::io::open(path)?;
    let chunks = r.chunks(MAX_CHUNK_POINTS)?;
    let stage = ctx.progress.stage("scan", Some(r.len()), "points");
    let res: Vec<Result<(Aabb, u64)>> = ctx.pool.install(|| {
        chunks
            .par_iter()
            .map_init(PointBatch::default, |b, spec| {
                let _p = ctx
                    .budget
                    .acquire(spec.count * CHUNK_BYTES_PER_POINT, "a chunk of points")?;
                b.clear();
                let st = r.read_chunk(spec, true, b)?;
                stage.inc(spec.count);
                Ok((batch_bounds(b), st.skipped_invalid))
            })
            .collect()
    });
    stage.finish(None);
    let mut bounds = Aabb::EMPTY;
    let mut invalid = 0;
    for x in res {
        let (b, s) = x?;
        bounds = bounds.union(&b);
        invalid += s;
    }
    Ok(FileInfo {
        path: path.display().to_string(),
        format: r.format(),
        points: r.len(),
        attributes: r.attributes().names(),
        bounds,
        invalid_points: invalid,
    })
}
