//! VTK legacy `.vtk`, `DATASET UNSTRUCTURED_GRID`: ASCII and BINARY (big-endian), the cell
//! layouts of file versions up to 4.x (`CELLS n size`, each cell's point count inline) and
//! 5.x (`OFFSETS` and `CONNECTIVITY` arrays). 0-based indices.

use std::io::Write;
use std::path::Path;

use super::scan::{Scan, Token, capacity, show};
use super::{Cell, VolumeMesh};
use crate::error::{Error, Location, Result};

/// A VTK data type: its size in bytes, and whether it is a float or a signed integer.
#[derive(Clone, Copy, Debug)]
struct Ty {
    size: usize,
    float: bool,
    signed: bool,
}

/// The type named `name` (case-insensitive), if this reader knows it.
fn ty(name: &[u8]) -> Option<Ty> {
    let n = String::from_utf8_lossy(name).to_ascii_lowercase();
    let (size, float, signed) = match n.as_str() {
        "char" | "vtktypeint8" => (1, false, true),
        "unsigned_char" | "vtktypeuint8" => (1, false, false),
        "short" | "vtktypeint16" => (2, false, true),
        "unsigned_short" | "vtktypeuint16" => (2, false, false),
        "int" | "vtktypeint32" => (4, false, true),
        "unsigned_int" | "vtktypeuint32" => (4, false, false),
        "long" | "vtktypeint64" | "vtkidtype" => (8, false, true),
        "unsigned_long" | "vtktypeuint64" => (8, false, false),
        "float" | "vtktypefloat32" => (4, true, true),
        "double" | "vtktypefloat64" => (8, true, true),
        _ => return None,
    };
    Some(Ty {
        size,
        float,
        signed,
    })
}

/// The big-endian value of type `t` in `b`, as `f64`.
fn be_f64(b: &[u8], t: Ty) -> f64 {
    if t.float {
        if t.size == 4 {
            f32::from_be_bytes([b[0], b[1], b[2], b[3]]) as f64
        } else {
            f64::from_be_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]])
        }
    } else {
        be_i64(b, t) as f64
    }
}

/// The big-endian integer of type `t` in `b` (unsigned 64-bit values beyond `i64` saturate).
fn be_i64(b: &[u8], t: Ty) -> i64 {
    if t.float {
        let v = be_f64(b, t);
        return if v.fract() == 0.0 && v.abs() < 9e15 {
            v as i64
        } else {
            i64::MIN
        };
    }
    let mut u: u64 = 0;
    for &x in &b[..t.size] {
        u = (u << 8) | x as u64;
    }
    if t.signed && t.size < 8 {
        let shift = 64 - 8 * t.size as u32;
        ((u << shift) as i64) >> shift
    } else if t.signed {
        u as i64
    } else {
        i64::try_from(u).unwrap_or(i64::MAX)
    }
}

/// An integer array as read: decoded text, or the raw big-endian bytes of binary data.
struct Ints<'a> {
    text: Vec<i64>,
    bin: &'a [u8],
    binary: bool,
    ty: Ty,
    /// Byte and line where the values start.
    byte: usize,
    line: u64,
    len: usize,
}

impl Ints<'_> {
    fn get(&self, i: usize) -> i64 {
        if self.binary {
            be_i64(&self.bin[i * self.ty.size..], self.ty)
        } else {
            self.text[i]
        }
    }

    /// Where value `i` is: its byte in binary data, its line in text (found by counting the
    /// tokens again: errors only).
    fn loc(&self, data: &[u8], i: usize) -> Location {
        if self.binary {
            return Location::Byte((self.byte + i * self.ty.size) as u64);
        }
        let mut s = Scan::new(Path::new(""), data);
        s.pos = self.byte;
        s.line = self.line;
        let mut line = self.line;
        for _ in 0..=i {
            match s.token(false) {
                Some(t) => line = t.line,
                None => break,
            }
        }
        Location::Line(line)
    }
}

