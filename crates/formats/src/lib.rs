//! File formats: point readers (PLY, LAS/LAZ, E57, XYZ/PTS), the `.conf` scan list, and the
//! surface-mesh readers and writers. IGES lives with the spline fit (`scanflow-spline`), the
//! volume-mesh formats with the hex mesher (`scanflow-hex`).
//!
//! Every reader is a [`PointReader`]: it parses its header once when opened, then splits
//! the point data into [`ChunkSpec`]s that workers read independently, each through its own
//! memory-mapped window (so resident memory stays proportional to the chunks in flight,
//! never to the file). Locations in errors are absolute: element index and byte offset (binary)
//! or line (text), counted from the start of the file.
//!
//! # Module map
//!
//! Readers ([`open`] picks one by content and extension; each first checks, from the file's
//! type alone, that its path is a regular file ([`regular_file`]), so a directory, FIFO or
//! device is named as such and a FIFO is never opened, which would block):
//!
//! * [`ply`]: PLY, read and written on one header model (`header.rs`, parsed by every PLY
//!   reader, written by both PLY writers through `write.rs`): points, ascii and binary
//!   (`point_reader/`), meshes (`mesh_reader/`: the `face` element or a scan's `range_grid`),
//!   and the writers listed below;
//! * [`las`]: LAS and LAZ;
//! * [`e57`]: E57, every scan with its pose (one input per scan for ingest);
//! * [`xyz`]: XYZ / PTS text (`text.rs` the layouts, tokenizer and line walk, `decode.rs` the
//!   values);
//! * [`mesh`]: the [`mesh::Mesh`] every mesh reader fills (below the readers, so none imports
//!   the dispatcher);
//! * [`mesh_read`]: meshes in any format, for `scanflow check`, `fit` and tests:
//!   [`mesh_read::read_any_mesh`] reads OBJ ([`obj`]) and STL ([`stl`]) by extension, PLY
//!   through [`ply`] (whose [`mesh_read::read_mesh`] and [`mesh_read::read_scan_mesh`] it
//!   re-exports);
//! * [`conf`]: the `.conf` scan list (files and their rigid transforms);
//! * [`fs::mmap`]: the memory-mapped window every binary and text reader reads through
//!   (in `scanflow-core`).
//!
//! Writers, each streaming in memory independent of the file's size:
//!
//! * [`ply_write`]: point PLY ([`ply_write::PointPlyWriter`]; a re-export of
//!   [`ply::point_writer`]);
//! * [`mesh_write`]: the streamed mesh of ARCHITECTURE.md step 5, as PLY (binary or ASCII),
//!   OBJ or STL ([`mesh_write::MeshWriter`]): the API, the staging and the three encoders (the
//!   PLY one writes its header from [`ply`]'s model);
//! * [`preview`]: a PNG picture of a mesh (three views), rasterised as the mesh streams to
//!   its writer;
//!
//! The atomic writer, [`fs::atomic`] (in `scanflow-core`), is the one way any output appears under its final name:
//! written under `NAME.tmp-<pid>`, synced, renamed, the directory synced; removed when dropped
//! before that. Both writers above (a `BufWriter` over an [`fs::atomic::AtomicFile`]) and every
//! other output of scanflow go through it.
#![deny(missing_docs)]
#![deny(unsafe_op_in_unsafe_fn)]
// Fixed-size 3D loops index several arrays at once; iterators would obscure the math.
#![allow(clippy::needless_range_loop)]

use scanflow_core::{error, fs, geom, types};

pub mod conf;
pub mod e57;
pub mod islands;
pub mod las;
pub mod las_meta;
pub mod mesh;
pub mod mesh_read;
pub mod mesh_write;
pub mod obj;
pub mod ply;
pub mod preview;
pub mod stl;
pub mod xyz;

pub use ply::point_writer as ply_write;

use std::path::{Path, PathBuf};

use crate::error::{Error, Location, Result, Setting};
use crate::types::{Attributes, PointBatch, Rigid, Viewpoint};

/// The formats scanflow reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum Format {
    /// PLY, ascii.
    PlyAscii,
    /// PLY, binary little endian.
    PlyBinaryLe,
    /// PLY, binary big endian.
    PlyBinaryBe,
    /// LAS (uncompressed).
    Las,
    /// LAZ (LASzip-compressed LAS).
    Laz,
    /// Whitespace-separated text, one point a line.
    Xyz,
    /// ASTM E57 (terrestrial scans with their poses).
    E57,
}

