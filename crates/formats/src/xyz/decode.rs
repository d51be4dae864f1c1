//! Decoding the data lines of a chunk into points.

use super::XyzReader;
use super::text::{
    Layout, MAX_COLUMNS, color16, empty_value, is_data_line, parse_number, show, tokenize,
};
use crate::error::{Error, Location, Result};
use crate::fs::mmap::Window;
use crate::types::PointBatch;
use crate::{ChunkSpec, ChunkStats, invalid_point_msg};

impl XyzReader {
    /// Decode the data lines of `chunk` into `out`; see [`crate::PointReader::read_chunk`].
    pub(super) fn read_records(
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
        reserve(out, layout, usize::try_from(chunk.count).unwrap_or(0));

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
                Some(at) => Some(self.color(&vals, &toks, at, index, this_line)?),
                None => None,
            };
            let p = [vals[0], vals[1], vals[2]];
            let normal = layout
                .normal_at()
                .filter(|_| !self.ignore_normals)
                .map(|at| [vals[at], vals[at + 1], vals[at + 2]]);
            if let Some(msg) = invalid_point_msg(p, normal) {
                if skip_invalid {
                    stats.skipped_invalid += 1;
                    index += 1;
                    continue;
                }
                return Err(Error::format(
                    &self.path,
                    Location::ElementLine {
                        index,
                        line: this_line,
                    },
                    msg,
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

    /// The colour in columns `at..at + 3` of point `index` (line `line`), 16-bit with an
    /// opaque alpha.
    fn color(
        &self,
        vals: &[f64; MAX_COLUMNS],
        toks: &[&[u8]; MAX_COLUMNS],
        at: usize,
        index: u64,
        line: u64,
    ) -> Result<[u16; 4]> {
        let mut c = [u16::MAX; 4];
        for (j, name) in ["red", "green", "blue"].into_iter().enumerate() {
            let v = vals[at + j];
            c[j] = color16(v).ok_or_else(|| {
                Error::format(
                    &self.path,
                    Location::ElementLine { index, line },
                    format!(
                        "column {} ({name}) is {}, expected an integer 0..255",
                        at + j + 1,
                        show(toks[at + j])
                    ),
                )
            })?;
        }
        Ok(c)
    }
}

/// Room in `out` for `n` more points of `layout`.
fn reserve(out: &mut PointBatch, layout: Layout, n: usize) {
    out.pos.reserve(n);
    if layout.normal_at().is_some() {
        out.normal.reserve(n);
    }
    if layout.rgb_at().is_some() {
        out.color.reserve(n);
    }
    if layout.intensity_at().is_some() {
        out.intensity.reserve(n);
    }
}
