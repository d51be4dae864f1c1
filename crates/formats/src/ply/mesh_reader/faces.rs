//! Reading the `face` element: its layout, the corner indices of each record (binary or
//! ascii) and fan triangulation.

use std::fs::File;
use std::io::{BufRead, BufReader, Read, Seek, SeekFrom};
use std::path::Path;

use crate::error::{Error, IoContext, Location, Result};
use crate::ply::{Element, Property, Scalar};

/// The face element's (or another element of index lists') properties and which one holds
/// the corner indices. Of the other properties only the sizes matter.
#[derive(Debug)]
pub(super) struct FaceLayout {
    pub(super) props: Vec<Property>,
    /// Position of the index list in `props`.
    pub(super) indices: usize,
    /// What one record is called in messages ("face", "range_grid entry").
    pub(super) noun: &'static str,
    /// The plural of `noun`.
    pub(super) plural: &'static str,
}

impl FaceLayout {
    /// The layout of the `face` element.
    pub(super) fn new(path: &Path, face: &Element) -> Result<FaceLayout> {
        FaceLayout::of(path, face, "face", "faces")
    }

    /// The layout of element `face`, whose records are called `noun` (`plural`) in messages.
    pub(super) fn of(
        path: &Path,
        face: &Element,
        noun: &'static str,
        plural: &'static str,
    ) -> Result<FaceLayout> {
        let find = |want: &str| {
            face.props
                .iter()
                .position(|p| matches!(p, Property::List { name, .. } if name == want))
        };
        let Some(indices) = find("vertex_indices").or_else(|| find("vertex_index")) else {
            let names: Vec<&str> = face.props.iter().map(Property::name).collect();
            return Err(Error::format(
                path,
                Location::Line(face.line),
                format!(
                    "the {} element has no list property \"vertex_indices\" or \"vertex_index\" (found: {})",
                    face.name,
                    if names.is_empty() {
                        "no property".to_string()
                    } else {
                        names.join(" ")
                    }
                ),
            ));
        };
        let props = face.props.clone();
        if let Property::List { item, .. } = props[indices]
            && item.is_float()
        {
            return Err(Error::format(
                path,
                Location::Line(face.line),
                format!("{noun} vertex indices are declared {item:?}, expected an integer type"),
            ));
        }
        Ok(FaceLayout {
            props,
            indices,
            noun,
            plural,
        })
    }
}

/// Receives the index lists of an element's records: [`ListSink::corner`] for each index of
/// record `rec`, then [`ListSink::finish`]; errors are messages without location.
pub(super) trait ListSink {
    /// One index (as read) of record `rec`.
    fn corner(&mut self, rec: u64, v: f64) -> std::result::Result<(), String>;
    /// The end of record `rec`.
    fn finish(&mut self, rec: u64) -> std::result::Result<(), String>;
}

impl ListSink for FaceSink {
    fn corner(&mut self, rec: u64, v: f64) -> std::result::Result<(), String> {
        FaceSink::corner(self, rec, v)
    }
    fn finish(&mut self, rec: u64) -> std::result::Result<(), String> {
        FaceSink::finish(self, rec)
    }
}

/// Collects faces into triangles, checking their indices.
pub(super) struct FaceSink {
    pub(super) n_vertices: u64,
    pub(super) triangles: Vec<[u32; 3]>,
    /// Corners of the face being read.
    pub(super) polygon: Vec<u32>,
}

impl FaceSink {
    /// Check one corner index (as read) of face `face`; the error message without location.
    pub(super) fn corner(&mut self, face: u64, v: f64) -> std::result::Result<(), String> {
        if !(v >= 0.0 && v < self.n_vertices as f64) {
            return Err(format!(
                "face {face}: vertex index {v} is out of range: the file has {} vertices",
                self.n_vertices
            ));
        }
        self.polygon.push(v as u32);
        Ok(())
    }

    /// Triangulate the face read since the last call.
    pub(super) fn finish(&mut self, face: u64) -> std::result::Result<(), String> {
        let p = &self.polygon;
        if p.len() < 3 {
            return Err(format!(
                "face {face} has {} vertices, expected at least 3",
                p.len()
            ));
        }
        for i in 1..p.len() - 1 {
            self.triangles.push([p[0], p[i], p[i + 1]]);
        }
        self.polygon.clear();
        Ok(())
    }
}

/// A buffered reader that knows its absolute byte position.
pub(super) struct Source<'a> {
    pub(super) path: &'a Path,
    pub(super) r: BufReader<File>,
    pub(super) pos: u64,
    pub(super) file_len: u64,
}

