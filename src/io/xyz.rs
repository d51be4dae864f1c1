//! XYZ / PTS text point reader: one point a line.
//!
//! Values are separated by spaces, tabs or commas. The number of values on the first data line
//! decides the layout, and every data line must have as many:
//!
//! | values | layout                                        |
//! |--------|-----------------------------------------------|
//! | 3      | `x y z`                                       |
//! | 4      | `x y z intensity`                             |
//! | 6      | `x y z nx ny nz`                              |
//! | 7      | `x y z intensity r g b` (Leica PTS)           |
//! | 9      | `x y z nx ny nz r g b`                        |
//!
//! Colours are integers 0..255, stored as 16-bit (×257) with an opaque alpha. Blank lines and
//! lines starting with `#` or `//` are skipped; lines may end in `\r\n`; a UTF-8 byte-order mark
//! at the start of the file is ignored. A PTS file may start with a line holding a single
//! integer, the number of points: it is skipped, and [`PointReader::chunks`] fails when the
//! file holds a different number of data lines.
//!
//! Opening counts the data lines in one pass over memory-mapped windows of 64 MiB (each
//! unmapped before the next), recording the position of every 65 536th data line. Chunks are
//! cut at those positions, so [`PointReader::chunks`] reads nothing more unless asked for
//! chunks smaller than the index step. Memory stays bounded for text files of any size.

use std::fs::File;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use crate::error::{Error, IoContext, Location, Result};
use crate::io::mmap::Window;
use crate::io::{ChunkSpec, ChunkStats, Format, PointReader, non_finite_axis, non_finite_msg};
use crate::types::{Attributes, PointBatch};

/// Bytes mapped at a time when scanning lines.
const SCAN_WINDOW: u64 = 64 << 20;
/// A position is recorded every this many data lines.
const INDEX_STEP: u64 = 1 << 16;
/// The most values a data line may hold.
const MAX_COLUMNS: usize = 9;
/// The UTF-8 byte-order mark some editors write at the start of a text file.
const BOM: &[u8] = b"\xEF\xBB\xBF";

/// The column layouts a data line may have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Layout {
    /// `x y z`
    Xyz,
    /// `x y z intensity`
    XyzI,
    /// `x y z nx ny nz`
    XyzN,
    /// `x y z intensity r g b`
    XyzIRgb,
    /// `x y z nx ny nz r g b`
    XyzNRgb,
}

impl Layout {
    fn from_columns(n: usize) -> Option<Layout> {
        Some(match n {
            3 => Layout::Xyz,
            4 => Layout::XyzI,
            6 => Layout::XyzN,
            7 => Layout::XyzIRgb,
            9 => Layout::XyzNRgb,
            _ => return None,
        })
    }

    fn columns(self) -> usize {
        match self {
            Layout::Xyz => 3,
            Layout::XyzI => 4,
            Layout::XyzN => 6,
            Layout::XyzIRgb => 7,
            Layout::XyzNRgb => 9,
        }
    }

    /// Column of `nx`.
    fn normal_at(self) -> Option<usize> {
        match self {
            Layout::XyzN | Layout::XyzNRgb => Some(3),
            _ => None,
        }
    }

    /// Column of the intensity.
    fn intensity_at(self) -> Option<usize> {
        match self {
            Layout::XyzI | Layout::XyzIRgb => Some(3),
            _ => None,
        }
    }

    /// Column of `r`.
    fn rgb_at(self) -> Option<usize> {
        match self {
            Layout::XyzIRgb => Some(4),
            Layout::XyzNRgb => Some(6),
            _ => None,
        }
    }

    fn attributes(self) -> Attributes {
        Attributes {
            normal: self.normal_at().is_some(),
            color: self.rgb_at().is_some(),
            alpha: false,
            intensity: self.intensity_at().is_some(),
            confidence: false,
            source: false,
        }
    }
}

/// A line start: byte offset, 1-based line number, and the number of data lines before it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Mark {
    byte: u64,
    line: u64,
    index: u64,
}

/// The point count a PTS file declares on its first line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct PtsHeader {
    count: u64,
    line: u64,
}

#[inline]
fn is_space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\r' | 0x0b | 0x0c)
}

/// True when the line holds a point: neither blank nor a `#` or `//` comment.
#[inline]
fn is_data_line(line: &[u8]) -> bool {
    match line.iter().position(|&b| !is_space(b)) {
        None => false,
        Some(i) => match line[i] {
            b'#' => false,
            b'/' => line.get(i + 1) != Some(&b'/'),
            _ => true,
        },
    }
}

