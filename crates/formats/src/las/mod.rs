//! LAS / LAZ point reader (LAS 1.0–1.4, point formats 0–10), through the `las` crate.
//!
//! Positions come scaled and offset as the header says; intensity is carried for every point
//! format, and RGB (16-bit, as stored, with an opaque alpha) when the point format has colour.
//! LASzip-compressed files (LAZ) are recognised by the compression bit of the point format.
//!
//! Opening reads and checks the header; for uncompressed files it also checks that the file
//! holds every point record the header declares, so that a truncated file fails at once. Each
//! chunk is read through its own `las::Reader` (a buffered file handle) that seeks to the
//! chunk's first point, so workers read chunks independently.

use std::fs::File;
use std::io::{BufReader, Read};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use crate::error::{Error, IoContext, Location, Result};
use crate::las_meta::{LasMeta, LasTally};
use crate::types::{Aabb, Attributes, PointBatch};
use crate::{ChunkSpec, ChunkStats, Format, PointReader, invalid_coordinate_msg};

/// Points decoded at a time within a chunk (bounds the `las::Point` buffer).
const BATCH: u64 = 1 << 16;
/// Read buffer of a chunk's file handle.
const READ_BUFFER: usize = 1 << 20;
/// Byte offsets of the x, y and z scale factors in the LAS header.
const SCALE_AT: [u64; 3] = [131, 139, 147];
/// Byte offset of the version (major, minor) in the LAS header.
const VERSION_AT: u64 = 24;
/// Byte offset of the offset to point data in the LAS header.
const DATA_OFFSET_AT: u64 = 96;
/// Byte of the header size field.
const HEADER_SIZE_AT: u64 = 94;
/// Byte of the point data format field (the record length follows it).
const POINT_FORMAT_AT: u64 = 104;

/// Run `f`, turning a panic inside the `las`/`laz` crates (on corrupt data) into an error.
fn guard<T>(f: impl FnOnce() -> T) -> std::result::Result<T, String> {
    catch_unwind(AssertUnwindSafe(f)).map_err(|p| {
        p.downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".to_string())
    })
}

/// Points per chunk: `target`, rounded to whole LASzip chunks when it spans at least one.
fn aligned_target(target: u64, laz_chunk: Option<u64>) -> u64 {
    let target = target.max(1);
    match laz_chunk {
        Some(c) if c > 0 && target >= c => target.saturating_add(c / 2) / c * c,
        _ => target,
    }
}

fn is_eof(e: &las::Error) -> bool {
    matches!(e, las::Error::Io(io) if io.kind() == std::io::ErrorKind::UnexpectedEof)
}

/// Check the `LASF` signature in the first 4 bytes of `file`.
fn check_signature(file: &mut File, path: &Path) -> Result<()> {
    let mut magic = Vec::with_capacity(4);
    file.take(4).read_to_end(&mut magic).with_path(path)?;
    if magic != b"LASF" {
        return Err(Error::format(
            path,
            Location::Byte(0),
            format!(
                "not a LAS file: expected the signature \"LASF\", found \"{}\"",
                magic.escape_ascii()
            ),
        ));
    }
    Ok(())
}

/// Read the raw header and check what the readers rely on: the version, where the point data
/// starts, and the scale factors.
fn read_raw_header(path: &Path, file_len: u64) -> Result<las::raw::Header> {
    let file = File::open(path).with_path(path)?;
    let raw = las::raw::Header::read_from(BufReader::new(file)).map_err(|e| {
        if is_eof(&e) {
            Error::format(
                path,
                Location::Byte(file_len),
                format!("truncated LAS header: the file ends after {file_len} bytes"),
            )
        } else {
            Error::input(path, format!("invalid LAS header: {e}"))
        }
    })?;
    let (major, minor) = (raw.version.major, raw.version.minor);
    if major != 1 || minor > 4 {
        return Err(Error::format(
            path,
            Location::Byte(VERSION_AT),
            format!("unsupported LAS version {major}.{minor}, expected 1.0 to 1.4"),
        ));
    }
    check_header_fields(path, &raw)?;
    let data_start = u64::from(raw.offset_to_point_data);
    if data_start > file_len {
        return Err(Error::format(
            path,
            Location::Byte(DATA_OFFSET_AT),
            format!(
                "the header puts the point data at byte {data_start}, but the file ends after {file_len} bytes"
            ),
        ));
    }
    let scales = [raw.x_scale_factor, raw.y_scale_factor, raw.z_scale_factor];
    for ((axis, s), at) in ["x", "y", "z"].into_iter().zip(scales).zip(SCALE_AT) {
        if !s.is_finite() || s == 0.0 {
            return Err(Error::format(
                path,
                Location::Byte(at),
                format!("{axis} scale factor is {s}, expected a finite non-zero number"),
            ));
        }
    }
    Ok(raw)
}

