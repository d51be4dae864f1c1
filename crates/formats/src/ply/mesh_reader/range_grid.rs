//! Stanford range grids: the `range_grid` element of a range scan's PLY, triangulated.
//!
//! A range scan (Stanford 3D Scanning Repository, e.g. `bun000.ply`) stores its vertices and
//! the scanner's pixel grid: the header declares `obj_info num_cols C` and
//! `obj_info num_rows R`, and `element range_grid C·R` with `property list uchar int
//! vertex_indices`. Entry `r·C + c` (row-major, row 0 first) lists 0 or 1 vertex index: the
//! vertex seen at that pixel, if any.
//!
//! # Triangulation
//!
//! Each 2×2 block of pixels `tl = (r, c)`, `tr = (r, c+1)`, `bl = (r+1, c)`,
//! `br = (r+1, c+1)` gives
//!
//! * all four present: two triangles split along the shorter of the two 3D diagonals (`tl–br`
//!   on a tie): `(tl, tr, br), (tl, br, bl)` or `(tl, tr, bl), (tr, br, bl)`;
//! * exactly three present: one triangle, the three in the cyclic order `tl, tr, br, bl`;
//! * fewer: none.
//!
//! Every triangle follows the cyclic order `tl → tr → br → bl`, so all are wound the same
//! way: clockwise in the image drawn with row 0 at the top. On Stanford's scans that faces
//! the scanner: on `bun000.ply`, whose surface bulges towards `+z` (the points near the middle
//! of the image lie higher in `z` than those near its rim), all but 76 of the 79,312 triangles
//! face `+z`. Blocks are visited row by row, then column by column, so the triangles' order is
//! fixed by the file.

use std::path::Path;

use super::faces::ListSink;
use crate::error::{Error, Location, Result};
use crate::ply::{Element, PlyHeader};

/// Pixel value of an empty pixel.
pub(super) const EMPTY: u32 = u32::MAX;

/// The grid's `(columns, rows)` from the header's `obj_info num_cols` / `num_rows` lines
/// (the last of each), checked against the `range_grid` element `el`'s record count.
pub(super) fn grid_size(path: &Path, header: &PlyHeader, el: &Element) -> Result<(usize, usize)> {
    let (mut cols, mut rows) = (None, None);
    for (line, info) in &header.obj_info {
        let toks: Vec<&str> = info.split_ascii_whitespace().collect();
        let slot = match toks.as_slice() {
            ["num_cols", _] => &mut cols,
            ["num_rows", _] => &mut rows,
            _ => continue,
        };
        let v: usize = toks[1].parse().map_err(|_| {
            Error::format(
                path,
                Location::Line(*line),
                format!("obj_info {} \"{}\" is not a count", toks[0], toks[1]),
            )
        })?;
        *slot = Some(v);
    }
    let (Some(cols), Some(rows)) = (cols, rows) else {
        return Err(Error::format(
            path,
            Location::Line(el.line),
            "the range_grid element needs the header lines \"obj_info num_cols C\" and \
             \"obj_info num_rows R\"",
        ));
    };
    if cols.checked_mul(rows).map(|n| n as u64) != Some(el.count) {
        return Err(Error::format(
            path,
            Location::Line(el.line),
            format!(
                "range_grid has {} entries, but num_cols {cols} × num_rows {rows} pixels",
                el.count
            ),
        ));
    }
    Ok((cols, rows))
}

/// Collects the range grid's pixels: a vertex index or [`EMPTY`] per entry.
pub(super) struct PixelSink {
    n_vertices: u64,
    /// Per entry (row-major), its vertex or [`EMPTY`].
    pub(super) pixels: Vec<u32>,
    /// Indices read of the entry being read.
    seen: u32,
}

impl PixelSink {
    /// A sink for `entries` entries indexing `n_vertices` vertices.
    pub(super) fn new(n_vertices: u64, entries: u64) -> PixelSink {
        PixelSink {
            n_vertices,
            pixels: Vec::with_capacity(entries.min(1 << 28) as usize),
            seen: 0,
        }
    }
}

