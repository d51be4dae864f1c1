//! `manifest.json`: what a store holds. Written last, so a store with a manifest is complete.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::fs::atomic::{self, Durability};
use crate::io::Format;
use crate::types::{Aabb, Attributes, CellKey, Cube, Rigid, Viewpoint};

/// The `format` field of every store manifest.
pub const STORE_FORMAT: &str = "scanflow-store";
/// The store layout version this build reads and writes.
pub const STORE_VERSION: u32 = 1;
/// File name of the manifest inside a store.
pub const MANIFEST: &str = "manifest.json";

/// The manifest of a store.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Always [`STORE_FORMAT`].
    pub format: String,
    /// Layout version ([`STORE_VERSION`]).
    pub version: u32,
    /// Points stored.
    pub point_count: u64,
    /// Points dropped for non-finite coordinates or normals that are not finite or are zero
    /// (`--skip-invalid`).
    pub skipped_invalid: u64,
    /// Attributes of every record.
    pub attributes: Attributes,
    /// Positions stored as f32 (every input coordinate was a float32), else f64.
    pub position_f32: bool,
    /// Bytes per record.
    pub record_bytes: usize,
    /// Record fields in order, with types (see `cell_file`).
    pub record_fields: Vec<String>,
    /// Cell file compression.
    pub compression: String,
    /// Exact bounds of the stored points (world frame, input units).
    pub bounds: Aabb,
    /// The octree's root cube.
    pub cube: Cube,
    /// Cell point limit the store was built with.
    pub max_cell_points: u64,
    /// Levels of the counting grid.
    pub count_levels: u32,
    /// The inputs, in order.
    pub inputs: Vec<InputEntry>,
    /// Non-empty cells in key order.
    pub cells: Vec<CellEntry>,
    /// How the normals were estimated, when ingest estimated them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimated_normals: Option<EstimatedNormals>,
    /// The cells' zstd level (`--zstd-level`; absent from stores made before it was
    /// recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zstd_level: Option<i32>,
    /// Whether invalid points were skipped (`--skip-invalid`; absent from stores made
    /// before it was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skip_invalid: Option<bool>,
}

/// How ingest estimated the normals (absent when they came from the inputs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EstimatedNormals {
    /// Neighbours per plane fit (`--neighbours`).
    pub k: usize,
    /// Most neighbours any cell used (grown for noise).
    #[serde(default)]
    pub k_max: usize,
    /// Robust (reweighted) plane fits.
    pub robust: bool,
    /// Points without a plane among their neighbours (zero normals).
    pub degenerate: u64,
    /// Points whose sign came from their scan's viewpoint.
    pub by_viewpoint: u64,
    /// Points oriented by propagation and the outward choice.
    pub by_propagation: u64,
    /// Orientation components (connected parts of the neighbour graph).
    pub components: u64,
}

/// One input file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InputEntry {
    /// Path as given.
    pub path: String,
    /// Format read.
    pub format: Format,
    /// Points in the file.
    pub points: u64,
    /// Transform applied.
    pub transform: Rigid,
    /// Where the scan was seen from, when known (orients estimated normals).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub viewpoint: Option<Viewpoint>,
    /// Factor its colours were scaled by to 16 bits (257 for 8-bit colour in LAS fields).
    #[serde(default = "one")]
    pub color_scale: u32,
}

fn one() -> u32 {
    1
}

/// One cell.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CellEntry {
    /// Key (level sentinel bit plus Morton code).
    pub key: CellKey,
    /// Octree level.
    pub level: u32,
    /// Integer coordinates at that level.
    pub coords: [u32; 3],
    /// Points.
    pub count: u64,
    /// Bounds of its points.
    pub bounds: Aabb,
    /// File name inside `cells/`.
    pub file: String,
    /// Compressed size in bytes.
    pub bytes: u64,
    /// CRC-32 (IEEE) of the file.
    pub crc32: u32,
}

/// The end of the wave of cells starting at `i`: at most `max_cells` cells and, beyond the
/// first (always taken, so that a wave makes progress), within `share` bytes at `per_point`
/// bytes per point. Returns the end and the bytes the wave holds.
pub fn next_wave(
    cells: &[CellEntry],
    i: usize,
    max_cells: usize,
    share: u64,
    per_point: u64,
) -> (usize, u64) {
    let (mut j, mut bytes) = (i, 0u64);
    while j < cells.len() && j - i < max_cells {
        let b = cells[j].count * per_point;
        if j > i && bytes + b > share {
            break;
        }
        bytes += b;
        j += 1;
    }
    (j, bytes)
}

impl Manifest {
    /// Read and check a manifest.
    pub fn load(store: &Path) -> Result<Manifest> {
        let path = store.join(MANIFEST);
        if !store.is_dir() {
            return Err(Error::input(
                store,
                "not a scanflow store (not a directory)",
            ));
        }
        if path.exists() {
            // A FIFO would block the read.
            crate::io::regular_file(&path, "a store manifest")?;
        }
        let text = std::fs::read_to_string(&path).map_err(|e| {
            if e.kind() == std::io::ErrorKind::NotFound {
                Error::input(
                    store,
                    "not a complete scanflow store: it has no manifest.json (an interrupted ingest leaves none)",
                )
            } else {
                Error::io(&path, e)
            }
        })?;
        let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| {
            Error::format(
                &path,
                crate::error::Location::Line(e.line() as u64),
                format!("invalid JSON: {e}"),
            )
        })?;
        if v.get("format").and_then(|f| f.as_str()) != Some(STORE_FORMAT) {
            return Err(Error::input(&path, "not a scanflow store manifest"));
        }
        let version = v.get("version").and_then(|f| f.as_u64()).unwrap_or(0);
        if version != STORE_VERSION as u64 {
            return Err(Error::input(
                &path,
                format!(
                    "store format version {version}, but this scanflow reads version {STORE_VERSION}; re-run ingest"
                ),
            ));
        }
        serde_json::from_value(v).map_err(|e| {
            Error::input(
                &path,
                format!("manifest does not match version {STORE_VERSION}: {e}"),
            )
        })
    }

    /// Write to `dir/manifest.json` atomically, synced.
    pub fn save(&self, dir: &Path) -> Result<()> {
        let path = dir.join(MANIFEST);
        let text = serde_json::to_string_pretty(self)
            .map_err(|e| Error::Internal(format!("manifest serialisation: {e}")))?;
        let mut bytes = text.into_bytes();
        bytes.push(b'\n');
        atomic::write(&path, &bytes, Durability::Synced)
    }
}

/// The manifest's `record_fields`: the fields of a record in order, with their types (see
/// the table in [`crate::cell_file`]).
pub fn record_fields(a: Attributes, pos_f32: bool) -> Vec<String> {
    let t = if pos_f32 { "f32" } else { "f64" };
    let mut v: Vec<String> = ["x", "y", "z"].map(|c| format!("{c}:{t}")).to_vec();
    if a.normal {
        v.extend(["nx:f32", "ny:f32", "nz:f32"].map(String::from));
    }
    if a.color {
        v.extend(["red:u16", "green:u16", "blue:u16"].map(String::from));
        if a.alpha {
            v.push("alpha:u16".into());
        }
    }
    if a.intensity {
        v.push("intensity:f32".into());
    }
    if a.confidence {
        v.push("confidence:f32".into());
    }
    if a.source {
        v.push("scan:u16".into());
    }
    v
}