impl Format {
    /// A short human name.
    pub fn name(self) -> &'static str {
        match self {
            Format::PlyAscii => "PLY ascii",
            Format::PlyBinaryLe => "PLY binary_little_endian",
            Format::PlyBinaryBe => "PLY binary_big_endian",
            Format::Las => "LAS",
            Format::Laz => "LAZ",
            Format::Xyz => "XYZ text",
            Format::E57 => "E57",
        }
    }

    /// LAS or LAZ: the same point records, uncompressed or LASzip-compressed. Every rule keyed
    /// on LAS (normals face up without a viewpoint, 8-bit colour scaling) covers both.
    pub fn is_las(self) -> bool {
        matches!(self, Format::Las | Format::Laz)
    }
}

/// A contiguous run of points of one file, read by one worker.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChunkSpec {
    /// First byte of the chunk's data.
    pub byte_start: u64,
    /// One past the last byte.
    pub byte_end: u64,
    /// Index of the chunk's first point within the file.
    pub first_index: u64,
    /// Number of points (records, or data lines for text) in the chunk.
    pub count: u64,
    /// 1-based line number of the chunk's first byte (text formats; 0 for binary).
    pub first_line: u64,
}

/// What reading a chunk produced besides the points.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ChunkStats {
    /// Points dropped because a coordinate was NaN or infinite, or the normal was not finite
    /// or zero (only with `skip_invalid`).
    pub skipped_invalid: u64,
}

/// A point file opened for reading: header parsed, data split into chunks on demand.
pub trait PointReader: Send + Sync {
    /// The file.
    fn path(&self) -> &Path;
    /// Its format.
    fn format(&self) -> Format;
    /// Attributes the file carries.
    fn attributes(&self) -> Attributes;
    /// Number of points (records) in the file.
    fn len(&self) -> u64;
    /// True when the file holds no point.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Bounds from the header, when the format stores them (LAS).
    fn header_bounds(&self) -> Option<crate::types::Aabb> {
        None
    }
    /// A LAS file's header metadata and CRS ([`las_meta`]); `None` for other formats.
    fn las_meta(&self) -> Option<&las_meta::LasMeta> {
        None
    }
    /// [`PointReader::read_chunk`], and for a LAS file the classes and return numbers of the
    /// chunk's records counted in the same pass (`None` for other formats).
    fn read_chunk_tally(
        &self,
        chunk: &ChunkSpec,
        skip_invalid: bool,
        out: &mut PointBatch,
    ) -> Result<(ChunkStats, Option<las_meta::LasTally>)> {
        Ok((self.read_chunk(chunk, skip_invalid, out)?, None))
    }
    /// True when every coordinate is stored as a float32 (or a narrower integer), so that
    /// f32 holds it exactly.
    fn positions_f32(&self) -> bool {
        false
    }
    /// Do not check the normals the file carries: they are ignored (normals are estimated).
    /// A format without normals has nothing to skip.
    fn ignore_normals(&mut self) {}
    /// Split the points into chunks of about `target_points` points each, in file order.
    /// Chunks cover every point exactly once.
    fn chunks(&self, target_points: u64) -> Result<Vec<ChunkSpec>>;
    /// Append the chunk's points to `out`, carrying the attributes of [`PointReader::attributes`].
    /// A NaN or infinite coordinate, or a normal that is not finite or is zero
    /// ([`invalid_normal_msg`], unless [`PointReader::ignore_normals`]), is an error naming the element, or, with `skip_invalid`, the
    /// point is dropped and counted.
    fn read_chunk(
        &self,
        chunk: &ChunkSpec,
        skip_invalid: bool,
        out: &mut PointBatch,
    ) -> Result<ChunkStats>;
}

/// One input: a file and the rigid transform that takes its points to the common frame.
#[derive(Debug, Clone, PartialEq)]
pub struct InputSpec {
    /// The file.
    pub path: PathBuf,
    /// Transform to apply (identity when none).
    pub transform: Rigid,
    /// Where the scan was seen from, in the common frame, when known.
    pub viewpoint: Option<Viewpoint>,
    /// The one scan of a multi-scan file (E57) this input reads; `None`: every scan.
    pub scan: Option<usize>,
}

impl InputSpec {
    /// An input without transform.
    pub fn plain(path: impl Into<PathBuf>) -> InputSpec {
        InputSpec {
            path: path.into(),
            transform: Rigid::IDENTITY,
            viewpoint: None,
            scan: None,
        }
    }
}