impl ListSink for PixelSink {
    fn corner(&mut self, rec: u64, v: f64) -> std::result::Result<(), String> {
        if !(v >= 0.0 && v < self.n_vertices as f64) {
            return Err(format!(
                "range_grid entry {rec}: vertex index {v} is out of range: the file has {} vertices",
                self.n_vertices
            ));
        }
        self.seen += 1;
        if self.seen > 1 {
            return Err(format!(
                "range_grid entry {rec} lists more than one vertex index, expected 0 or 1"
            ));
        }
        self.pixels.push(v as u32);
        Ok(())
    }

    fn finish(&mut self, rec: u64) -> std::result::Result<(), String> {
        if self.seen == 0 {
            self.pixels.push(EMPTY);
        }
        self.seen = 0;
        debug_assert_eq!(self.pixels.len() as u64, rec + 1);
        Ok(())
    }
}

/// Squared distance.
fn dist2(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]) * (a[k] - b[k])).sum()
}

/// The triangles of a `(cols, rows)` grid of `pixels` (module docs).
pub(super) fn triangulate(
    (cols, rows): (usize, usize),
    pixels: &[u32],
    vertices: &[[f64; 3]],
) -> Vec<[u32; 3]> {
    let mut out = Vec::new();
    if cols < 2 || rows < 2 || pixels.len() < cols * rows {
        return out;
    }
    for r in 0..rows - 1 {
        for c in 0..cols - 1 {
            let at = r * cols + c;
            // The cyclic order tl, tr, br, bl.
            let cyc = [
                pixels[at],
                pixels[at + 1],
                pixels[at + cols + 1],
                pixels[at + cols],
            ];
            let present = cyc.iter().filter(|&&v| v != EMPTY).count();
            match present {
                4 => {
                    let [tl, tr, br, bl] = cyc;
                    let p = |v: u32| vertices[v as usize];
                    if dist2(p(tl), p(br)) <= dist2(p(tr), p(bl)) {
                        out.push([tl, tr, br]);
                        out.push([tl, br, bl]);
                    } else {
                        out.push([tl, tr, bl]);
                        out.push([tr, br, bl]);
                    }
                }
                3 => {
                    let mut t = [0u32; 3];
                    for (slot, v) in t.iter_mut().zip(cyc.into_iter().filter(|&v| v != EMPTY)) {
                        *slot = v;
                    }
                    out.push(t);
                }
                _ => {}
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Twice the signed area of triangle `t` of points in the image plane (x = column,
    /// y = −row, so row 0 is at the top).
    fn image_area(t: [u32; 3], pos: &[[f64; 3]]) -> f64 {
        let [a, b, c] = t.map(|v| pos[v as usize]);
        (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    }

    #[test]
    fn blocks_of_four_and_three_are_wound_alike() {
        // 3 × 3 pixels, the centre-right one empty; vertices at (col, −row, 0).
        let (cols, rows) = (3usize, 3usize);
        let mut pixels = Vec::new();
        let mut pos = Vec::new();
        for r in 0..rows {
            for c in 0..cols {
                if (r, c) == (1, 2) {
                    pixels.push(EMPTY);
                } else {
                    pixels.push(pos.len() as u32);
                    pos.push([c as f64, -(r as f64), 0.0]);
                }
            }
        }
        let t = triangulate((cols, rows), &pixels, &pos);
        // Left blocks: two triangles each; right blocks: three pixels, one triangle each.
        assert_eq!(t.len(), 6);
        assert!(t.iter().all(|&t| image_area(t, &pos) < 0.0), "{t:?}");
        // Every triangle's corners are distinct vertices.
        assert!(
            t.iter()
                .all(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
        );
    }

    #[test]
    fn shorter_diagonal_splits_the_block() {
        let pixels = [0, 1, 2, 3];
        // tl, tr, bl, br: tl and br pulled apart in depth, so tr–bl is the shorter diagonal.
        let pos = [
            [0.0, 0.0, 5.0],
            [1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0],
            [1.0, -1.0, -5.0],
        ];
        assert_eq!(
            triangulate((2, 2), &pixels, &pos),
            vec![[0, 1, 2], [1, 3, 2]]
        );
        // tr and bl pulled apart: tl–br is the shorter one.
        let pos = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 5.0],
            [0.0, -1.0, -5.0],
            [1.0, -1.0, 0.0],
        ];
        assert_eq!(
            triangulate((2, 2), &pixels, &pos),
            vec![[0, 1, 3], [0, 3, 2]]
        );
    }
}