/// Where each cell's point ids are in the id array.
enum Layout<'a> {
    /// Versions up to 4: `count ids...` runs; the position of each run's count, and one past
    /// the last run.
    Inline(Vec<usize>),
    /// Version 5: offsets into the connectivity, one more than the cells.
    Offsets(Ints<'a>),
}

impl Layout<'_> {
    fn cells(&self) -> usize {
        match self {
            Layout::Inline(p) => p.len().saturating_sub(1),
            Layout::Offsets(o) => o.len.saturating_sub(1),
        }
    }

    /// The first id of cell `c` and how many it has (both checked when read).
    fn span(&self, c: usize) -> (usize, usize) {
        match self {
            Layout::Inline(p) => (p[c] + 1, p[c + 1] - p[c] - 1),
            Layout::Offsets(o) => {
                let (a, b) = (o.get(c) as usize, o.get(c + 1) as usize);
                (a, b - a)
            }
        }
    }
}

/// What becomes of a cell type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Tet,
    Hex,
    /// `VTK_VOXEL`: a hexahedron with its points in lexicographic order.
    Voxel,
    Tri,
    Skip,
    HighOrder,
}

/// What becomes of VTK cell type `t`, and its name ("" when unknown).
fn cell_type(t: i64) -> (Kind, &'static str) {
    match t {
        10 => (Kind::Tet, "VTK_TETRA"),
        12 => (Kind::Hex, "VTK_HEXAHEDRON"),
        11 => (Kind::Voxel, "VTK_VOXEL"),
        5 => (Kind::Tri, "VTK_TRIANGLE"),
        1 => (Kind::Skip, "VTK_VERTEX"),
        2 => (Kind::Skip, "VTK_POLY_VERTEX"),
        3 => (Kind::Skip, "VTK_LINE"),
        4 => (Kind::Skip, "VTK_POLY_LINE"),
        6 => (Kind::Skip, "VTK_TRIANGLE_STRIP"),
        7 => (Kind::Skip, "VTK_POLYGON"),
        8 => (Kind::Skip, "VTK_PIXEL"),
        9 => (Kind::Skip, "VTK_QUAD"),
        13 => (Kind::Skip, "VTK_WEDGE"),
        14 => (Kind::Skip, "VTK_PYRAMID"),
        15 => (Kind::Skip, "VTK_PENTAGONAL_PRISM"),
        16 => (Kind::Skip, "VTK_HEXAGONAL_PRISM"),
        21 => (Kind::Skip, "VTK_QUADRATIC_EDGE"),
        22 => (Kind::Skip, "VTK_QUADRATIC_TRIANGLE"),
        23 => (Kind::Skip, "VTK_QUADRATIC_QUAD"),
        26 => (Kind::Skip, "VTK_QUADRATIC_WEDGE"),
        27 => (Kind::Skip, "VTK_QUADRATIC_PYRAMID"),
        28 => (Kind::Skip, "VTK_BIQUADRATIC_QUAD"),
        42 => (Kind::Skip, "VTK_POLYHEDRON"),
        24 => (Kind::HighOrder, "VTK_QUADRATIC_TETRA"),
        25 => (Kind::HighOrder, "VTK_QUADRATIC_HEXAHEDRON"),
        29 => (Kind::HighOrder, "VTK_TRIQUADRATIC_HEXAHEDRON"),
        33 => (Kind::HighOrder, "VTK_BIQUADRATIC_QUADRATIC_HEXAHEDRON"),
        71 => (Kind::HighOrder, "VTK_LAGRANGE_TETRAHEDRON"),
        72 => (Kind::HighOrder, "VTK_LAGRANGE_HEXAHEDRON"),
        78 => (Kind::HighOrder, "VTK_BEZIER_TETRAHEDRON"),
        79 => (Kind::HighOrder, "VTK_BEZIER_HEXAHEDRON"),
        _ => (Kind::Skip, ""),
    }
}

