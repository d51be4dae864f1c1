//! The PLY point reader: the `vertex` element of an ascii, binary_little_endian or
//! binary_big_endian file, as [`PointReader`] chunks.
//!
//! The header is parsed once ([`super::parse_header`]); vertex properties may come in any
//! order and of any scalar type (`char`…`double` and the `int8`…`float64` spellings). Elements
//! before `vertex` (a `camera`, say) are skipped by size, walking their lists where they have
//! any; elements after it (faces, `range_grid`, `tristrips`) are walked once at open time in
//! binary files, so that a truncated file is reported at open, never half-read; where each
//! element's records start is kept ([`PlyReader::element_start`]), for the mesh reader.
//!
//! Binary vertex records are decoded straight from a memory-mapped window per chunk. ply-rs
//! parses whole files into owned maps and gives no byte offsets, so the reader is ours.
//!
//! This file opens and validates a file and splits it into chunks; `decode.rs` decodes the
//! records of a chunk.

mod decode;

use std::fs::File;
use std::path::{Path, PathBuf};

use super::header::HEADER_LIMIT;
use super::{Element, Encoding, PlyHeader, Property, Scalar, parse_header};
use crate::error::{Error, IoContext, Location, Result};
use crate::fs::mmap::Window;
use crate::types::{Attributes, PointBatch};
use crate::{ChunkSpec, ChunkStats, Format, PointReader};

/// Where each wanted attribute sits in a vertex record.
#[derive(Debug, Clone, Copy)]
struct Field {
    /// Byte offset within a binary record, or token index for ascii.
    at: usize,
    ty: Scalar,
}

#[derive(Debug, Clone, Default)]
struct Layout {
    xyz: Option<[Field; 3]>,
    normal: Option<[Field; 3]>,
    rgb: Option<[Field; 3]>,
    alpha: Option<Field>,
    intensity: Option<Field>,
    confidence: Option<Field>,
}

/// A PLY file opened for reading points.
pub struct PlyReader {
    path: PathBuf,
    /// The normals are ignored, so not checked ([`PointReader::ignore_normals`]).
    ignore_normals: bool,
    file: File,
    header: PlyHeader,
    /// Index of the vertex element.
    vertex: usize,
    layout: Layout,
    /// Binary: record size. Ascii: number of tokens per vertex line.
    stride: usize,
    /// Byte where vertex data starts.
    vertex_start: u64,
    /// Binary: the byte where each element's records start, in header order (empty for
    /// ascii).
    element_starts: Vec<u64>,
    /// Ascii: line number of the first vertex line, and an index of (byte, line, element)
    /// every [`ASCII_INDEX_STEP`] vertices, ending with the position after the last vertex.
    ascii_index: Vec<(u64, u64, u64)>,
    attrs: Attributes,
}

/// Ascii: a position is recorded every this many vertex lines (chunks are cut there).
const ASCII_INDEX_STEP: u64 = 1 << 16;
/// Bytes mapped at a time when walking lists or indexing ascii lines.
const SCAN_WINDOW: u64 = 64 << 20;