impl Source<'_> {
    pub(super) fn seek(&mut self, to: u64) -> Result<()> {
        self.r.seek(SeekFrom::Start(to)).with_path(self.path)?;
        self.pos = to;
        Ok(())
    }

    /// Skip `n` bytes known to lie within the file.
    pub(super) fn skip(&mut self, n: u64) -> Result<()> {
        let Ok(d) = i64::try_from(n) else {
            return self.seek(self.pos.saturating_add(n));
        };
        self.r.seek_relative(d).with_path(self.path)?;
        self.pos += n;
        Ok(())
    }

    /// True when `n` more bytes lie within the file.
    pub(super) fn has(&self, n: u64) -> bool {
        self.pos.checked_add(n).is_some_and(|e| e <= self.file_len)
    }

    /// Read one value of type `ty` known to lie within the file.
    pub(super) fn value(&mut self, ty: Scalar, be: bool) -> Result<f64> {
        let mut b = [0u8; 8];
        let n = ty.size();
        self.r.read_exact(&mut b[..n]).with_path(self.path)?;
        self.pos += n as u64;
        Ok(ty.read(&b, be))
    }

    /// Skip one line; false at the end of the file.
    pub(super) fn skip_line(&mut self) -> Result<bool> {
        let mut seen = 0u64;
        loop {
            let buf = self.r.fill_buf().with_path(self.path)?;
            if buf.is_empty() {
                self.pos += seen;
                return Ok(seen > 0);
            }
            match memchr::memchr(b'\n', buf) {
                Some(i) => {
                    self.r.consume(i + 1);
                    self.pos += seen + i as u64 + 1;
                    return Ok(true);
                }
                None => {
                    let l = buf.len();
                    self.r.consume(l);
                    seen += l as u64;
                }
            }
        }
    }

    /// Read one line into `line` (without the newline); false at the end of the file.
    pub(super) fn line(&mut self, line: &mut Vec<u8>) -> Result<bool> {
        line.clear();
        let n = self.r.read_until(b'\n', line).with_path(self.path)?;
        self.pos += n as u64;
        if line.last() == Some(&b'\n') {
            line.pop();
        }
        Ok(n > 0)
    }
}

/// Read `count` binary face records starting at the source's position.
pub(super) fn read_binary_faces(
    src: &mut Source<'_>,
    layout: &FaceLayout,
    count: u64,
    be: bool,
    faces: &mut impl ListSink,
) -> Result<()> {
    for face in 0..count {
        let start = src.pos;
        let truncated = |src: &Source<'_>| {
            Error::format(
                src.path,
                Location::Byte(start),
                format!(
                    "truncated: the header promises {count} {}, but the file ends at byte {} inside {} {face}",
                    layout.plural, src.file_len, layout.noun
                ),
            )
        };
        for (k, p) in layout.props.iter().enumerate() {
            match *p {
                Property::Scalar { ty, .. } => {
                    if !src.has(ty.size() as u64) {
                        return Err(truncated(src));
                    }
                    src.skip(ty.size() as u64)?;
                }
                Property::List {
                    count: cty, item, ..
                } => {
                    if !src.has(cty.size() as u64) {
                        return Err(truncated(src));
                    }
                    let n = src.value(cty, be)?;
                    if n < 0.0 {
                        return Err(Error::format(
                            src.path,
                            Location::Byte(start),
                            format!("{} {face} has a negative list length {n}", layout.noun),
                        ));
                    }
                    let n = n as u64;
                    let bytes = n.saturating_mul(item.size() as u64);
                    if !src.has(bytes) {
                        return Err(truncated(src));
                    }
                    if k == layout.indices {
                        for _ in 0..n {
                            let v = src.value(item, be)?;
                            faces
                                .corner(face, v)
                                .map_err(|m| Error::format(src.path, Location::Byte(start), m))?;
                        }
                    } else {
                        src.skip(bytes)?;
                    }
                }
            }
        }
        faces
            .finish(face)
            .map_err(|m| Error::format(src.path, Location::Byte(start), m))?;
    }
    Ok(())
}

/// Read `count` ascii face lines; `line` is the number of lines before the first one.
pub(super) fn read_ascii_faces(
    src: &mut Source<'_>,
    layout: &FaceLayout,
    count: u64,
    mut line: u64,
    faces: &mut impl ListSink,
) -> Result<()> {
    let mut text = Vec::new();
    for face in 0..count {
        line += 1;
        if !src.line(&mut text)? {
            return Err(Error::format(
                src.path,
                Location::Line(line),
                format!(
                    "truncated: the header promises {count} {}, but the file ends after {face} of them",
                    layout.plural
                ),
            ));
        }
        let at = Location::Line(line);
        let bad = |m: String| Error::format(src.path, at, m);
        let mut toks = text
            .split(|b| b.is_ascii_whitespace())
            .filter(|t| !t.is_empty());
        let int = |t: Option<&[u8]>, what: &str| -> Result<i64> {
            let Some(t) = t else {
                return Err(bad(format!(
                    "{} {face}: the line ends where {what} was expected",
                    layout.noun
                )));
            };
            std::str::from_utf8(t)
                .ok()
                .and_then(|s| s.parse::<i64>().ok())
                .ok_or_else(|| {
                    bad(format!(
                        "{} {face}: {what} \"{}\" is not an integer",
                        layout.noun,
                        String::from_utf8_lossy(t)
                    ))
                })
        };
        for (k, p) in layout.props.iter().enumerate() {
            match *p {
                Property::Scalar { .. } => {
                    // Skipped unparsed, but it must be there.
                    if toks.next().is_none() {
                        return Err(bad(format!(
                            "{} {face}: the line ends where property {} was expected",
                            layout.noun,
                            k + 1
                        )));
                    }
                }
                Property::List { .. } => {
                    let n = int(toks.next(), "a list length")?;
                    if n < 0 {
                        return Err(bad(format!(
                            "{} {face} has a negative list length {n}",
                            layout.noun
                        )));
                    }
                    if k == layout.indices {
                        for _ in 0..n {
                            let v = int(toks.next(), "a vertex index")?;
                            faces.corner(face, v as f64).map_err(bad)?;
                        }
                    } else {
                        for _ in 0..n {
                            if toks.next().is_none() {
                                return Err(bad(format!(
                                    "{} {face}: the line ends inside the list of property {}",
                                    layout.noun,
                                    k + 1
                                )));
                            }
                        }
                    }
                }
            }
        }
        if toks.next().is_some() {
            return Err(bad(format!(
                "{} {face}: the line has more values than its properties declare",
                layout.noun
            )));
        }
        faces.finish(face).map_err(bad)?;
    }
    Ok(())
}