/// The type of `CELLS` (≤ 4.x) and `CELL_TYPES`.
const INT: Ty = Ty {
    size: 4,
    float: false,
    signed: true,
};

/// The reader's state.
struct Vtk<'a> {
    s: Scan<'a>,
    version: (u32, u32),
    mesh: VolumeMesh,
    have_points: bool,
}

/// Read a VTK legacy unstructured grid held in `data`.
pub(super) fn read(path: &Path, data: &[u8]) -> Result<VolumeMesh> {
    let mut s = Scan::new(path, data);
    let head = s.line_rest().map(|t| t.text).unwrap_or_default();
    let version = parse_version(head).ok_or_else(|| {
        Error::format(
            path,
            Location::Line(1),
            format!(
                "not a VTK legacy file: expected `# vtk DataFile Version x.y`, found {}",
                show(head)
            ),
        )
    })?;
    if s.line_rest().is_none() {
        return Err(s.err("file ends after the header: expected a title line"));
    }
    let binary = match s.nonblank_line() {
        Some(t) if t.is("ASCII") => false,
        Some(t) if t.is("BINARY") => true,
        Some(t) => {
            return Err(s.err_at(&t, format!("expected ASCII or BINARY, found {}", t.show())));
        }
        None => return Err(s.err("file ends after the title: expected ASCII or BINARY")),
    };
    let mut v = Vtk {
        s,
        version,
        mesh: VolumeMesh::default(),
        have_points: false,
    };
    match (v.s.token(false), v.s.token(false)) {
        (Some(d), Some(t)) if d.is("DATASET") && t.is("UNSTRUCTURED_GRID") => {}
        (Some(d), Some(t)) if d.is("DATASET") => {
            return Err(v.s.err_at(
                &t,
                format!(
                    "DATASET {}: only UNSTRUCTURED_GRID is supported (a volume mesh)",
                    t.show()
                ),
            ));
        }
        (Some(d), _) => {
            return Err(v.s.err_at(
                &d,
                format!("expected DATASET UNSTRUCTURED_GRID, found {}", d.show()),
            ));
        }
        (None, _) => return Err(v.s.err("file ends: expected DATASET UNSTRUCTURED_GRID")),
    }
    v.s.binary = binary;
    let mut cells: Option<(Layout, Ints, Token)> = None;
    let mut types: Option<(Ints, Token)> = None;
    let mut stopped = false;
    while let Some(kw) = v.s.token(false) {
        if kw.is("POINTS") {
            v.points(&kw)?;
        } else if kw.is("CELLS") {
            if !v.have_points {
                return Err(v
                    .s
                    .err_at(&kw, "CELLS before POINTS: expected POINTS first"));
            }
            if cells.is_some() {
                return Err(v.s.err_at(&kw, "a second CELLS: expected one"));
            }
            let (layout, ids) = v.cells(&kw)?;
            cells = Some((layout, ids, kw));
        } else if kw.is("CELL_TYPES") {
            let n = v.count(&kw, "CELL_TYPES", "the number of cells")?;
            let t = v.ints(n, INT, "CELL_TYPES")?;
            types = Some((t, kw));
        } else if kw.is("POINT_DATA") || kw.is("CELL_DATA") {
            stopped = true;
            break;
        } else if kw.is("FIELD") {
            v.field(&kw)?;
        } else if kw.is("METADATA") {
            v.metadata();
        } else {
            return Err(v.s.err_at(
                &kw,
                format!(
                    "expected POINTS, CELLS, CELL_TYPES, FIELD, POINT_DATA or CELL_DATA, found {}",
                    kw.show()
                ),
            ));
        }
    }
    if !stopped && !binary {
        v.s.check_not_cut("VTK legacy")?;
    }
    if !v.have_points {
        return Err(v.s.err("no POINTS: expected POINTS, CELLS and CELL_TYPES"));
    }
    match (cells, types) {
        (None, None) => {}
        (Some((_, _, kw)), None) => return Err(v.s.err_at(&kw, "CELLS without CELL_TYPES")),
        (None, Some((_, kw))) => return Err(v.s.err_at(&kw, "CELL_TYPES without CELLS")),
        (Some((layout, ids, _)), Some((types, tkw))) => {
            v.assemble(&layout, &ids, &types, &tkw)?;
        }
    }
    Ok(v.mesh)
}