/// Split a data line into values separated by blanks and/or one comma. Fills `toks` with the
/// first [`MAX_COLUMNS`] values and returns how many there are in all; a trailing comma is
/// allowed. An empty value (a leading comma, or two commas in a row) is `Err(column)`, 1-based.
fn tokenize<'a>(line: &'a [u8], toks: &mut [&'a [u8]; MAX_COLUMNS]) -> Result<usize, usize> {
    let len = line.len();
    let mut i = 0;
    let mut n = 0usize;
    while i < len && is_space(line[i]) {
        i += 1;
    }
    if i < len && line[i] == b',' {
        return Err(1);
    }
    while i < len {
        let start = i;
        while i < len && !is_space(line[i]) && line[i] != b',' {
            i += 1;
        }
        if let Some(slot) = toks.get_mut(n) {
            *slot = &line[start..i];
        }
        n += 1;
        while i < len && is_space(line[i]) {
            i += 1;
        }
        if i < len && line[i] == b',' {
            i += 1;
            while i < len && is_space(line[i]) {
                i += 1;
            }
            if i < len && line[i] == b',' {
                return Err(n + 1);
            }
        }
    }
    Ok(n)
}

#[inline]
fn parse_number(tok: &[u8]) -> Option<f64> {
    std::str::from_utf8(tok).ok()?.parse::<f64>().ok()
}

/// A token for a message: quoted, escaped, and cut short when long.
fn show(tok: &[u8]) -> String {
    const MAX: usize = 40;
    let s = String::from_utf8_lossy(tok);
    let mut out = String::from("\"");
    for (k, c) in s.chars().enumerate() {
        if k == MAX {
            out.push('…');
            break;
        }
        out.extend(c.escape_debug());
    }
    out.push('"');
    out
}

/// An 8-bit colour value as 16 bits, or `None` when it is not an integer 0..255.
#[inline]
fn color16(v: f64) -> Option<u16> {
    if (0.0..=255.0).contains(&v) && v.fract() == 0.0 {
        Some(v as u16 * 257)
    } else {
        None
    }
}

/// Walk the lines starting at `from` (a line start) up to byte `end` (a line start or the end
/// of the file), mapping `window` bytes at a time. `on_data` sees every data line with its
/// mark and bytes (without the `\n`); when it breaks, the walk stops there and returns that
/// line's mark. Otherwise the walk returns the mark just past the last line.
fn scan_lines(
    file: &File,
    path: &Path,
    window: u64,
    from: Mark,
    end: u64,
    mut on_data: impl FnMut(Mark, &[u8]) -> Result<ControlFlow<()>>,
) -> Result<Mark> {
    let mut cur = from;
    while cur.byte < end {
        let win_end = end.min(cur.byte.saturating_add(window));
        let win = Window::map(file, path, cur.byte, win_end)?;
        let mut off = 0usize;
        while off < win.len() {
            let rest = &win[off..];
            let (line, step) = match memchr::memchr(b'\n', rest) {
                Some(nl) => (&rest[..nl], nl + 1),
                None if win_end < end => {
                    if off == 0 {
                        return Err(Error::format(
                            path,
                            Location::Line(cur.line),
                            format!(
                                "line is longer than {window} bytes, expected one point per line"
                            ),
                        ));
                    }
                    // The line goes on past this window: the next window starts with it.
                    break;
                }
                None => (rest, rest.len()),
            };
            let here = Mark {
                byte: cur.byte + off as u64,
                ..cur
            };
            if is_data_line(line) {
                if on_data(here, line)?.is_break() {
                    return Ok(here);
                }
                cur.index += 1;
            }
            cur.line += 1;
            off += step;
        }
        cur.byte += off as u64;
    }
    Ok(cur)
}

/// What open learns from one line while scanning for the first data line.
struct FirstLine {
    mark: Mark,
    /// Bytes of the line, without the `\n`.
    len: u64,
    /// Number of values, or the 1-based column of an empty value.
    values: Result<usize, usize>,
    /// The line's value when it is a single non-negative integer (a PTS point count).
    single_integer: Option<u64>,
}