impl PlyReader {
    /// Open and validate a PLY file: header, vertex properties, and (binary) that the file
    /// holds every element the header declares.
    pub fn open(path: &Path) -> Result<PlyReader> {
        crate::regular_file(path, "a PLY file")?;
        let file = File::open(path).with_path(path)?;
        let file_len = file.metadata().with_path(path)?.len();
        if file_len == 0 {
            return Err(Error::input(path, "empty file (0 bytes)"));
        }
        let head = Window::map(&file, path, 0, file_len.min(HEADER_LIMIT as u64))?;
        let header = parse_header(path, &head)?;
        drop(head);
        let Some(vertex) = header.elements.iter().position(|e| e.name == "vertex") else {
            return Err(Error::format(
                path,
                Location::Line(header.lines),
                "PLY header declares no \"vertex\" element",
            ));
        };
        let el = &header.elements[vertex];
        if let Some(p) = el.props.iter().find(|p| matches!(p, Property::List { .. })) {
            return Err(Error::format(
                path,
                Location::Line(el.line),
                format!(
                    "vertex element has a list property \"{}\"; vertex properties must be scalars",
                    p.name()
                ),
            ));
        }
        let binary = header.encoding != Encoding::Ascii;
        let mut offsets = Vec::with_capacity(el.props.len());
        let mut off = 0usize;
        for (i, p) in el.props.iter().enumerate() {
            let Property::Scalar { name, ty } = p else {
                unreachable!("lists rejected above")
            };
            offsets.push((
                name.as_str(),
                Field {
                    at: if binary { off } else { i },
                    ty: *ty,
                },
            ));
            off += ty.size();
        }
        let find = |names: &[&str]| {
            offsets
                .iter()
                .find(|(n, _)| names.contains(n))
                .map(|&(_, f)| f)
        };
        let x = find(&["x"]);
        let y = find(&["y"]);
        let z = find(&["z"]);
        let (Some(x), Some(y), Some(z)) = (x, y, z) else {
            let missing: Vec<&str> = [("x", x), ("y", y), ("z", z)]
                .iter()
                .filter(|(_, f)| f.is_none())
                .map(|(n, _)| *n)
                .collect();
            return Err(Error::format(
                path,
                Location::Line(el.line),
                format!(
                    "vertex element has no {} property (found: {})",
                    missing.join(", "),
                    offsets
                        .iter()
                        .map(|(n, _)| *n)
                        .collect::<Vec<_>>()
                        .join(" ")
                ),
            ));
        };
        let tri = |a: &[&str], b: &[&str], c: &[&str]| match (find(a), find(b), find(c)) {
            (Some(a), Some(b), Some(c)) => Some([a, b, c]),
            _ => None,
        };
        let layout = Layout {
            xyz: Some([x, y, z]),
            normal: tri(
                &["nx", "normal_x"],
                &["ny", "normal_y"],
                &["nz", "normal_z"],
            ),
            rgb: tri(
                &["red", "r", "diffuse_red"],
                &["green", "g", "diffuse_green"],
                &["blue", "b", "diffuse_blue"],
            ),
            alpha: find(&["alpha", "a", "diffuse_alpha"]),
            intensity: find(&["intensity", "scalar_intensity"]),
            confidence: find(&["confidence", "scalar_confidence"]),
        };
        let attrs = Attributes {
            normal: layout.normal.is_some(),
            color: layout.rgb.is_some(),
            alpha: layout.rgb.is_some() && layout.alpha.is_some(),
            intensity: layout.intensity.is_some(),
            confidence: layout.confidence.is_some(),
            source: false,
        };
        let stride = if binary { off } else { el.props.len() };
        let mut r = PlyReader {
            ignore_normals: false,
            path: path.to_path_buf(),
            file,
            vertex,
            layout,
            stride,
            vertex_start: 0,
            element_starts: Vec::new(),
            ascii_index: Vec::new(),
            attrs,
            header,
        };
        if binary {
            r.validate_binary(file_len)?;
        } else {
            r.index_ascii(file_len)?;
        }
        Ok(r)
    }

    /// The parsed header.
    pub fn header(&self) -> &PlyHeader {
        &self.header
    }

    /// The byte where the records of element `i` (in header order) start, in a binary file
    /// (found when it was opened); `None` in an ascii one.
    pub fn element_start(&self, i: usize) -> Option<u64> {
        self.element_starts.get(i).copied()
    }

    fn big_endian(&self) -> bool {
        self.header.encoding.big_endian()
    }