/// `(major, minor)` from `# vtk DataFile Version x.y`.
fn parse_version(head: &[u8]) -> Option<(u32, u32)> {
    let h = std::str::from_utf8(head).ok()?.trim();
    let rest = h.strip_prefix('#')?.trim_start();
    let tail = rest.get(3..)?;
    if !rest[..3].eq_ignore_ascii_case("vtk") {
        return None;
    }
    let mut w = tail.split_whitespace();
    if !w.next()?.eq_ignore_ascii_case("DataFile") || !w.next()?.eq_ignore_ascii_case("Version") {
        return None;
    }
    let ver = w.next()?;
    let (a, b) = ver.split_once('.').unwrap_or((ver, "0"));
    Some((a.parse().ok()?, b.parse().ok()?))
}

impl<'a> Vtk<'a> {
    /// A non-negative count after keyword `kw`.
    fn count(&mut self, kw: &Token, name: &str, what: &str) -> Result<u64> {
        match self.s.token(false) {
            Some(t) => t.u64().ok_or_else(|| {
                self.s
                    .err_at(&t, format!("{name}: expected {what}, found {}", t.show()))
            }),
            None => Err(self
                .s
                .err_at(kw, format!("file ends after {name}: expected {what}"))),
        }
    }

    /// A data type name after keyword `kw`.
    fn ty(&mut self, kw: &Token, name: &str) -> Result<Ty> {
        match self.s.token(false) {
            Some(t) => ty(t.text).ok_or_else(|| {
                self.s.err_at(
                    &t,
                    format!(
                        "{name}: unsupported data type {}: expected a numeric VTK type (float, \
                         double, int, long, vtktypeint32, vtktypeint64, ...)",
                        t.show()
                    ),
                )
            }),
            None => Err(self
                .s
                .err_at(kw, format!("file ends after {name}: expected a data type"))),
        }
    }

    /// Binary: the raw bytes of `n` values of type `t`, which start after the end of the
    /// keyword's line, and the byte they start at.
    fn raw(&mut self, n: u64, t: Ty, what: &str) -> Result<(&'a [u8], usize)> {
        self.s.end_line()?;
        let start = self.s.pos;
        let total = usize::try_from(n)
            .ok()
            .and_then(|n| n.checked_mul(t.size))
            .filter(|&b| b <= self.s.remaining());
        match total {
            Some(total) => Ok((self.s.take(total, what)?, start)),
            None => Err(Error::format(
                self.s.path,
                Location::Byte(self.s.data.len() as u64),
                format!(
                    "file ends in {what}: expected {n} values of {} bytes from byte {start}, \
                     found {} bytes",
                    t.size,
                    self.s.remaining()
                ),
            )),
        }
    }