/// A text point file (XYZ, PTS) opened for reading.
pub struct XyzReader {
    path: PathBuf,
    file: File,
    file_len: u64,
    window: u64,
    layout: Layout,
    header: Option<PtsHeader>,
    /// Marks of data lines 0, [`INDEX_STEP`], 2·[`INDEX_STEP`]…, then the mark past the last
    /// line (its `index` is the number of points). Never empty: open fails without points.
    index: Vec<Mark>,
}

impl XyzReader {
    /// Open a text point file: find the first data line and the column layout, then count
    /// the data lines in one pass over the file.
    pub fn open(path: &Path) -> Result<XyzReader> {
        XyzReader::open_with_window(path, SCAN_WINDOW)
    }

    fn open_with_window(path: &Path, window: u64) -> Result<XyzReader> {
        let file = File::open(path).with_path(path)?;
        let meta = file.metadata().with_path(path)?;
        if meta.is_dir() {
            return Err(Error::input(path, "is a directory, expected a point file"));
        }
        let file_len = meta.len();
        if file_len == 0 {
            return Err(Error::input(path, "no points: the file is empty (0 bytes)"));
        }
        let head = Window::map(&file, path, 0, file_len.min(BOM.len() as u64))?;
        let start = Mark {
            byte: if head.starts_with(BOM) {
                BOM.len() as u64
            } else {
                0
            },
            line: 1,
            index: 0,
        };
        drop(head);

        let first = find_first_line(&file, path, window, start, file_len)?;
        let Some(first) = first else {
            return Err(Error::input(
                path,
                "no points: the file holds only blank lines and comments",
            ));
        };
        let (header, data) = match first.single_integer {
            Some(count) => {
                let next = Mark {
                    byte: (first.mark.byte + first.len + 1).min(file_len),
                    line: first.mark.line + 1,
                    index: 0,
                };
                match find_first_line(&file, path, window, next, file_len)? {
                    Some(data) => (
                        Some(PtsHeader {
                            count,
                            line: first.mark.line,
                        }),
                        data,
                    ),
                    None => {
                        return Err(Error::input(
                            path,
                            format!(
                                "no points: the PTS header on line {} declares {count} points, but no data line follows",
                                first.mark.line
                            ),
                        ));
                    }
                }
            }
            None => (None, first),
        };
        let line = data.mark.line;
        let n = data.values.map_err(|col| empty_value(path, line, col))?;
        let layout = Layout::from_columns(n).ok_or_else(|| {
            Error::format(
                path,
                Location::Line(line),
                format!(
                    "expected 3, 4, 6, 7 or 9 numbers (x y z [intensity | nx ny nz] [r g b]), found {n}"
                ),
            )
        })?;

        let mut index = Vec::new();
        let end = scan_lines(&file, path, window, data.mark, file_len, |m, _| {
            if m.index % INDEX_STEP == 0 {
                index.push(m);
            }
            Ok(ControlFlow::Continue(()))
        })?;
        index.push(end);
        Ok(XyzReader {
            path: path.to_path_buf(),
            file,
            file_len,
            window,
            layout,
            header,
            index,
        })
    }

    /// Number of values per data line (3, 4, 6, 7 or 9).
    pub fn columns(&self) -> usize {
        self.layout.columns()
    }

    /// The point count declared by a PTS header line, when the file has one.
    pub fn header_count(&self) -> Option<u64> {
        self.header.map(|h| h.count)
    }

    /// The mark past the last line; its `index` is the number of points.
    fn end_mark(&self) -> Mark {
        self.index.last().copied().unwrap_or(Mark {
            byte: self.file_len,
            line: 1,
            index: 0,
        })
    }

    /// Fail when the file is no longer as long as it was when opened (reading a mapping past
    /// the end of a file is a bus error, not an error value).
    fn check_unchanged(&self) -> Result<()> {
        let now = self.file.metadata().with_path(&self.path)?.len();
        if now != self.file_len {
            return Err(Error::input(
                &self.path,
                format!(
                    "the file changed while being read: it was {} bytes when opened, it is {now} bytes now",
                    self.file_len
                ),
            ));
        }
        Ok(())
    }

    fn parse_error(&self, line: u64, msg: String) -> Error {
        Error::format(&self.path, Location::Line(line), msg)
    }
}

fn empty_value(path: &Path, line: u64, col: usize) -> Error {
    Error::format(
        path,
        Location::Line(line),
        format!("column {col} is empty, expected a number (between commas)"),
    )
}

