//! Lines and values of a text point file: the column layouts, the tokenizer, and the walk
//! over the lines through memory-mapped windows.

use std::fs::File;
use std::ops::ControlFlow;
use std::path::Path;

use crate::error::{Error, Location, Result};
use crate::fs::mmap::Window;
use crate::types::Attributes;

/// Bytes mapped at a time when scanning lines.
pub(super) const SCAN_WINDOW: u64 = 64 << 20;
/// A position is recorded every this many data lines.
pub(super) const INDEX_STEP: u64 = 1 << 16;
/// The most values a data line may hold.
pub(super) const MAX_COLUMNS: usize = 9;
/// The UTF-8 byte-order mark some editors write at the start of a text file.
pub(super) const BOM: &[u8] = b"\xEF\xBB\xBF";

/// The column layouts a data line may have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Layout {
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
    pub(super) fn from_columns(n: usize) -> Option<Layout> {
        Some(match n {
            3 => Layout::Xyz,
            4 => Layout::XyzI,
            6 => Layout::XyzN,
            7 => Layout::XyzIRgb,
            9 => Layout::XyzNRgb,
            _ => return None,
        })
    }

    pub(super) fn columns(self) -> usize {
        match self {
            Layout::Xyz => 3,
            Layout::XyzI => 4,
            Layout::XyzN => 6,
            Layout::XyzIRgb => 7,
            Layout::XyzNRgb => 9,
        }
    }

    /// Column of `nx`.
    pub(super) fn normal_at(self) -> Option<usize> {
        match self {
            Layout::XyzN | Layout::XyzNRgb => Some(3),
            _ => None,
        }
    }

    /// Column of the intensity.
    pub(super) fn intensity_at(self) -> Option<usize> {
        match self {
            Layout::XyzI | Layout::XyzIRgb => Some(3),
            _ => None,
        }
    }

    /// Column of `r`.
    pub(super) fn rgb_at(self) -> Option<usize> {
        match self {
            Layout::XyzIRgb => Some(4),
            Layout::XyzNRgb => Some(6),
            _ => None,
        }
    }

    pub(super) fn attributes(self) -> Attributes {
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
pub(super) struct Mark {
    pub(super) byte: u64,
    pub(super) line: u64,
    pub(super) index: u64,
}

/// The point count a PTS file declares on its first line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct PtsHeader {
    pub(super) count: u64,
    pub(super) line: u64,
}

#[inline]
pub(super) fn is_space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\r' | 0x0b | 0x0c)
}

/// True when the line holds a point: neither blank nor a `#` or `//` comment.
#[inline]
pub(super) fn is_data_line(line: &[u8]) -> bool {
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
pub(super) fn tokenize<'a>(
    line: &'a [u8],
    toks: &mut [&'a [u8]; MAX_COLUMNS],
) -> Result<usize, usize> {
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
pub(super) fn parse_number(tok: &[u8]) -> Option<f64> {
    std::str::from_utf8(tok).ok()?.parse::<f64>().ok()
}

/// A token for a message: quoted, escaped, and cut short when long.
pub(super) fn show(tok: &[u8]) -> String {
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
pub(super) fn color16(v: f64) -> Option<u16> {
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
pub(super) fn scan_lines(
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
pub(super) struct FirstLine {
    pub(super) mark: Mark,
    /// Bytes of the line, without the `\n`.
    pub(super) len: u64,
    /// Number of values, or the 1-based column of an empty value.
    pub(super) values: Result<usize, usize>,
    /// The line's value when it is a single non-negative integer (a PTS point count).
    pub(super) single_integer: Option<u64>,
}

pub(super) fn empty_value(path: &Path, line: u64, col: usize) -> Error {
    Error::format(
        path,
        Location::Line(line),
        format!("column {col} is empty, expected a number (between commas)"),
    )
}

/// Scan from `from` for the first data line and describe it.
pub(super) fn find_first_line(
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

#[cfg(test)]
mod tests {
    use super::*;

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
