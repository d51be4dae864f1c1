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
//!
//! `text.rs` holds the layouts, the tokenizer and the line walk; `decode.rs` decodes the
//! values of a chunk's lines.

mod decode;
mod text;

use std::fs::File;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use crate::error::{Error, IoContext, Location, Result};
use crate::fs::mmap::Window;
use crate::types::{Attributes, PointBatch};
use crate::{ChunkSpec, ChunkStats, Format, PointReader};
use text::{
    BOM, INDEX_STEP, Layout, Mark, PtsHeader, SCAN_WINDOW, empty_value, find_first_line, scan_lines,
};

/// A text point file (XYZ, PTS) opened for reading.
pub struct XyzReader {
    path: PathBuf,
    file: File,
    file_len: u64,
    window: u64,
    layout: Layout,
    /// The normals are ignored, so not checked ([`PointReader::ignore_normals`]).
    ignore_normals: bool,
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
        crate::regular_file(path, "a point file")?;
        let file = File::open(path).with_path(path)?;
        let meta = file.metadata().with_path(path)?;
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
            ignore_normals: false,
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

impl PointReader for XyzReader {
    fn ignore_normals(&mut self) {
        self.ignore_normals = true;
    }

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
        self.read_records(chunk, skip_invalid, out)
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
        let r = crate::open(&p).unwrap();
        assert_eq!((r.format(), r.len()), (Format::Xyz, 1));
    }
}