    /// Walk every element's extent; fail on the first one the file does not fully hold.
    fn validate_binary(&mut self, file_len: u64) -> Result<()> {
        let mut pos = self.header.data_start;
        let mut starts = Vec::with_capacity(self.header.elements.len());
        for (i, el) in self.header.elements.iter().enumerate() {
            if i == self.vertex {
                self.vertex_start = pos;
            }
            starts.push(pos);
            let end = match el.fixed_size() {
                Some(sz) => {
                    let end = sz
                        .checked_mul(el.count)
                        .and_then(|b| b.checked_add(pos))
                        .unwrap_or(u64::MAX);
                    if end > file_len {
                        let have = (file_len - pos.min(file_len)).checked_div(sz).unwrap_or(0);
                        return Err(Error::format(
                            &self.path,
                            Location::Element {
                                index: have,
                                byte: pos + have * sz,
                            },
                            format!(
                                "truncated: the header promises {} \"{}\" records of {} bytes from byte {}, but the file ends at byte {} after {} of them",
                                el.count, el.name, sz, pos, file_len, have
                            ),
                        ));
                    }
                    end
                }
                None => self.walk_lists(el, pos, file_len)?,
            };
            pos = end;
        }
        self.element_starts = starts;
        Ok(())
    }

    /// Walk a binary element with list properties record by record; return its end.
    fn walk_lists(&self, el: &Element, start: u64, file_len: u64) -> Result<u64> {
        let be = self.big_endian();
        let mut pos = start;
        let mut win_start = start;
        let mut win = Window::map(
            &self.file,
            &self.path,
            start,
            file_len.min(start + SCAN_WINDOW),
        )?;
        let truncated = |rec: u64, at: u64| {
            Error::format(
                &self.path,
                Location::Element {
                    index: rec,
                    byte: at,
                },
                format!(
                    "truncated: the header promises {} \"{}\" records, but the file ends at byte {} inside record {}",
                    el.count, el.name, file_len, rec
                ),
            )
        };
        for rec in 0..el.count {
            let rec_start = pos;
            for p in &el.props {
                let (need_now, item) = match p {
                    Property::Scalar { ty, .. } => (ty.size() as u64, None),
                    Property::List { count, item, .. } => (count.size() as u64, Some(*item)),
                };
                // Make sure the window holds [pos, pos + need_now).
                if pos + need_now > win_start + win.len() as u64 {
                    if pos + need_now > file_len {
                        return Err(truncated(rec, rec_start));
                    }
                    win_start = pos;
                    win =
                        Window::map(&self.file, &self.path, pos, file_len.min(pos + SCAN_WINDOW))?;
                }
                if let (Property::List { count, .. }, Some(item)) = (p, item) {
                    let at = (pos - win_start) as usize;
                    let n = count.read(&win[at..], be);
                    if n < 0.0 {
                        return Err(Error::format(
                            &self.path,
                            Location::Element {
                                index: rec,
                                byte: rec_start,
                            },
                            format!(
                                "\"{}\" record {} has a negative list length {}",
                                el.name, rec, n
                            ),
                        ));
                    }
                    pos += need_now + n as u64 * item.size() as u64;
                } else {
                    pos += need_now;
                }
                if pos > file_len {
                    return Err(truncated(rec, rec_start));
                }
            }
        }
        Ok(pos)
    }