    /// ASCII: value `i` of the `n` of `what`, a number token.
    fn text_value(&mut self, i: u64, n: u64, what: &str) -> Result<Token<'a>> {
        let Some(tok) = self.s.token(false) else {
            return Err(self
                .s
                .err(format!("file ends in {what} after {i} of {n} values")));
        };
        if tok.f64().is_none() {
            return Err(self.s.err_at(
                &tok,
                format!(
                    "{what}: expected {n} numbers, found {i} before {}",
                    tok.show()
                ),
            ));
        }
        Ok(tok)
    }

    /// An integer array of `n` values of type `t`.
    fn ints(&mut self, n: u64, t: Ty, what: &str) -> Result<Ints<'a>> {
        if self.s.binary {
            let (bin, byte) = self.raw(n, t, what)?;
            return Ok(Ints {
                text: Vec::new(),
                bin,
                binary: true,
                ty: t,
                byte,
                line: 0,
                len: bin.len() / t.size,
            });
        }
        let (byte, line) = (self.s.pos, self.s.line);
        let mut text = Vec::with_capacity(capacity(n, self.s.remaining(), 2));
        for i in 0..n {
            let tok = self.text_value(i, n, what)?;
            let Some(x) = tok.i64() else {
                return Err(self.s.err_at(
                    &tok,
                    format!("{what}: expected a whole number, found {}", tok.show()),
                ));
            };
            text.push(x);
        }
        let len = text.len();
        Ok(Ints {
            text,
            bin: &[],
            binary: false,
            ty: t,
            byte,
            line,
            len,
        })
    }

    /// `POINTS n type`, then 3n values.
    fn points(&mut self, kw: &Token) -> Result<()> {
        if self.have_points {
            return Err(self.s.err_at(kw, "a second POINTS: expected one"));
        }
        let n = self.count(kw, "POINTS", "the number of points")?;
        if n > u32::MAX as u64 {
            return Err(self.s.err_at(
                kw,
                format!("POINTS: {n} points are more than 32-bit indices address"),
            ));
        }
        let t = self.ty(kw, "POINTS")?;
        let n3 = n * 3;
        let what = format!("POINTS ({n} points, {n3} numbers)");
        let bad = |i: usize, x: f64| {
            format!(
                "POINTS: point {}: {} is {x}, expected a finite coordinate",
                i / 3,
                ["x", "y", "z"][i % 3]
            )
        };
        let mut flat = Vec::with_capacity(capacity(n3, self.s.remaining(), 2));
        if self.s.binary {
            let (bytes, start) = self.raw(n3, t, &what)?;
            for (i, b) in bytes.chunks_exact(t.size).enumerate() {
                let x = be_f64(b, t);
                if !x.is_finite() {
                    return Err(Error::format(
                        self.s.path,
                        Location::Byte((start + i * t.size) as u64),
                        bad(i, x),
                    ));
                }
                flat.push(x);
            }
        } else {
            for i in 0..n3 {
                let tok = self.text_value(i, n3, &what)?;
                let x = tok.f64().unwrap_or(f64::NAN);
                if !x.is_finite() {
                    return Err(self.s.err_at(&tok, bad(i as usize, x)));
                }
                flat.push(x);
            }
        }
        self.mesh.verts = flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        self.have_points = true;
        Ok(())
    }

    /// `CELLS`, in either layout: where each cell's ids are, and the ids.
    fn cells(&mut self, kw: &Token<'a>) -> Result<(Layout<'a>, Ints<'a>)> {
        let a = self.count(kw, "CELLS", "the number of cells")?;
        let b = self.count(kw, "CELLS", "the size of the cell list")?;
        let data = self.s.data;
        if self.version.0 >= 5 {
            // CELLS nOffsets nConnectivity, then OFFSETS type and CONNECTIVITY type arrays.
            let mut offsets = None;
            let mut conn = None;
            for _ in 0..2 {
                let Some(k) = self.s.token(false) else {
                    return Err(self
                        .s
                        .err("file ends in CELLS: expected OFFSETS and CONNECTIVITY"));
                };
                if k.is("OFFSETS") && offsets.is_none() {
                    let t = self.ty(&k, "OFFSETS")?;
                    offsets = Some(self.ints(a, t, "OFFSETS")?);
                } else if k.is("CONNECTIVITY") && conn.is_none() {
                    let t = self.ty(&k, "CONNECTIVITY")?;
                    conn = Some(self.ints(b, t, "CONNECTIVITY")?);
                } else {
                    return Err(self.s.err_at(
                        &k,
                        format!(
                            "CELLS (file version {}.{}): expected OFFSETS and CONNECTIVITY, \
                             found {}",
                            self.version.0,
                            self.version.1,
                            k.show()
                        ),
                    ));
                }
            }
            let (Some(offsets), Some(conn)) = (offsets, conn) else {
                return Err(self
                    .s
                    .err_at(kw, "CELLS: expected OFFSETS and CONNECTIVITY"));
            };
            if offsets.len == 0 {
                return Err(self.s.err_at(
                    kw,
                    "CELLS 0: expected the number of offsets, one more than the cells",
                ));
            }
            // Offsets start at 0, never decrease and end at the connectivity's size.
            let mut prev = 0i64;
            for i in 0..offsets.len {
                let o = offsets.get(i);
                let last = i + 1 == offsets.len;
                let bad = (i == 0 && o != 0)
                    || o < prev
                    || o > conn.len as i64
                    || (last && o != conn.len as i64);
                if bad {
                    return Err(Error::format(
                        self.s.path,
                        offsets.loc(data, i),
                        format!(
                            "OFFSETS: offset {i} is {o}: expected offsets from 0, never \
                             decreasing, the last equal to the {} connectivity entries",
                            conn.len
                        ),
                    ));
                }
                prev = o;
            }
            return Ok((Layout::Offsets(offsets), conn));
        }
        // Up to version 4: CELLS n size, then n runs of `count ids...`, size numbers in all.
        let list = self.ints(b, INT, "CELLS")?;
        let mut pos = Vec::with_capacity(capacity(a.saturating_add(1), list.len, 1));
        let mut at = 0usize;
        for c in 0..a {
            if at >= list.len {
                return Err(self.s.err_at(
                    kw,
                    format!("CELLS {a} {b}: the {b} numbers end after {c} of the {a} cells"),
                ));
            }
            pos.push(at);
            let k = list.get(at);
            let left = list.len - at - 1;
            if k < 0 || k as u64 > left as u64 {
                return Err(Error::format(
                    self.s.path,
                    list.loc(data, at),
                    format!(
                        "CELLS: cell {c}: point count {k}: expected 0 to the {left} numbers left \
                         in the list"
                    ),
                ));
            }
            at += 1 + k as usize;
        }
        if at != list.len {
            return Err(self.s.err_at(
                kw,
                format!("CELLS {a} {b}: the {a} cells take {at} numbers, not the {b} announced"),
            ));
        }
        pos.push(at);
        Ok((Layout::Inline(pos), list))
    }

    /// Keep, count or refuse each cell by its type.
    fn assemble(&mut self, layout: &Layout, ids: &Ints, types: &Ints, tkw: &Token) -> Result<()> {
        let n = layout.cells();
        if types.len != n {
            return Err(self.s.err_at(
                tkw,
                format!(
                    "CELL_TYPES {}: expected {n}, one type per cell of CELLS",
                    types.len
                ),
            ));
        }
        let data = self.s.data;
        let nv = self.mesh.verts.len();
        let mut idx = [0u32; 8];
        for c in 0..n {
            let t = types.get(c);
            let (kind, name) = cell_type(t);
            let want = match kind {
                Kind::Tet => 4,
                Kind::Hex | Kind::Voxel => 8,
                Kind::Tri => 3,
                Kind::Skip => {
                    if name.is_empty() {
                        self.mesh.skip(&format!("VTK cell type {t}"), 1);
                    } else {
                        self.mesh.skip(name, 1);
                    }
                    continue;
                }
                Kind::HighOrder => {
                    return Err(Error::format(
                        self.s.path,
                        types.loc(data, c),
                        format!(
                            "cell {c}: {name} ({t}): only linear cells are supported \
                             (VTK_TETRA 10, VTK_HEXAHEDRON 12)"
                        ),
                    ));
                }
            };
            let (start, k) = layout.span(c);
            if k != want {
                return Err(Error::format(
                    self.s.path,
                    types.loc(data, c),
                    format!("cell {c}: {name} ({t}) with {k} points, expected {want}"),
                ));
            }
            for (j, slot) in idx[..k].iter_mut().enumerate() {
                let v = ids.get(start + j);
                if v < 0 || v as u64 >= nv as u64 {
                    return Err(Error::format(
                        self.s.path,
                        ids.loc(data, start + j),
                        format!("cell {c} ({name}): point {v} is beyond the {nv} points"),
                    ));
                }
                *slot = v as u32;
            }
            match kind {
                Kind::Tet => self.mesh.tets.push([idx[0], idx[1], idx[2], idx[3]]),
                Kind::Hex => self.mesh.hexes.push(idx),
                Kind::Voxel => self.mesh.hexes.push([
                    idx[0], idx[1], idx[3], idx[2], idx[4], idx[5], idx[7], idx[6],
                ]),
                _ => self.mesh.triangles.push([idx[0], idx[1], idx[2]]),
            }
        }
        Ok(())
    }

    /// `FIELD name n`: n arrays `name components tuples type`, skipped.
    fn field(&mut self, kw: &Token) -> Result<()> {
        self.s.token(false);
        let n = self.count(kw, "FIELD", "the number of arrays")?;
        for _ in 0..n {
            let mut name = self.s.token(false);
            while name.is_some_and(|t| t.is("METADATA")) {
                self.metadata();
                name = self.s.token(false);
            }
            let Some(name) = name else {
                return Err(self.s.err_at(kw, "file ends in FIELD: expected an array"));
            };
            let what = format!("FIELD array {}", name.show());
            let comps = self.count(&name, &what, "the number of components")?;
            let tuples = self.count(&name, &what, "the number of tuples")?;
            let t = self.ty(&name, &what)?;
            let total = comps.saturating_mul(tuples);
            if self.s.binary {
                self.raw(total, t, &what)?;
            } else {
                for i in 0..total {
                    self.text_value(i, total, &what)?;
                }
            }
        }
        Ok(())
    }

    /// `METADATA`: lines up to the next blank line, skipped.
    fn metadata(&mut self) {
        self.s.line_rest();
        while let Some(l) = self.s.line_rest() {
            if l.text.trim_ascii().is_empty() {
                break;
            }
        }
    }
}