/// Scan from `from` for the first data line and describe it.
fn find_first_line(
    file: &File,
    path: &Path,
    window: u64,
    from: Mark,
    end: u64,
) -> Result<Option<FirstLine>> {
    let mut found = None;
    scan_lines(file, path, window, from, end, |mark, line| {
        let mut toks: [&[u8]; MAX_COLUMNS] = [&[]; MAX_COLUMNS];
        let values = tokenize(line, &mut toks);
        let single_integer = match values {
            Ok(1) if toks[0].iter().all(u8::is_ascii_digit) => std::str::from_utf8(toks[0])
                .ok()
                .and_then(|s| s.parse::<u64>().ok()),
            _ => None,
        };
        found = Some(FirstLine {
            mark,
            len: line.len() as u64,
            values,
            single_integer,
        });
        Ok(ControlFlow::Break(()))
    })?;
    Ok(found)
}

impl PointReader for XyzReader {
    fn path(&self) -> &Path {
        &self.path
    }

    fn format(&self) -> Format {
        Format::Xyz
    }

    fn attributes(&self) -> Attributes {
        self.layout.attributes()
    }

    fn len(&self) -> u64 {
        self.end_mark().index
    }

    fn chunks(&self, target_points: u64) -> Result<Vec<ChunkSpec>> {
        let target = target_points.max(1);
        let Some((&end, steps)) = self.index.split_last() else {
            return Ok(Vec::new());
        };
        let Some(&first) = steps.first() else {
            return Ok(Vec::new());
        };
        let marks: Vec<Mark> = if target >= INDEX_STEP {
            // Whole index steps: nothing to read.
            let per_chunk = target.saturating_add(INDEX_STEP / 2) / INDEX_STEP;
            let per_chunk = usize::try_from(per_chunk.max(1)).unwrap_or(usize::MAX);
            let mut m: Vec<Mark> = steps.iter().step_by(per_chunk).copied().collect();
            m.push(end);
            m
        } else {
            // Finer than the index: walk the lines once more.
            self.check_unchanged()?;
            let mut m = Vec::with_capacity(usize::try_from(end.index / target + 2).unwrap_or(0));
            let past = scan_lines(
                &self.file,
                &self.path,
                self.window,
                first,
                self.file_len,
                |mark, _| {
                    if mark.index % target == 0 {
                        m.push(mark);
                    }
                    Ok(ControlFlow::Continue(()))
                },
            )?;
            if past != end {
                return Err(Error::input(
                    &self.path,
                    format!(
                        "the file changed while being read: it held {} data lines when opened, it holds {} now",
                        end.index, past.index
                    ),
                ));
            }
            m.push(end);
            m
        };
        let chunks = marks
            .windows(2)
            .filter(|w| w[1].index > w[0].index)
            .map(|w| ChunkSpec {
                byte_start: w[0].byte,
                byte_end: w[1].byte,
                first_index: w[0].index,
                count: w[1].index - w[0].index,
                first_line: w[0].line,
            })
            .collect();
        if let Some(h) = self.header
            && h.count != end.index
        {
            return Err(Error::format(
                &self.path,
                Location::Line(h.line),
                format!(
                    "the PTS header declares {} points, but the file holds {} data lines",
                    h.count, end.index
                ),
            ));
        }
        Ok(chunks)
    }

