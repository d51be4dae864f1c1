//! Checks of a committed store: what [`Store::open`](super::Store::open) refuses, and the
//! full read of `info --verify`.
//!
//! A store is trusted only as far as it is checked, since a manifest is a file a user (or a
//! damaged disk) can change. Opening a store checks, without reading a cell:
//!
//! * **the manifest** ([`check_manifest`]): zstd compression and the record fields its
//!   attributes make; every cell listed once (keys and file names
//!   unique, in strictly increasing key order); each key a valid octree key whose level and
//!   coordinates are the entry's; each file name exactly the one ingest gives the key
//!   (`<key in hex>.zst`), so no entry can name a path outside the store's `cells/`
//!   directory (`../../etc/passwd`, an absolute path); every cell non-empty, with no more
//!   points than its file could decompress to (zstd expands a byte to at most 2^17); the
//!   cells' counts summing to `point_count`, and the inputs' points to `point_count` plus
//!   `skipped_invalid`;
//! * **the files** ([`check_cell_files`]): `cells/` a directory and every cell file a regular
//!   file (not a symbolic link, which could lead out of the store) of the manifest's size.
//!
//! [`verify_cells`] reads every cell: it decompresses the file, counts whole records against
//! the manifest's count, and compares the CRC-32 of its compressed bytes with the manifest's.
//! A truncated, deleted or corrupt cell is reported naming the store and the cell.

use std::collections::HashMap;
use std::path::Path;

use rayon::prelude::*;

use crate::cell_file::CellReader;
use crate::error::{Error, Result};
use crate::exec::Ctx;
use crate::manifest::{MANIFEST, Manifest, record_fields};
use crate::types::keys::MAX_LEVEL;
use crate::types::{CellKey, PointBatch};
use crate::{CELLS_DIR, Store};

/// Most bytes a cell file's one byte can decompress to (see [`check_manifest`]).
const MAX_ZSTD_RATIO: u64 = 1 << 17;

/// Records decoded at a time while verifying a cell: 64 Ki records, a few MiB of buffer.
const VERIFY_RECORDS: usize = 1 << 16;

/// An error about cell `i` of the manifest of the store at `dir`.
fn cell_err(dir: &Path, i: usize, file: &str, msg: impl std::fmt::Display) -> Error {
    Error::input(dir.join(MANIFEST), format!("cell {i} (\"{file}\"): {msg}"))
}

/// Why `key` is not the key of an octree cell scanflow can name, if it is not.
fn bad_key(key: CellKey) -> Option<String> {
    if key.0 == 0 {
        return Some("key 0 is not an octree key (it has no level bit)".into());
    }
    let bit = 63 - key.0.leading_zeros();
    if !bit.is_multiple_of(3) || bit / 3 > MAX_LEVEL {
        return Some(format!(
            "key {:#x} is not an octree key of level 0 to {MAX_LEVEL}",
            key.0
        ));
    }
    None
}

/// Check the manifest of the store at `dir` for what no ingest writes: see the module docs.
pub fn check_manifest(dir: &Path, m: &Manifest) -> Result<()> {
    let manifest = dir.join(MANIFEST);
    if m.compression != "zstd" {
        return Err(Error::input(
            &manifest,
            format!("compression \"{}\", expected \"zstd\"", m.compression),
        ));
    }
    let fields = record_fields(m.attributes, m.position_f32);
    if m.record_fields != fields {
        return Err(Error::input(
            &manifest,
            format!(
                "record_fields {:?} do not match the attributes, which make {fields:?}",
                m.record_fields
            ),
        ));
    }
    let mut keys: HashMap<CellKey, usize> = HashMap::with_capacity(m.cells.len());
    let mut files: HashMap<&str, usize> = HashMap::with_capacity(m.cells.len());
    let mut sum: u128 = 0;
    for (i, c) in m.cells.iter().enumerate() {
        let file = c.file.as_str();
        let escapes = Path::new(file).is_absolute()
            || file.contains(['/', '\\'])
            || file == ".."
            || file == "."
            || file.is_empty();
        if escapes {
            return Err(cell_err(
                dir,
                i,
                file,
                format!("the file is not a name inside the store's {CELLS_DIR}/ directory"),
            ));
        }
        if let Some(j) = files.insert(file, i) {
            return Err(cell_err(
                dir,
                i,
                file,
                format!("listed twice: cell {j} names the same file"),
            ));
        }
        if let Some(j) = keys.insert(c.key, i) {
            return Err(cell_err(
                dir,
                i,
                file,
                format!("listed twice: cell {j} has the same key {:#x}", c.key.0),
            ));
        }
        if let Some(why) = bad_key(c.key) {
            return Err(cell_err(dir, i, file, why));
        }
        let want = format!("{}.zst", c.key.file_name());
        if file != want {
            return Err(cell_err(
                dir,
                i,
                file,
                format!("the file of key {:#x} is \"{want}\"", c.key.0),
            ));
        }
        let (level, coords) = c.key.decode();
        if (level, coords) != (c.level, c.coords) {
            return Err(cell_err(
                dir,
                i,
                file,
                format!(
                    "level {} and coordinates {:?} do not match its key (level {level}, {coords:?})",
                    c.level, c.coords
                ),
            ));
        }
        if i > 0 && m.cells[i - 1].key >= c.key {
            return Err(cell_err(dir, i, file, "cells are not in key order"));
        }
        if c.count == 0 {
            return Err(cell_err(
                dir,
                i,
                file,
                "0 points (a store lists only non-empty cells)",
            ));
        }
        // A zstd block of 128 KiB of one repeated byte compresses to 4 bytes (2^15 times
        // smaller), so no cell file decompresses to more than 2^17 times its size.
        let most = c.bytes.saturating_mul(MAX_ZSTD_RATIO) / m.record_bytes.max(1) as u64;
        if c.count > most {
            return Err(cell_err(
                dir,
                i,
                file,
                format!(
                    "{} points cannot be in a cell file of {} bytes (at most {most})",
                    c.count, c.bytes
                ),
            ));
        }
        sum += u128::from(c.count);
    }
    if sum != u128::from(m.point_count) {
        return Err(Error::input(
            manifest,
            format!(
                "the cells hold {sum} points, but point_count is {}",
                m.point_count
            ),
        ));
    }
    let inputs: u128 = m.inputs.iter().map(|i| u128::from(i.points)).sum();
    let total = u128::from(m.point_count) + u128::from(m.skipped_invalid);
    if inputs != total {
        return Err(Error::input(
            manifest,
            format!(
                "the inputs hold {inputs} points, but point_count {} and skipped_invalid {} make {total}",
                m.point_count, m.skipped_invalid
            ),
        ));
    }
    Ok(())
}