/// Write `verts` and `cells` as VTK legacy 4.2 BINARY (big-endian), with `cell_data` as
/// `CELL_DATA` scalars.
pub(super) fn write<const K: usize>(
    w: &mut impl Write,
    verts: &[[f64; 3]],
    cells: &[[u32; K]],
    kind: Cell,
    cell_data: &[(&str, &[f64])],
) -> std::io::Result<()> {
    let (ctype, what): (i32, &str) = match kind {
        Cell::Tet => (10, "tetrahedral"),
        Cell::Hex => (12, "hexahedral"),
    };
    write!(
        w,
        "# vtk DataFile Version 4.2\nscanflow {what} mesh\nBINARY\nDATASET UNSTRUCTURED_GRID\n"
    )?;
    writeln!(w, "POINTS {} double", verts.len())?;
    for p in verts {
        for c in p {
            w.write_all(&c.to_be_bytes())?;
        }
    }
    writeln!(w, "\nCELLS {} {}", cells.len(), cells.len() * (K + 1))?;
    for c in cells {
        w.write_all(&(K as i32).to_be_bytes())?;
        for &v in c {
            w.write_all(&(v as i32).to_be_bytes())?;
        }
    }
    writeln!(w, "\nCELL_TYPES {}", cells.len())?;
    for _ in cells {
        w.write_all(&ctype.to_be_bytes())?;
    }
    writeln!(w)?;
    if !cell_data.is_empty() {
        writeln!(w, "CELL_DATA {}", cells.len())?;
        for (name, values) in cell_data {
            writeln!(w, "SCALARS {name} double 1\nLOOKUP_TABLE default")?;
            for v in *values {
                w.write_all(&v.to_be_bytes())?;
            }
            writeln!(w)?;
        }
    }
    Ok(())
}

#[cfg(test)]
pub(super) mod tests;