/// Check the header size, point format and record length of a raw header against its
/// version, naming the field's byte.
fn check_header_fields(path: &Path, raw: &las::raw::Header) -> Result<()> {
    let min_header = match raw.version.minor {
        0..=2 => 227,
        3 => 235,
        _ => 375,
    };
    if raw.header_size < min_header {
        return Err(Error::format(
            path,
            Location::Byte(HEADER_SIZE_AT),
            format!(
                "header size {} is smaller than the {min_header} bytes of a LAS {}.{} header",
                raw.header_size, raw.version.major, raw.version.minor
            ),
        ));
    }
    if raw.offset_to_point_data < u32::from(raw.header_size) {
        return Err(Error::format(
            path,
            Location::Byte(DATA_OFFSET_AT),
            format!(
                "the point data starts at byte {}, inside the {}-byte header",
                raw.offset_to_point_data, raw.header_size
            ),
        ));
    }
    // Bits 6 and 7 flag LASzip compression.
    let number = raw.point_data_record_format & 0x3f;
    let Ok(fmt) = las::point::Format::new(number) else {
        return Err(Error::format(
            path,
            Location::Byte(POINT_FORMAT_AT),
            format!("point data format {number}, expected 0 to 10"),
        ));
    };
    if raw.point_data_record_length < fmt.len() {
        return Err(Error::format(
            path,
            Location::Byte(POINT_FORMAT_AT + 1),
            format!(
                "point records of {} bytes, but point format {number} needs at least {}",
                raw.point_data_record_length,
                fmt.len()
            ),
        ));
    }
    Ok(())
}

/// Open the `las` decoder on `path` (its header, variable-length records and, for LAZ, the
/// LASzip record and chunk table).
fn open_decoder(
    path: &Path,
    file_len: u64,
    data_start: u64,
    raw: &las::raw::Header,
) -> Result<las::Reader> {
    // The compression bit, as the las crate tests it.
    let raw_compressed = raw.point_data_record_format & 0x80 != 0;
    let file = File::open(path).with_path(path)?;
    guard(|| las::Reader::new(BufReader::new(file)))
        .map_err(|p| Error::input(path, format!("invalid LAS header (decoder failed: {p})")))?
        .map_err(|e| {
            if is_eof(&e) {
                Error::format(
                    path,
                    Location::Byte(file_len),
                    format!(
                        "truncated LAS header or variable-length records: the file ends after {file_len} bytes"
                    ),
                )
            } else if raw_compressed {
                Error::format(
                    path,
                    Location::Byte(data_start),
                    format!(
                        "cannot open the LASzip-compressed point data (LASzip record or chunk table; is the file truncated?): {e}"
                    ),
                )
            } else {
                Error::input(path, format!("invalid LAS header: {e}"))
            }
        })
}

/// Check that an uncompressed file holds the `len` records of `record_len` bytes from byte
/// `data_start` its header declares.
fn check_record_bytes(
    path: &Path,
    file_len: u64,
    data_start: u64,
    len: u64,
    record_len: u64,
) -> Result<()> {
    let need = len
        .checked_mul(record_len)
        .and_then(|b| b.checked_add(data_start));
    if need.is_none_or(|need| need > file_len) {
        let complete = (file_len - data_start) / record_len.max(1);
        return Err(Error::format(
            path,
            Location::Element {
                index: complete,
                byte: data_start + complete * record_len,
            },
            format!(
                "truncated: the header declares {len} points of {record_len} bytes from byte {data_start}, but the file ends after {file_len} bytes, within or before point {complete}"
            ),
        ));
    }
    Ok(())
}

/// A LAS or LAZ file opened for reading.
pub struct LasReader {
    path: PathBuf,
    compressed: bool,
    version: (u8, u8),
    point_format: u8,
    len: u64,
    /// Byte where point records start.
    data_start: u64,
    /// Bytes per point record (uncompressed).
    record_len: u64,
    has_color: bool,
    bounds: Option<Aabb>,
    /// LAZ: points per LASzip chunk, when fixed. Seeking decompresses from the start of a
    /// LASzip chunk, so chunks are cut on their boundaries.
    laz_chunk: Option<u64>,
    /// Header metadata and CRS, for `info`.
    meta: LasMeta,
}