    fn read_chunk(
        &self,
        chunk: &ChunkSpec,
        skip_invalid: bool,
        out: &mut PointBatch,
    ) -> Result<ChunkStats> {
        let mut stats = ChunkStats::default();
        if chunk.count == 0 {
            return Ok(stats);
        }
        if chunk.byte_end > self.file_len || chunk.byte_start > chunk.byte_end {
            return Err(Error::Internal(format!(
                "{}: chunk bytes {}..{} are not within the file ({} bytes)",
                self.path.display(),
                chunk.byte_start,
                chunk.byte_end,
                self.file_len
            )));
        }
        self.check_unchanged()?;
        let win = Window::map(&self.file, &self.path, chunk.byte_start, chunk.byte_end)?;
        let layout = self.layout;
        let cols = layout.columns();
        let first_data_line = self.index.first().map_or(1, |m| m.line);
        let reserve = usize::try_from(chunk.count).unwrap_or(0);
        out.pos.reserve(reserve);
        if layout.normal_at().is_some() {
            out.normal.reserve(reserve);
        }
        if layout.rgb_at().is_some() {
            out.color.reserve(reserve);
        }
        if layout.intensity_at().is_some() {
            out.intensity.reserve(reserve);
        }

        let mut toks: [&[u8]; MAX_COLUMNS] = [&[]; MAX_COLUMNS];
        let mut vals = [0f64; MAX_COLUMNS];
        let mut rest: &[u8] = &win;
        let mut line_no = chunk.first_line;
        let mut index = chunk.first_index;
        let end_index = chunk.first_index.saturating_add(chunk.count);
        while index < end_index {
            if rest.is_empty() {
                return Err(Error::format(
                    &self.path,
                    Location::Line(line_no),
                    format!(
                        "expected {} data lines from line {}, found {} (did the file change?)",
                        chunk.count,
                        chunk.first_line,
                        index - chunk.first_index
                    ),
                ));
            }
            let (line, tail) = match memchr::memchr(b'\n', rest) {
                Some(nl) => (&rest[..nl], &rest[nl + 1..]),
                None => (rest, &rest[rest.len()..]),
            };
            rest = tail;
            let this_line = line_no;
            line_no += 1;
            if !is_data_line(line) {
                continue;
            }
            let n =
                tokenize(line, &mut toks).map_err(|col| empty_value(&self.path, this_line, col))?;
            if n != cols {
                return Err(self.parse_error(
                    this_line,
                    format!("expected {cols} numbers as on line {first_data_line}, found {n}"),
                ));
            }
            for (k, (v, tok)) in vals.iter_mut().zip(&toks).take(cols).enumerate() {
                *v = parse_number(tok).ok_or_else(|| {
                    self.parse_error(
                        this_line,
                        format!("column {} {} is not a number", k + 1, show(tok)),
                    )
                })?;
            }
            let color = match layout.rgb_at() {
                Some(at) => {
                    let mut c = [u16::MAX; 4];
                    for (j, name) in ["red", "green", "blue"].into_iter().enumerate() {
                        let v = vals[at + j];
                        c[j] = color16(v).ok_or_else(|| {
                            Error::format(
                                &self.path,
                                Location::ElementLine {
                                    index,
                                    line: this_line,
                                },
                                format!(
                                    "column {} ({name}) is {}, expected an integer 0..255",
                                    at + j + 1,
                                    show(toks[at + j])
                                ),
                            )
                        })?;
                    }
                    Some(c)
                }
                None => None,
            };
            let p = [vals[0], vals[1], vals[2]];
            if let Some(axis) = non_finite_axis(p) {
                if skip_invalid {
                    stats.skipped_invalid += 1;
                    index += 1;
                    continue;
                }
                let v = match axis {
                    "x" => p[0],
                    "y" => p[1],
                    _ => p[2],
                };
                return Err(Error::format(
                    &self.path,
                    Location::ElementLine {
                        index,
                        line: this_line,
                    },
                    non_finite_msg(axis, v),
                ));
            }
            out.pos.push(p);
            if let Some(at) = layout.normal_at() {
                out.normal
                    .push([vals[at] as f32, vals[at + 1] as f32, vals[at + 2] as f32]);
            }
            if let Some(c) = color {
                out.color.push(c);
            }
            if let Some(at) = layout.intensity_at() {
                out.intensity.push(vals[at] as f32);
            }
            index += 1;
        }
        Ok(stats)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    fn read_all(r: &dyn PointReader, target: u64) -> PointBatch {
        let mut b = PointBatch::default();
        for c in r.chunks(target).unwrap() {
            r.read_chunk(&c, false, &mut b).unwrap();
        }
        b
    }

    fn open_err(p: &Path) -> String {
        match XyzReader::open(p) {
            Ok(_) => panic!("{} opened", p.display()),
            Err(e) => e.to_string(),
        }
    }

    /// The error of reading the whole file in one chunk.
    fn read_err(r: &XyzReader) -> String {
        let c = r.chunks(u64::MAX).unwrap();
        let mut b = PointBatch::default();
        match c
            .iter()
            .try_for_each(|c| r.read_chunk(c, false, &mut b).map(drop))
        {
            Ok(()) => panic!("read succeeded"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn three_columns_mixed_separators() {
        let d = tempfile::tempdir().unwrap();
        let p = write(
            d.path(),
            "a.xyz",
            "1 2 3\n4\t5\t6\n7,8,9\n10, 11 ,12,\n-1e3 .5 +2.\n",
        );
        let r = XyzReader::open(&p).unwrap();
        assert_eq!((r.len(), r.columns(), r.format()), (5, 3, Format::Xyz));
        assert_eq!(r.attributes(), Attributes::default());
        let b = read_all(&r, 100);
        assert_eq!(
            b.pos,
            vec![
                [1.0, 2.0, 3.0],
                [4.0, 5.0, 6.0],
                [7.0, 8.0, 9.0],
                [10.0, 11.0, 12.0],
                [-1000.0, 0.5, 2.0]
            ]
        );
        assert!(b.normal.is_empty() && b.color.is_empty() && b.intensity.is_empty());
    }

    #[test]
    fn four_columns_intensity() {
        let d = tempfile::tempdir().unwrap();
        let p = write(d.path(), "i.xyz", "0 0 0 0.5\n1 1 1 -7\n");
        let r = XyzReader::open(&p).unwrap();
        assert!(r.attributes().intensity && !r.attributes().color);
        let b = read_all(&r, 10);
        assert_eq!(b.intensity, vec![0.5, -7.0]);
    }

    #[test]
    fn six_columns_normals() {
        let d = tempfile::tempdir().unwrap();
        let p = write(d.path(), "n.xyz", "1 2 3 0 0 1\n4 5 6 0 1 0\n");
        let r = XyzReader::open(&p).unwrap();
        let a = r.attributes();
        assert!(a.normal && !a.color && !a.intensity);
        let b = read_all(&r, 10);
        assert_eq!(b.pos[1], [4.0, 5.0, 6.0]);
        assert_eq!(b.normal, vec![[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]);
    }

    #[test]
    fn seven_columns_pts_with_header() {
        let d = tempfile::tempdir().unwrap();
        let p = write(
            d.path(),
            "s.pts",
            "3\n1 2 3 -1200 255 0 128\n4 5 6 17 1 2 3\n7 8 9 0 0 0 0\n",
        );
        let r = XyzReader::open(&p).unwrap();
        assert_eq!((r.len(), r.header_count()), (3, Some(3)));
        let a = r.attributes();
        assert!(a.color && a.intensity && !a.normal && !a.alpha);
        let c = r.chunks(10).unwrap();
        assert_eq!(c.len(), 1);
        assert_eq!((c[0].first_line, c[0].first_index, c[0].count), (2, 0, 3));
        let b = read_all(&r, 10);
        assert_eq!(b.pos[0], [1.0, 2.0, 3.0]);
        assert_eq!(b.intensity, vec![-1200.0, 17.0, 0.0]);
        assert_eq!(b.color[0], [65535, 0, 128 * 257, 65535]);
        assert_eq!(b.color[1], [257, 514, 771, 65535]);
    }

    #[test]
    fn nine_columns_normals_and_colour() {
        let d = tempfile::tempdir().unwrap();
        let p = write(d.path(), "c.xyz", "1 2 3 0 0 1 10 20 30\n");
        let r = XyzReader::open(&p).unwrap();
        let a = r.attributes();
        assert!(a.color && a.normal && !a.intensity);
        let b = read_all(&r, 1);
        assert_eq!(b.normal, vec![[0.0, 0.0, 1.0]]);
        assert_eq!(b.color, vec![[2570, 5140, 7710, 65535]]);
    }

    #[test]
    fn pts_header_mismatch_names_its_line() {
        let d = tempfile::tempdir().unwrap();
        let p = write(d.path(), "m.pts", "5\n1 2 3 4 5 6 7\n1 2 3 4 5 6 7\n");
        let r = XyzReader::open(&p).unwrap();
        assert_eq!(r.len(), 2);
        let e = r.chunks(100).unwrap_err().to_string();
        assert!(
            e.contains("m.pts: line 1:")
                && e.contains("declares 5 points")
                && e.contains("holds 2"),
            "{e}"
        );
        // Also when cutting chunks finer than the index.
        assert!(r.chunks(1).is_err());
    }

    #[test]
    fn pts_header_without_data() {
        let d = tempfile::tempdir().unwrap();
        let p = write(d.path(), "h.pts", "12\n\n# nothing\n");
        let e = open_err(&p);
        assert!(e.contains("no points") && e.contains("declares 12"), "{e}");
    }

    #[test]
    fn comments_blank_lines_and_crlf() {
        let d = tempfile::tempdir().unwrap();
        let text = "\u{feff}# exported\r\n// by hand\r\n\r\n   \r\n1 2 3\r\n  # inner\r\n\t\r\n4 5 6\r\n// end\r\n7 8 9";
        let p = write(d.path(), "c.xyz", text);
        let r = XyzReader::open(&p).unwrap();
        assert_eq!(r.len(), 3);
        let c = r.chunks(1).unwrap();
        let got: Vec<_> = c
            .iter()
            .map(|c| (c.first_line, c.first_index, c.count))
            .collect();
        assert_eq!(got, vec![(5, 0, 1), (8, 1, 1), (10, 2, 1)]);
        let b = read_all(&r, 1);
        assert_eq!(
            b.pos,
            vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]]
        );
        assert_eq!(read_all(&r, 100), b);
    }

    #[test]
    fn nan_names_element_and_line() {
        let d = tempfile::tempdir().unwrap();
        let p = write(d.path(), "n.xyz", "# c\n0 0 0\n\n1 nan 1\n2 2 inf\n3 3 3\n");
        let r = XyzReader::open(&p).unwrap();
        let e = read_err(&r);
        assert!(e.contains("n.xyz: element 1 (line 4): y is NaN"), "{e}");
        // In a later chunk, the element index and line are still absolute.
        let c = r.chunks(2).unwrap();
        assert_eq!(c.len(), 2);
        let mut b = PointBatch::default();
        let e = r.read_chunk(&c[1], false, &mut b).unwrap_err().to_string();
        assert!(e.contains("element 2 (line 5): z is inf"), "{e}");
        let mut b = PointBatch::default();
        let mut skipped = 0;
        for c in &c {
            skipped += r.read_chunk(c, true, &mut b).unwrap().skipped_invalid;
        }
        assert_eq!(skipped, 2);
        assert_eq!(b.pos, vec![[0.0, 0.0, 0.0], [3.0, 3.0, 3.0]]);
    }

    #[test]
    fn wrong_column_count_names_the_line() {
        let d = tempfile::tempdir().unwrap();
        let p = write(d.path(), "w.xyz", "1 2 3\n4 5 6\n\n7 8 9 10\n");
        let r = XyzReader::open(&p).unwrap();
        let e = read_err(&r);
        assert!(
            e.contains("w.xyz: line 4: expected 3 numbers as on line 1, found 4"),
            "{e}"
        );
        let p = write(d.path(), "f.xyz", "# hi\n1 2 3 4 5\n");
        let e = open_err(&p);
        assert!(e.contains("line 2: expected 3, 4, 6, 7 or 9 numbers") && e.contains("found 5"));
        let p = write(d.path(), "g.xyz", "1.5\n1 2 3\n");
        let e = open_err(&p);
        assert!(
            e.contains("line 1: expected 3, 4, 6") && e.contains("found 1"),
            "{e}"
        );
    }

    #[test]
    fn syntax_errors() {
        let d = tempfile::tempdir().unwrap();
        let cases: &[(&str, &str)] = &[
            (
                "1 2 3\n1 abc 3\n",
                "line 2: column 2 \"abc\" is not a number",
            ),
            ("1 2 3\n1,,3\n", "line 2: column 2 is empty"),
            (",1,2,3\n", "line 1: column 1 is empty"),
            (
                "1 2 3 4 5 256 7\n",
                "element 0 (line 1): column 6 (green) is \"256\"",
            ),
            (
                "1 2 3 4 5 6 -1\n",
                "column 7 (blue) is \"-1\", expected an integer 0..255",
            ),
            ("1 2 3 4 5.5 6 7\n", "column 5 (red) is \"5.5\""),
            ("1 2 3 4 nan 6 7\n", "column 5 (red) is \"nan\""),
            (
                "1 2 \u{e9}\n",
                "line 1: column 3 \"\u{e9}\" is not a number",
            ),
            ("1 2 3\n1 2 0x10\n", "column 3 \"0x10\" is not a number"),
        ];
        for (text, want) in cases {
            let p = write(d.path(), "s.xyz", text);
            let e = match XyzReader::open(&p) {
                Err(e) => e.to_string(),
                Ok(r) => read_err(&r),
            };
            assert!(e.contains(want) && e.contains("s.xyz"), "{text:?}: {e}");
        }
    }

    #[test]
    fn small_chunks_equal_whole_read() {
        let d = tempfile::tempdir().unwrap();
        let mut s = String::from("# header comment\n");
        for i in 0..100 {
            s += &format!("{i} {}.25 {} 0 0 1 {} 7 9\r\n", i * 2, -i, i % 256);
            if i % 13 == 0 {
                s += "\n// gap\n";
            }
        }
        let p = write(d.path(), "big.xyz", &s);
        let r = XyzReader::open(&p).unwrap();
        assert_eq!(r.len(), 100);
        let whole = read_all(&r, u64::MAX);
        assert_eq!(whole.len(), 100);
        assert_eq!(whole.pos[99], [99.0, 198.25, -99.0]);
        let c = r.chunks(7).unwrap();
        assert_eq!(c.len(), 15);
        let mut next = 0;
        for c in &c {
            assert_eq!(c.first_index, next);
            assert!(c.count == 7 || c.first_index == 98);
            next += c.count;
        }
        assert_eq!(next, 100);
        assert_eq!(read_all(&r, 7), whole);
        for w in c.windows(2) {
            assert_eq!(w[0].byte_end, w[1].byte_start);
        }
    }

    #[test]
    fn tiny_windows_cross_line_boundaries() {
        let d = tempfile::tempdir().unwrap();
        let mut s = String::from("7\n");
        for i in 0..7 {
            s += &format!("# comment {i}\n{i}.5 {i} {i}\n");
        }
        let p = write(d.path(), "t.xyz", &s);
        let whole = read_all(&XyzReader::open(&p).unwrap(), 1000);
        for window in [20, 23, 64] {
            let r = XyzReader::open_with_window(&p, window).unwrap();
            assert_eq!(r.len(), 7);
            for target in [1, 2, 3, 7, 100] {
                assert_eq!(
                    read_all(&r, target),
                    whole,
                    "window {window} target {target}"
                );
            }
        }
        let e = XyzReader::open_with_window(&p, 8)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("longer than 8 bytes"), "{e}");
    }

    #[test]
    fn index_steps_make_chunks_without_rereading() {
        let d = tempfile::tempdir().unwrap();
        let n = INDEX_STEP * 2 + 10;
        let mut s = String::with_capacity(n as usize * 8);
        for i in 0..n {
            s += &format!("{i} 0 1\n");
        }
        let p = write(d.path(), "s.xyz", &s);
        let r = XyzReader::open(&p).unwrap();
        assert_eq!(r.len(), n);
        let c = r.chunks(INDEX_STEP).unwrap();
        let counts: Vec<_> = c.iter().map(|c| c.count).collect();
        assert_eq!(counts, vec![INDEX_STEP, INDEX_STEP, 10]);
        assert_eq!(c[1].first_line, INDEX_STEP + 1);
        let b = read_all(&r, INDEX_STEP * 3);
        assert_eq!(b.len() as u64, n);
        assert_eq!(b.pos[INDEX_STEP as usize], [INDEX_STEP as f64, 0.0, 1.0]);
        assert_eq!(read_all(&r, 50_000), b);
    }

    #[test]
    fn empty_and_comment_only_files() {
        let d = tempfile::tempdir().unwrap();
        let p = write(d.path(), "e.xyz", "");
        let e = open_err(&p);
        assert!(e.contains("e.xyz") && e.contains("no points"), "{e}");
        let p = write(d.path(), "c.xyz", "# a\n\n// b\r\n   \n");
        let e = open_err(&p);
        assert!(e.contains("c.xyz") && e.contains("no points"), "{e}");
    }

    #[test]
    fn opened_through_io_open() {
        let d = tempfile::tempdir().unwrap();
        let p = write(d.path(), "o.pts", "1\n1 2 3\n");
        let r = crate::io::open(&p).unwrap();
        assert_eq!((r.format(), r.len()), (Format::Xyz, 1));
    }

    #[test]
    fn tokenizer() {
        let mut t: [&[u8]; MAX_COLUMNS] = [&[]; MAX_COLUMNS];
        assert_eq!(tokenize(b"  1 ,2\t, 3 ,\r", &mut t), Ok(3));
        assert_eq!(&t[..3], &[b"1" as &[u8], b"2", b"3"]);
        assert_eq!(tokenize(b"1 2 3 4 5 6 7 8 9 10 11", &mut t), Ok(11));
        assert_eq!(tokenize(b"1, ,2", &mut t), Err(2));
        assert_eq!(tokenize(b"", &mut t), Ok(0));
        assert!(!is_data_line(b" \t\r"));
        assert!(!is_data_line(b"  // x"));
        assert!(!is_data_line(b"#"));
        assert!(is_data_line(b"/1 2 3"));
    }
}