/// Open input `spec`: its file ([`open`]), or the one scan of an E57 file it names.
pub fn open_input(spec: &InputSpec) -> Result<Box<dyn PointReader>> {
    match spec.scan {
        Some(i) => Ok(Box::new(e57::E57Reader::open(&spec.path, Some(i))?)),
        None => open(&spec.path),
    }
}

/// Open a point file, choosing the reader by content (PLY magic, LAS signature) and, for text,
/// by extension (`.xyz`, `.pts`, `.txt`, `.csv` is not supported).
pub fn open(path: &Path) -> Result<Box<dyn PointReader>> {
    let meta = regular_file(path, "a point file")?;
    if meta.len() == 0 {
        return Err(Error::input(path, "empty file (0 bytes)"));
    }
    let mut magic = [0u8; 4];
    {
        use std::io::Read;
        let mut f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        let n = f.read(&mut magic).map_err(|e| Error::io(path, e))?;
        if n < 4 {
            magic[n..].fill(0);
        }
    }
    if &magic[..3] == b"ply" {
        return Ok(Box::new(ply::PlyReader::open(path)?));
    }
    if &magic == b"LASF" {
        return Ok(Box::new(las::LasReader::open(path)?));
    }
    if &magic == b"ASTM" {
        return Ok(Box::new(e57::E57Reader::open(path, None)?));
    }
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "xyz" | "pts" | "txt" | "xyzn" | "xyzrgb" => Ok(Box::new(xyz::XyzReader::open(path)?)),
        "ply" => Err(Error::format(
            path,
            Location::Byte(0),
            "not a PLY file: it does not start with the magic line \"ply\"",
        )),
        "las" | "laz" => Err(Error::format(
            path,
            Location::Byte(0),
            "not a LAS file: it does not start with the signature \"LASF\"",
        )),
        "e57" => Err(Error::format(
            path,
            Location::Byte(0),
            "not an E57 file: it does not start with the signature \"ASTM-E57\"",
        )),
        _ => Err(Error::input(
            path,
            "unknown point format: expected a PLY, LAS/LAZ or E57 file, or text with extension .xyz, .pts or .txt",
        )),
    }
}

/// The kind of a file that is not a regular file, in words ("a directory", "a FIFO", ...).
pub fn file_kind(t: std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_dir() {
        "a directory"
    } else if t.is_file() {
        "a regular file"
    } else {
        "not a regular file"
    }
}

/// The metadata of `path` (symbolic links followed), which must be a regular file: a
/// directory, FIFO, device or socket is an error saying which, with `expected` in the
/// message ("a point file"). Reads no byte of the file and does not open it, so a FIFO cannot
/// block; every reader calls it before opening its file.
pub fn regular_file(path: &Path, expected: &str) -> Result<std::fs::Metadata> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if meta.is_file() {
        return Ok(meta);
    }
    let kind = file_kind(meta.file_type());
    Err(Error::input(
        path,
        if meta.is_dir() {
            format!("is a directory, expected {expected}")
        } else {
            format!("not a regular file ({kind}), expected {expected}")
        },
    ))
}

/// Chunks of at most `target` records out of `total` fixed-size records, record `i` starting
/// at byte `byte_of(i)` (binary formats).
pub fn record_chunks(total: u64, target: u64, byte_of: impl Fn(u64) -> u64) -> Vec<ChunkSpec> {
    let target = target.max(1);
    let mut out = Vec::with_capacity(usize::try_from(total / target + 1).unwrap_or(0));
    let mut i = 0;
    while i < total {
        let n = target.min(total - i);
        out.push(ChunkSpec {
            byte_start: byte_of(i),
            byte_end: byte_of(i + n),
            first_index: i,
            count: n,
            first_line: 0,
        });
        i += n;
    }
    out
}

/// What is wrong with a point's coordinates `p`, if anything: the first that is NaN or
/// infinite, named with its value.
#[inline]
pub fn invalid_coordinate_msg(p: [f64; 3]) -> Option<String> {
    let (axis, v) = ["x", "y", "z"]
        .into_iter()
        .zip(p)
        .find(|(_, v)| !v.is_finite())?;
    Some(format!(
        "{axis} is {v}, expected a finite coordinate (use {} to drop such points)",
        Setting::SkipInvalid
    ))
}

/// What makes the point at `p` with normal `normal` (when it carries one that is checked)
/// invalid, if anything: a coordinate ([`invalid_coordinate_msg`]) first, then the normal
/// ([`invalid_normal_msg`]). Every reader's one check per point: a branch on [`point_ok`]
/// inline, the message out of line (building it cost a tenth of an ingest's time when it
/// was one call per point).
#[inline(always)]
pub fn invalid_point_msg(p: [f64; 3], normal: Option<[f64; 3]>) -> Option<String> {
    if point_ok(p, normal) {
        None
    } else {
        invalid_point_detail(p, normal)
    }
}