impl LasReader {
    /// Open a LAS or LAZ file: read and check its header and, for uncompressed files, that
    /// the file is long enough for every point record the header declares.
    pub fn open(path: &Path) -> Result<LasReader> {
        crate::regular_file(path, "a LAS or LAZ file")?;
        let mut file = File::open(path).with_path(path)?;
        let file_len = file.metadata().with_path(path)?.len();
        check_signature(&mut file, path)?;
        let raw = read_raw_header(path, file_len)?;
        let (major, minor) = (raw.version.major, raw.version.minor);
        let data_start = u64::from(raw.offset_to_point_data);
        let reader = open_decoder(path, file_len, data_start, &raw)?;
        let header = reader.header();
        let fmt = header.point_format();
        let compressed = fmt.is_compressed;
        let len = header.number_of_points();
        let record_len = u64::from(fmt.len());
        let point_format = fmt.to_u8().unwrap_or(raw.point_data_record_format & 0x3f);
        let meta = LasMeta::from_header(header, point_format);

        if !compressed {
            check_record_bytes(path, file_len, data_start, len, record_len)?;
        }

        let laz_chunk = if compressed {
            header
                .laz_vlr()
                .ok()
                .filter(|v| !v.uses_variable_size_chunks())
                .map(|v| u64::from(v.chunk_size()))
                .filter(|&c| c > 0)
        } else {
            None
        };
        let b = header.bounds();
        let bounds = Aabb {
            min: [b.min.x, b.min.y, b.min.z],
            max: [b.max.x, b.max.y, b.max.z],
        };
        let bounds_ok = len > 0
            && bounds.min.iter().chain(&bounds.max).all(|v| v.is_finite())
            && !bounds.is_empty();
        Ok(LasReader {
            path: path.to_path_buf(),
            compressed,
            version: (major, minor),
            point_format,
            len,
            data_start,
            record_len,
            has_color: fmt.has_color,
            bounds: bounds_ok.then_some(bounds),
            laz_chunk,
            meta,
        })
    }

    /// LAS version as (major, minor).
    pub fn version(&self) -> (u8, u8) {
        self.version
    }

    /// Point data record format (0–10).
    pub fn point_format(&self) -> u8 {
        self.point_format
    }

    /// Byte offset of point `index` (uncompressed files; 0 for LAZ, whose records have no
    /// fixed place).
    fn byte_of(&self, index: u64) -> u64 {
        if self.compressed {
            0
        } else {
            self.data_start
                .saturating_add(index.saturating_mul(self.record_len))
        }
    }

    fn element_error(&self, index: u64, msg: String) -> Error {
        Error::format(
            &self.path,
            Location::Element {
                index,
                byte: self.byte_of(index),
            },
            msg,
        )
    }

    fn panic_msg(&self, p: &str) -> String {
        if self.compressed {
            format!("corrupt LAZ data at or after this point: the decompressor failed ({p})")
        } else {
            format!("corrupt point data: the decoder failed ({p})")
        }
    }

    fn decode_error(&self, index: u64, e: &las::Error) -> Error {
        let msg = if is_eof(e) {
            format!(
                "truncated: the file ends inside this point record, but the header declares {} points",
                self.len
            )
        } else if self.compressed {
            format!("cannot decompress LAZ point data at or after this point: {e}")
        } else {
            format!("cannot decode point record: {e}")
        };
        self.element_error(index, msg)
    }
}

impl PointReader for LasReader {
    fn path(&self) -> &Path {
        &self.path
    }

    fn format(&self) -> Format {
        if self.compressed {
            Format::Laz
        } else {
            Format::Las
        }
    }

    fn attributes(&self) -> Attributes {
        Attributes {
            color: self.has_color,
            intensity: true,
            ..Attributes::default()
        }
    }

    fn len(&self) -> u64 {
        self.len
    }

    fn header_bounds(&self) -> Option<Aabb> {
        self.bounds
    }

    fn chunks(&self, target_points: u64) -> Result<Vec<ChunkSpec>> {
        let target = aligned_target(target_points, self.laz_chunk);
        Ok(crate::record_chunks(self.len, target, |i| self.byte_of(i)))
    }

    fn read_chunk(
        &self,
        chunk: &ChunkSpec,
        skip_invalid: bool,
        out: &mut PointBatch,
    ) -> Result<ChunkStats> {
        self.read_into(chunk, skip_invalid, out, None)
    }