/// Check that the store's `cells/` is a directory and that every cell file is a regular file
/// (not a symbolic link) of the manifest's size. Reads no cell.
pub fn check_cell_files(store: &Store) -> Result<()> {
    let cells = store.dir.join(CELLS_DIR);
    let meta = std::fs::symlink_metadata(&cells).map_err(|e| {
        Error::input(
            &store.dir,
            format!("not a complete scanflow store: {CELLS_DIR}/ cannot be read ({e})"),
        )
    })?;
    if !meta.is_dir() {
        return Err(Error::input(
            &cells,
            format!(
                "is {}, expected the store's directory of cell files",
                crate::io::file_kind(meta.file_type())
            ),
        ));
    }
    for (i, c) in store.manifest.cells.iter().enumerate() {
        let path = store.cell_path(i);
        let what = match std::fs::symlink_metadata(&path) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => "the file is missing".into(),
            Err(e) => format!("the file cannot be read ({e})"),
            Ok(m) if m.file_type().is_symlink() => {
                "the file is a symbolic link; a store's cells are plain files inside it".into()
            }
            Ok(m) if !m.is_file() => format!(
                "the file is {}, expected a cell file",
                crate::io::file_kind(m.file_type())
            ),
            Ok(m) if m.len() != c.bytes => format!(
                "the file has {} bytes, the manifest says {} (truncated or replaced)",
                m.len(),
                c.bytes
            ),
            Ok(_) => continue,
        };
        return Err(cell_err(&store.dir, i, &c.file, what));
    }
    Ok(())
}

/// Read cell `i` of `store` whole, in pieces: its record count and CRC-32 must be the
/// manifest's.
pub fn verify_cell(store: &Store, i: usize, batch: &mut PointBatch) -> Result<()> {
    let c = &store.manifest.cells[i];
    let path = store.cell_path(i);
    let mut rd = CellReader::open(&path, store.layout)?;
    let mut buf = Vec::new();
    loop {
        batch.clear();
        if rd.read(VERIFY_RECORDS, batch, &mut buf)? == 0 {
            break;
        }
        if rd.records_read() > c.count {
            break;
        }
    }
    let n = rd.records_read();
    if n != c.count {
        let holds = if n > c.count {
            "more".to_string()
        } else {
            n.to_string()
        };
        return Err(Error::input(
            &path,
            format!(
                "corrupt cell file: the manifest lists {} points, the file holds {holds}",
                c.count
            ),
        ));
    }
    let crc = rd.finish_crc();
    if crc != c.crc32 {
        return Err(Error::input(
            &path,
            format!(
                "corrupt cell file: CRC-32 {crc:08x}, the manifest says {:08x}",
                c.crc32
            ),
        ));
    }
    Ok(())
}

/// What [`verify_cells`] found.
#[derive(Debug, Clone, serde::Serialize)]
pub struct VerifyReport {
    /// Cells read.
    pub cells: usize,
    /// Records read.
    pub points: u64,
    /// Compressed bytes read.
    pub bytes: u64,
}

/// Read every cell of `store` on `ctx`'s pool, checking count and CRC-32 of each. Every bad
/// cell is logged; the error names the first (in key order) and how many there are.
pub fn verify_cells(store: &Store, ctx: &Ctx) -> Result<VerifyReport> {
    let cells = &store.manifest.cells;
    let stage = ctx
        .progress
        .stage("verify", Some(cells.len() as u64), "cells");
    let piece = (VERIFY_RECORDS * store.layout.stride) as u64;
    let res: Vec<Result<()>> = ctx.pool.install(|| {
        (0..cells.len())
            .into_par_iter()
            .map_init(PointBatch::default, |b, i| {
                // The decoded records and the read buffer.
                let _p = ctx.budget.acquire(2 * piece, "a piece of a cell")?;
                let r = verify_cell(store, i, b);
                stage.inc(1);
                r
            })
            .collect()
    });
    stage.finish(None);
    let bad: Vec<Error> = res.into_iter().filter_map(|r| r.err()).collect();
    if bad.len() > 1 {
        for e in &bad {
            log::error!("{e}");
        }
    }
    let mut bad = bad.into_iter();
    match (bad.next(), bad.len()) {
        (None, _) => Ok(VerifyReport {
            cells: cells.len(),
            points: store.manifest.point_count,
            bytes: cells.iter().map(|c| c.bytes).sum(),
        }),
        (Some(first), 0) => Err(first),
        (Some(first), more) => Err(Error::input(
            &store.dir,
            format!(
                "{} of {} cells failed verification; the first: {first}",
                more + 1,
                cells.len()
            ),
        )),
    }
}