    /// Ascii: find the first vertex line and index vertex lines; fail if there are too few.
    fn index_ascii(&mut self, file_len: u64) -> Result<()> {
        let skip_lines: u64 = self.header.elements[..self.vertex]
            .iter()
            .map(|e| e.count)
            .sum();
        let total = self.header.elements[self.vertex].count;
        let mut line = self.header.lines + 1;
        let mut pos = self.header.data_start;
        let mut vertices_seen = 0u64;
        let mut skipped = 0u64;
        let mut index = Vec::new();
        let mut in_vertex = skip_lines == 0;
        if in_vertex {
            self.vertex_start = pos;
            index.push((pos, line, 0));
        }
        while (skipped < skip_lines || vertices_seen < total) && pos < file_len {
            let end = file_len.min(pos + SCAN_WINDOW);
            let win = Window::map(&self.file, &self.path, pos, end)?;
            let mut i = 0usize;
            while i < win.len() && (skipped < skip_lines || vertices_seen < total) {
                let Some(nl) = win[i..].iter().position(|&b| b == b'\n') else {
                    if end == file_len {
                        // Last line without newline.
                        i = win.len();
                        if in_vertex {
                            vertices_seen += 1;
                        } else {
                            skipped += 1;
                        }
                        line += 1;
                    }
                    break;
                };
                i += nl + 1;
                line += 1;
                if in_vertex {
                    vertices_seen += 1;
                    if vertices_seen.is_multiple_of(ASCII_INDEX_STEP) {
                        index.push((pos + i as u64, line, vertices_seen));
                    }
                } else {
                    skipped += 1;
                    if skipped == skip_lines {
                        in_vertex = true;
                        self.vertex_start = pos + i as u64;
                        index.push((pos + i as u64, line, 0));
                    }
                }
            }
            if i == 0 {
                break;
            }
            pos += i as u64;
        }
        if vertices_seen < total {
            return Err(Error::format(
                &self.path,
                Location::Line(line),
                format!(
                    "truncated: the header promises {} vertices, but the file ends after {} vertex lines",
                    total, vertices_seen
                ),
            ));
        }
        if index.last().map(|e| e.2) != Some(total) {
            index.push((pos, line, total));
        }
        self.ascii_index = index;
        Ok(())
    }
}

impl PointReader for PlyReader {
    fn ignore_normals(&mut self) {
        self.ignore_normals = true;
    }

    fn path(&self) -> &Path {
        &self.path
    }

    fn format(&self) -> Format {
        match self.header.encoding {
            Encoding::Ascii => Format::PlyAscii,
            Encoding::BinaryLe => Format::PlyBinaryLe,
            Encoding::BinaryBe => Format::PlyBinaryBe,
        }
    }

    fn attributes(&self) -> Attributes {
        self.attrs
    }

    fn len(&self) -> u64 {
        self.header.elements[self.vertex].count
    }

    fn positions_f32(&self) -> bool {
        self.layout.xyz.is_some_and(|f| {
            f.iter().all(|f| {
                matches!(
                    f.ty,
                    Scalar::F32 | Scalar::I8 | Scalar::U8 | Scalar::I16 | Scalar::U16
                )
            })
        })
    }

    fn chunks(&self, target_points: u64) -> Result<Vec<ChunkSpec>> {
        let target = target_points.max(1);
        let total = self.len();
        let mut out = Vec::new();
        if self.header.encoding == Encoding::Ascii {
            // Chunks are unions of consecutive index steps.
            let steps = (target / ASCII_INDEX_STEP).max(1) as usize;
            let idx = &self.ascii_index;
            let mut k = 0;
            while k + 1 < idx.len() {
                let e = (k + steps).min(idx.len() - 1);
                let (b0, l0, i0) = idx[k];
                let (b1, _, i1) = idx[e];
                if i1 > i0 {
                    out.push(ChunkSpec {
                        byte_start: b0,
                        byte_end: b1,
                        first_index: i0,
                        count: i1 - i0,
                        first_line: l0,
                    });
                }
                k = e;
            }
            return Ok(out);
        }
        let stride = self.stride as u64;
        Ok(crate::record_chunks(total, target, |i| {
            self.vertex_start + i * stride
        }))
    }

    fn read_chunk(
        &self,
        chunk: &ChunkSpec,
        skip_invalid: bool,
        out: &mut PointBatch,
    ) -> Result<ChunkStats> {
        match self.header.encoding {
            Encoding::Ascii => self.read_ascii(chunk, skip_invalid, out),
            _ => self.read_binary(chunk, skip_invalid, out),
        }
    }
}

#[cfg(test)]
mod tests;