/// Whether [`invalid_point_msg`] finds nothing wrong: finite coordinates, and a normal (when
/// checked) whose components are finite in float32 and not all zero there.
#[inline(always)]
pub fn point_ok(p: [f64; 3], normal: Option<[f64; 3]>) -> bool {
    let finite = p[0].is_finite() & p[1].is_finite() & p[2].is_finite();
    finite
        && normal.is_none_or(|n| {
            let m = n.map(|v| v as f32);
            // NaN and infinities stay so as float32; larger finite values become infinite.
            (m[0].is_finite() & m[1].is_finite() & m[2].is_finite())
                && (m[0] != 0.0 || m[1] != 0.0 || m[2] != 0.0)
        })
}

#[cold]
#[inline(never)]
fn invalid_point_detail(p: [f64; 3], normal: Option<[f64; 3]>) -> Option<String> {
    invalid_coordinate_msg(p).or_else(|| normal.and_then(invalid_normal_msg))
}

/// What is wrong with a point's normal `n` (as read, before it is narrowed to the store's
/// float32), if anything: a component that is NaN, infinite or beyond float32's range, or a
/// normal of zero length (after narrowing), which orients nothing and would splat nothing.
/// The message names the component and suggests [`Setting::SkipInvalid`].
#[inline]
pub fn invalid_normal_msg(n: [f64; 3]) -> Option<String> {
    let hint = format!("(use {} to drop such points)", Setting::SkipInvalid);
    for (name, v) in ["nx", "ny", "nz"].into_iter().zip(n) {
        if !v.is_finite() {
            return Some(format!("{name} is {v}, expected a finite normal {hint}"));
        }
        if !(v as f32).is_finite() {
            return Some(format!(
                "{name} is {v:e}, beyond float32's range, expected a finite normal {hint}"
            ));
        }
    }
    if n.iter().all(|&v| v as f32 == 0.0) {
        return Some(format!(
            "normal is zero ({}, {}, {}), expected a nonzero normal {hint}",
            n[0], n[1], n[2]
        ));
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fast_check_agrees_with_the_messages() {
        let vals = [
            0.0,
            -0.0,
            1.0,
            -2.5,
            1e-46,
            1e-40,
            3.4e38,
            1e39,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for &a in &vals {
            for &b in &vals {
                for p in [[a, b, 1.0], [1.0, a, b]] {
                    let coord_msg = invalid_coordinate_msg(p);
                    let n = [a, b, 0.0];
                    for normal in [None, Some(n), Some([0.0, a, b])] {
                        let want = coord_msg
                            .clone()
                            .or_else(|| normal.and_then(invalid_normal_msg));
                        assert_eq!(point_ok(p, normal), want.is_none(), "{p:?} {normal:?}");
                        assert_eq!(invalid_point_msg(p, normal), want, "{p:?} {normal:?}");
                    }
                }
            }
        }
    }

    fn open_err(p: &Path) -> String {
        match open(p) {
            Ok(_) => panic!("{} opened", p.display()),
            Err(e) => e.to_string(),
        }
    }

    #[cfg(unix)]
    #[test]
    fn fifo_and_char_device_are_not_regular_files() {
        let d = tempfile::tempdir().unwrap();
        let fifo = d.path().join("pipe.ply");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if matches!(made, Ok(s) if s.success()) {
            // Would block forever if the FIFO were opened for reading.
            let e = open_err(&fifo);
            assert!(e.contains("pipe.ply") && e.contains("(a FIFO)"), "{e}");
            assert!(!e.contains("empty"), "{e}");
            for e in [
                ply::PlyReader::open(&fifo).err(),
                las::LasReader::open(&fifo).err(),
                xyz::XyzReader::open(&fifo).err(),
            ] {
                let e = e.expect("a FIFO is refused").to_string();
                assert!(e.contains("(a FIFO)"), "{e}");
            }
        } else {
            eprintln!("skipped the FIFO: mkfifo is not available");
        }
        let zero = Path::new("/dev/zero");
        if zero.exists() {
            let e = open_err(zero);
            assert!(
                e.contains("/dev/zero") && e.contains("(a character device)"),
                "{e}"
            );
        }
        let e = open_err(d.path());
        assert!(e.contains("is a directory"), "{e}");
    }
}