    fn las_meta(&self) -> Option<&LasMeta> {
        Some(&self.meta)
    }

    fn read_chunk_tally(
        &self,
        chunk: &ChunkSpec,
        skip_invalid: bool,
        out: &mut PointBatch,
    ) -> Result<(ChunkStats, Option<LasTally>)> {
        let mut t = LasTally::default();
        let stats = self.read_into(chunk, skip_invalid, out, Some(&mut t))?;
        Ok((stats, Some(t)))
    }
}

impl LasReader {
    /// Decode `chunk` into `out` (the records with an invalid coordinate skipped, or an error,
    /// as `skip_invalid` says), counting every record's class and return number into `tally`.
    fn read_into(
        &self,
        chunk: &ChunkSpec,
        skip_invalid: bool,
        out: &mut PointBatch,
        mut tally: Option<&mut LasTally>,
    ) -> Result<ChunkStats> {
        let mut stats = ChunkStats::default();
        let reserve = usize::try_from(chunk.count).unwrap_or(0);
        out.pos.reserve(reserve);
        out.intensity.reserve(reserve);
        if self.has_color {
            out.color.reserve(reserve);
        }
        self.each_batch(chunk, |at, points| {
            for (k, p) in points.iter().enumerate() {
                if let Some(t) = tally.as_deref_mut() {
                    t.add(u8::from(p.classification), p.return_number);
                }
                let xyz = [p.x, p.y, p.z];
                if let Some(msg) = invalid_coordinate_msg(xyz) {
                    if skip_invalid {
                        stats.skipped_invalid += 1;
                        continue;
                    }
                    return Err(self.element_error(at + k as u64, msg));
                }
                out.pos.push(xyz);
                out.intensity.push(f32::from(p.intensity));
                if self.has_color {
                    out.color.push(
                        p.color
                            .map_or([0, 0, 0, u16::MAX], |c| [c.red, c.green, c.blue, u16::MAX]),
                    );
                }
            }
            Ok(())
        })?;
        Ok(stats)
    }

    /// Decode the points of `chunk` in batches of at most [`BATCH`], handing each to `f` with
    /// the index of its first point. Errors name the point where decoding stopped.
    fn each_batch(
        &self,
        chunk: &ChunkSpec,
        mut f: impl FnMut(u64, &[las::Point]) -> Result<()>,
    ) -> Result<()> {
        if chunk.count == 0 {
            return Ok(());
        }
        if chunk
            .first_index
            .checked_add(chunk.count)
            .is_none_or(|end| end > self.len)
        {
            return Err(Error::Internal(format!(
                "{}: chunk of {} points from point {} goes past the {} points of the file",
                self.path.display(),
                chunk.count,
                chunk.first_index,
                self.len
            )));
        }
        let file = File::open(&self.path).with_path(&self.path)?;
        let first = chunk.first_index;
        let mut reader = guard(|| las::Reader::new(BufReader::with_capacity(READ_BUFFER, file)))
            .map_err(|p| self.element_error(first, self.panic_msg(&p)))?
            .map_err(|e| {
                Error::input(
                    &self.path,
                    format!("invalid LAS header (did the file change since it was opened?): {e}"),
                )
            })?;
        if reader.header().number_of_points() != self.len {
            return Err(Error::input(
                &self.path,
                format!(
                    "the file changed while being read: its header declared {} points when opened, {} now",
                    self.len,
                    reader.header().number_of_points()
                ),
            ));
        }
        guard(|| reader.seek(first))
            .map_err(|p| self.element_error(first, self.panic_msg(&p)))?
            .map_err(|e| self.decode_error(first, &e))?;

        let mut points = Vec::with_capacity(usize::try_from(chunk.count.min(BATCH)).unwrap_or(0));
        let mut done = 0u64;
        while done < chunk.count {
            let want = BATCH.min(chunk.count - done);
            let at = first + done;
            points.clear();
            let got = guard(|| reader.read_points_into(want, &mut points))
                .map_err(|p| self.element_error(at, self.panic_msg(&p)))?
                .map_err(|e| self.decode_error(at + points.len() as u64, &e))?;
            if got != want || points.len() as u64 != want {
                let index = at + got.min(points.len() as u64);
                return Err(self.element_error(
                    index,
                    format!(
                        "truncated: the point data ends here, but the header declares {} points",
                        self.len
                    ),
                ));
            }
            f(at, &points)?;
            done += want;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
