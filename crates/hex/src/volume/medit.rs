//! MEDIT / INRIA ASCII `.mesh`: a stream of whitespace-separated tokens, `#` comments,
//! keywords each followed by a count and that many fixed-size entries, 1-based indices.

use std::io::Write;
use std::path::Path;

use super::scan::{Scan, Token, capacity, show};
use super::{Cell, VolumeMesh, fmt_f64};
use crate::error::{Error, Location, Result};

/// What becomes of an element section's entries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Keep {
    Tet,
    Hex,
    Tri,
    Skip,
}

/// Element sections: keyword, vertices per entry, what is kept, singular noun.
const ELEMENTS: [(&str, usize, Keep, &str); 7] = [
    ("Tetrahedra", 4, Keep::Tet, "tetrahedron"),
    ("Hexahedra", 8, Keep::Hex, "hexahedron"),
    ("Triangles", 3, Keep::Tri, "triangle"),
    ("Edges", 2, Keep::Skip, "edge"),
    ("Quadrilaterals", 4, Keep::Skip, "quadrilateral"),
    ("Prisms", 6, Keep::Skip, "prism"),
    ("Pyramids", 5, Keep::Skip, "pyramid"),
];

/// Other sections skipped whole: keyword, numbers per entry.
const SKIPPED: [(&str, usize); 15] = [
    ("Corners", 1),
    ("Ridges", 1),
    ("RequiredVertices", 1),
    ("RequiredEdges", 1),
    ("RequiredTriangles", 1),
    ("RequiredQuadrilaterals", 1),
    ("RequiredTetrahedra", 1),
    ("RequiredHexahedra", 1),
    ("Normals", 3),
    ("Tangents", 3),
    ("NormalAtVertices", 2),
    ("NormalAtTriangleVertices", 3),
    ("NormalAtQuadrilateralVertices", 3),
    ("TangentAtEdgeVertices", 3),
    ("TangentAtEdges", 3),
];

/// Whether `tok` is a keyword this reader knows (for messages about short sections).
fn is_keyword(tok: &Token) -> bool {
    ["MeshVersionFormatted", "Dimension", "Vertices", "End"]
        .iter()
        .chain(ELEMENTS.iter().map(|e| &e.0))
        .chain(SKIPPED.iter().map(|e| &e.0))
        .any(|k| tok.is(k))
}

/// For a higher-order element keyword (`TetrahedraP2`, `HexahedraQ2`, `TrianglesP3`, ...),
/// the linear keyword it extends.
fn high_order(tok: &Token) -> Option<&'static str> {
    ELEMENTS.iter().map(|e| e.0).find(|name| {
        let t = tok.text;
        t.len() > name.len() + 1
            && t[..name.len()].eq_ignore_ascii_case(name.as_bytes())
            && matches!(t[name.len()], b'P' | b'Q' | b'p' | b'q')
            && t[name.len() + 1..].iter().all(u8::is_ascii_digit)
    })
}

/// Every keyword, for the message about an unknown one.
fn keyword_list() -> String {
    let mut all: Vec<&str> = vec!["MeshVersionFormatted", "Dimension", "Vertices"];
    all.extend(ELEMENTS.iter().map(|e| e.0));
    all.extend(SKIPPED.iter().map(|e| e.0));
    all.push("End");
    all.join(", ")
}

/// The reader's state between sections.
struct Reader<'a> {
    s: Scan<'a>,
    mesh: VolumeMesh,
    dimension: Option<u64>,
    /// Vertex count once `Vertices` was read.
    nverts: Option<usize>,
    /// Element sections read before `Vertices`, checked at the end: kind, first entry, line.
    unchecked: Vec<(Keep, usize, u64)>,
}

/// Read a MEDIT ASCII mesh held in `data`.
pub(super) fn read(path: &Path, data: &[u8]) -> Result<VolumeMesh> {
    let mut r = Reader {
        s: Scan::new(path, data),
        mesh: VolumeMesh::default(),
        dimension: None,
        nverts: None,
        unchecked: Vec::new(),
    };
    let mut ended = false;
    while let Some(kw) = r.s.token(true) {
        if kw.text.iter().any(|&b| b < 0x20 || b == 0x7f) {
            return Err(r.s.err_at(
                &kw,
                format!(
                    "expected MEDIT ASCII text, found binary data {} (a binary mesh is .meshb)",
                    kw.show()
                ),
            ));
        }
        if kw.is("End") {
            ended = true;
            break;
        } else if kw.is("MeshVersionFormatted") {
            let v = r.count(&kw, "MeshVersionFormatted", "the version (1 to 4)")?;
            if !(1..=4).contains(&v) {
                return Err(r.s.err_at(
                    &kw,
                    format!("MeshVersionFormatted: expected 1, 2, 3 or 4, found {v}"),
                ));
            }
        } else if kw.is("Dimension") {
            let d = r.count(&kw, "Dimension", "the dimension 3")?;
            if d != 3 {
                return Err(r.s.err_at(
                    &kw,
                    format!(
                        "Dimension {d}: a volume mesh needs Dimension 3{}",
                        if d == 2 {
                            " (this is a planar mesh)"
                        } else {
                            ""
                        }
                    ),
                ));
            }
            r.dimension = Some(d);
        } else if kw.is("Vertices") {
            r.vertices(&kw)?;
        } else if let Some(&(name, n, keep, one)) = ELEMENTS.iter().find(|e| kw.is(e.0)) {
            r.elements(&kw, name, n, keep, one)?;
        } else if let Some(&(name, n)) = SKIPPED.iter().find(|e| kw.is(e.0)) {
            r.skipped(&kw, name, n)?;
        } else if let Some(base) = high_order(&kw) {
            return Err(r.s.err_at(
                &kw,
                format!(
                    "{}: higher-order elements are not supported: expected linear {base} \
                     (only Tetrahedra and Hexahedra are volume elements here)",
                    kw.show()
                ),
            ));
        } else if kw.f64().is_some() {
            return Err(r.s.err_at(
                &kw,
                format!(
                    "expected a keyword, found the number {}: does the count of the section \
                     before match its entries?",
                    kw.show()
                ),
            ));
        } else {
            return Err(r.s.err_at(
                &kw,
                format!(
                    "unknown keyword {}: the size of its entries is unknown, so the file cannot \
                     be read past it (supported: {})",
                    kw.show(),
                    keyword_list()
                ),
            ));
        }
    }
    if !ended {
        r.s.check_not_cut("MEDIT")?;
    }
    let Some(nverts) = r.nverts else {
        return Err(Error::format(
            path,
            r.s.loc(),
            "no Vertices section: expected `Vertices` with the vertex count and coordinates",
        ));
    };
    // Sections read before the vertices were known: check their indices now.
    for &(keep, first, line) in &r.unchecked {
        let (name, n) = match keep {
            Keep::Tet => ("tetrahedron", 4),
            Keep::Hex => ("hexahedron", 8),
            _ => ("triangle", 3),
        };
        let flat: &[u32] = match keep {
            Keep::Tet => r.mesh.tets.as_flattened(),
            Keep::Hex => r.mesh.hexes.as_flattened(),
            _ => r.mesh.triangles.as_flattened(),
        };
        if let Some(i) = flat[first * n..].iter().position(|&v| v as usize >= nverts) {
            let e = first + i / n;
            return Err(Error::format(
                path,
                Location::Line(line),
                format!(
                    "{name} {}: vertex {} is beyond the {nverts} vertices",
                    e + 1,
                    flat[first * n + i] as u64 + 1
                ),
            ));
        }
    }
    Ok(r.mesh)
}

/// One section being read, for messages.
struct Section<'k> {
    /// Its keyword.
    name: &'k str,
    /// Its entry, singular ("tetrahedron").
    one: &'k str,
    /// What an entry holds ("4 vertices and a reference").
    layout: String,
    /// Entries announced.
    count: u64,
    /// Numbers per entry.
    per: usize,
}

/// Where an entry is while it is read: its index, the bytes of its numbers so far and the
/// line of its first.
struct Entry<'a> {
    i: u64,
    got: &'a [u8],
    line: u64,
}

impl<'a> Reader<'a> {
    /// The count after keyword `kw` (named `what` in messages): a non-negative integer.
    fn count(&mut self, kw: &Token, name: &str, what: &str) -> Result<u64> {
        let Some(t) = self.s.token(true) else {
            return Err(self
                .s
                .err(format!("file ends after {name}: expected {what}")));
        };
        t.u64().ok_or_else(|| {
            self.s.err_at(
                &t,
                format!(
                    "{name} (line {}): expected {what}, found {}",
                    kw.line,
                    t.show()
                ),
            )
        })
    }

    /// The next number of entry `e` of section `sec`. An error at the end of the file, or
    /// when a keyword or anything else that is not a number comes first.
    fn number(&mut self, sec: &Section, e: &Entry) -> Result<Token<'a>> {
        let Section {
            name,
            one,
            count,
            per,
            ..
        } = *sec;
        let i = e.i;
        let got = show(e.got.trim_ascii());
        let Some(t) = self.s.token(true) else {
            let partial = if e.got.is_empty() {
                String::new()
            } else {
                format!(" ({one} {} has {got} of its {per} numbers)", i + 1)
            };
            return Err(self.s.err(format!(
                "file ends in {name} after {i} of {count} entries{partial}"
            )));
        };
        if t.f64().is_some() {
            return Ok(t);
        }
        if !e.got.is_empty() {
            return Err(Error::format(
                self.s.path,
                Location::Line(e.line),
                format!(
                    "{name}: expected {per} numbers per {one} ({}), found {got} then {}",
                    sec.layout,
                    t.show()
                ),
            ));
        }
        if is_keyword(&t) {
            return Err(self.s.err_at(
                &t,
                format!(
                    "{name}: expected {count} entries, found {i} before {}",
                    t.show()
                ),
            ));
        }
        Err(self.s.err_at(
            &t,
            format!(
                "{name}: {one} {}: expected a number, found {}",
                i + 1,
                t.show()
            ),
        ))
    }

    /// The numbers of entry `i` of `sec`, passed to `each` with their position in the entry.
    fn entry(
        &mut self,
        sec: &Section,
        i: u64,
        mut each: impl FnMut(&Scan, usize, Token<'a>) -> Result<()>,
    ) -> Result<()> {
        let data = self.s.data;
        let start = self.s.pos;
        let mut line = 0;
        for k in 0..sec.per {
            let e = Entry {
                i,
                got: &data[start..self.s.pos],
                line,
            };
            let t = self.number(sec, &e)?;
            if k == 0 {
                line = t.line;
            }
            each(&self.s, k, t)?;
        }
        Ok(())
    }

    /// `Vertices`: count, then x y z ref each.
    fn vertices(&mut self, kw: &Token) -> Result<()> {
        if self.dimension.is_none() {
            return Err(self.s.err_at(
                kw,
                "Vertices before Dimension: expected `Dimension 3` first",
            ));
        }
        if self.nverts.is_some() {
            return Err(self.s.err_at(kw, "a second Vertices section"));
        }
        let count = self.count(kw, "Vertices", "the vertex count")?;
        if count > u32::MAX as u64 {
            return Err(self.s.err_at(
                kw,
                format!("Vertices: {count} vertices are more than 32-bit indices address"),
            ));
        }
        let sec = Section {
            name: "Vertices",
            one: "vertex",
            layout: "x y z and a reference".into(),
            count,
            per: 4,
        };
        let mut verts = Vec::with_capacity(capacity(count, self.s.remaining(), 8));
        for i in 0..count {
            let mut p = [0.0; 3];
            self.entry(&sec, i, |s, k, t| {
                if k < 3 {
                    p[k] = t.f64().unwrap_or(f64::NAN);
                    if !p[k].is_finite() {
                        return Err(s.err_at(
                            &t,
                            format!(
                                "Vertices: vertex {}: {} is {}, expected a finite coordinate",
                                i + 1,
                                ["x", "y", "z"][k],
                                t.show()
                            ),
                        ));
                    }
                }
                Ok(())
            })?;
            verts.push(p);
        }
        self.nverts = Some(verts.len());
        self.mesh.verts = verts;
        Ok(())
    }

    /// An element section of `n` vertices and a reference per entry.
    fn elements(&mut self, kw: &Token, name: &str, n: usize, keep: Keep, one: &str) -> Result<()> {
        let count = self.count(kw, name, "the number of entries")?;
        let sec = Section {
            name,
            one,
            layout: format!("{n} vertices and a reference"),
            count,
            per: n + 1,
        };
        let first = match keep {
            Keep::Tet => self.mesh.tets.len(),
            Keep::Hex => self.mesh.hexes.len(),
            Keep::Tri => self.mesh.triangles.len(),
            Keep::Skip => 0,
        };
        let cap = capacity(count, self.s.remaining(), 2 * sec.per);
        match keep {
            Keep::Tet => self.mesh.tets.reserve(cap),
            Keep::Hex => self.mesh.hexes.reserve(cap),
            Keep::Tri => self.mesh.triangles.reserve(cap),
            Keep::Skip => {}
        }
        let nverts = self.nverts;
        let mut idx = [0u32; 8];
        for i in 0..count {
            self.entry(&sec, i, |s, k, t| {
                if k == n || keep == Keep::Skip {
                    return Ok(()); // the reference, or an entry not kept
                }
                let Some(v) = t.u64() else {
                    return Err(s.err_at(
                        &t,
                        format!(
                            "{name}: {one} {}: expected a vertex index (a whole number from 1), \
                             found {}",
                            i + 1,
                            t.show()
                        ),
                    ));
                };
                if v == 0 {
                    return Err(s.err_at(
                        &t,
                        format!(
                            "{name}: {one} {}: vertex 0 is not an index (MEDIT indices start at 1)",
                            i + 1
                        ),
                    ));
                }
                let limit = nverts.map_or(u32::MAX as u64, |nv| nv as u64);
                if v > limit {
                    let nv = nverts.map_or("addressable".to_string(), |nv| nv.to_string());
                    return Err(s.err_at(
                        &t,
                        format!(
                            "{name}: {one} {}: vertex {v} is beyond the {nv} vertices",
                            i + 1
                        ),
                    ));
                }
                idx[k] = (v - 1) as u32;
                Ok(())
            })?;
            match keep {
                Keep::Tet => self.mesh.tets.push([idx[0], idx[1], idx[2], idx[3]]),
                Keep::Hex => self.mesh.hexes.push(idx),
                Keep::Tri => self.mesh.triangles.push([idx[0], idx[1], idx[2]]),
                Keep::Skip => {}
            }
        }
        if keep == Keep::Skip {
            self.mesh
                .skip(name, usize::try_from(count).unwrap_or(usize::MAX));
        } else if self.nverts.is_none() {
            self.unchecked.push((keep, first, kw.line));
        }
        Ok(())
    }

    /// A section skipped whole, `n` numbers per entry.
    fn skipped(&mut self, kw: &Token, name: &str, n: usize) -> Result<()> {
        let count = self.count(kw, name, "the number of entries")?;
        let sec = Section {
            name,
            one: "entry",
            layout: format!("{n} number{}", if n == 1 { "" } else { "s" }),
            count,
            per: n,
        };
        for i in 0..count {
            self.entry(&sec, i, |_, _, _| Ok(()))?;
        }
        self.mesh
            .skip(name, usize::try_from(count).unwrap_or(usize::MAX));
        Ok(())
    }
}

/// Write `verts` and `cells` as MEDIT ASCII (1-based, every reference 0).
pub(super) fn write<const K: usize>(
    w: &mut impl Write,
    verts: &[[f64; 3]],
    cells: &[[u32; K]],
    kind: Cell,
) -> std::io::Result<()> {
    writeln!(w, "MeshVersionFormatted 2\n\nDimension 3\n")?;
    writeln!(w, "Vertices\n{}", verts.len())?;
    for p in verts {
        writeln!(w, "{} {} {} 0", fmt_f64(p[0]), fmt_f64(p[1]), fmt_f64(p[2]))?;
    }
    let keyword = match kind {
        Cell::Tet => "Tetrahedra",
        Cell::Hex => "Hexahedra",
    };
    writeln!(w, "\n{keyword}\n{}", cells.len())?;
    for c in cells {
        for v in c {
            write!(w, "{} ", v + 1)?;
        }
        writeln!(w, "0")?;
    }
    writeln!(w, "\nEnd")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A valid tetrahedron, one entry per line: line 3 `Vertices`, vertices on lines 5 to 8,
    /// `Tetrahedra` on 9, the tetrahedron on 11, `End` on 12.
    const TET: &str = "MeshVersionFormatted 2\nDimension 3\nVertices\n4\n0 0 0 1\n1 0 0 1\n\
                       0 1 0 1\n0 0 1 1\nTetrahedra\n1\n1 2 3 4 10\nEnd\n";

    fn read_str(text: &str) -> Result<VolumeMesh> {
        read(Path::new("dir/bad.mesh"), text.as_bytes())
    }

    /// The error for `text`, which must name the file and contain every one of `want`.
    fn err(text: &str, want: &[&str]) {
        let e = read_str(text).unwrap_err().to_string();
        assert!(e.starts_with("dir/bad.mesh: "), "{e}");
        for w in want {
            assert!(e.contains(w), "{e:?} lacks {w:?}");
        }
    }

    #[test]
    fn reads_a_tetrahedron() {
        let m = read_str(TET).unwrap();
        assert_eq!(m.verts.len(), 4);
        assert_eq!(m.tets, vec![[0, 1, 2, 3]]);
        assert!(m.skipped.is_empty());
    }

    #[test]
    fn tokens_comments_case_and_skipped_sections() {
        // Keywords and numbers split across lines, comments anywhere, CRLF, other case,
        // sections before Vertices, skipped sections, anything after End ignored.
        let text = "# a comment\r\nmeshversionformatted\r\n 1 DIMENSION 3 # trailing\n\
                    Hexahedra 1 1 2 3 4\n5 6 7 8 0\nCorners 2 1 2\nEdges 1 1 2 7\n\
                    Normals 1 0 0 1 NormalAtVertices 1 1 1\n\
                    Vertices 8\n0 0 0 0 1 0 0 0 1 1 0 0 0 1 0 0\n0 0 1 0#x\n1 0 1 0 1 1 1 0 \
                    0 1 1 0\nTriangles 1 1 2 3 0 Quadrilaterals 1 1 2 3 4 0\nPrisms 0\n\
                    end\nnot a keyword at all";
        let m = read_str(text).unwrap();
        assert_eq!(m.verts.len(), 8);
        assert_eq!(m.verts[6], [1.0, 1.0, 1.0]);
        assert_eq!(m.hexes, vec![[0, 1, 2, 3, 4, 5, 6, 7]]);
        assert_eq!(m.triangles, vec![[0, 1, 2]]);
        let skipped: Vec<(&str, usize)> = m.skipped.iter().map(|(k, n)| (k.as_str(), *n)).collect();
        assert_eq!(
            skipped,
            [
                ("Corners", 2),
                ("Edges", 1),
                ("Normals", 1),
                ("NormalAtVertices", 1),
                ("Quadrilaterals", 1)
            ]
        );
    }

    #[test]
    fn reads_gmsh_output() {
        // As gmsh 4.15 writes a single hexahedron (leading spaces, wide columns).
        let text = " MeshVersionFormatted 2\n Dimension\n 3\n Vertices\n 8\n\
                    \x20                   0                         0                         1      1\n\
                    \x20                   0                         0                         0      2\n\
                    \x20                   0                         1                         1      3\n\
                    \x20                   0                         1                         0      4\n\
                    \x20                   2                         0                         1      5\n\
                    \x20                   2                         0                         0      6\n\
                    \x20                   2                         1                         1      7\n\
                    \x20                   2                         1                         0      8\n\
                    \x20Hexahedra\n 1\n 3 1 2 4 7 5 6 8 1\n End\n";
        let m = read_str(text).unwrap();
        assert_eq!(m.verts[0], [0.0, 0.0, 1.0]);
        assert_eq!(m.verts[7], [2.0, 1.0, 0.0]);
        assert_eq!(m.hexes, vec![[2, 0, 1, 3, 6, 4, 5, 7]]);
    }

    #[test]
    fn end_is_optional_but_a_cut_token_is_an_error() {
        let no_end = TET.strip_suffix("End\n").unwrap();
        assert_eq!(read_str(no_end).unwrap().tets.len(), 1);
        // The reference 10 cut to 1: still a number, but the file ends inside it.
        err(
            no_end.strip_suffix("0\n").unwrap(),
            &["line 11: ", "ends inside \"1\"", "truncated"],
        );
        // A comment after the last number without a line end is no cut.
        let commented = format!("{no_end}# done");
        assert_eq!(read_str(&commented).unwrap().tets.len(), 1);
    }

    #[test]
    fn truncated_files() {
        let at = |n: usize| TET.lines().take(n).collect::<Vec<_>>().join("\n") + "\n";
        err(
            &at(6),
            &["line 7: ", "file ends in Vertices after 2 of 4 entries"],
        );
        err(
            &(at(6) + "0 1"),
            &[
                "file ends in Vertices after 2 of 4 entries",
                "(vertex 3 has \"0 1\" of its 4 numbers)",
            ],
        );
        err(
            &at(3),
            &[
                "line 4: ",
                "file ends after Vertices: expected the vertex count",
            ],
        );
        err(&at(10), &["file ends in Tetrahedra after 0 of 1 entries"]);
        // The file ends after the vertices: no tetrahedra, which the caller reports.
        assert!(read_str(&at(8)).unwrap().tets.is_empty());
    }

    #[test]
    fn missing_sections() {
        err(
            "MeshVersionFormatted 2\nDimension 3\nTetrahedra\n1\n1 2 3 4 0\nEnd\n",
            &["line 6: ", "no Vertices section: expected `Vertices`"],
        );
        err(
            "MeshVersionFormatted 2\nVertices\n0\n",
            &[
                "line 2: ",
                "Vertices before Dimension: expected `Dimension 3` first",
            ],
        );
        err(
            &TET.replace("End", "Vertices 0"),
            &["line 12: ", "a second Vertices"],
        );
    }

    #[test]
    fn indices_out_of_range() {
        err(
            &TET.replace("1 2 3 4 10", "1 2 3 9 10"),
            &[
                "line 11: ",
                "Tetrahedra: tetrahedron 1: vertex 9 is beyond the 4 vertices",
            ],
        );
        err(
            &TET.replace("1 2 3 4 10", "0 2 3 4 10"),
            &[
                "line 11: ",
                "vertex 0 is not an index (MEDIT indices start at 1)",
            ],
        );
        err(
            &TET.replace("1 2 3 4 10", "1 2 -3 4 10"),
            &[
                "line 11: ",
                "expected a vertex index (a whole number from 1), found \"-3\"",
            ],
        );
        err(
            &TET.replace("1 2 3 4 10", "1 2 3.5 4 10"),
            &["expected a vertex index", "found \"3.5\""],
        );
        // A section before Vertices is checked once they are known, at its keyword's line.
        let early = "MeshVersionFormatted 2\nDimension 3\nTetrahedra\n1\n1 2 3 5 0\n\
                     Vertices\n4\n0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\nEnd\n";
        err(
            early,
            &[
                "line 3: ",
                "tetrahedron 1: vertex 5 is beyond the 4 vertices",
            ],
        );
        let early = early.replace("1 2 3 5 0", "1 2 3 4 0");
        assert_eq!(read_str(&early).unwrap().tets, vec![[0, 1, 2, 3]]);
    }

    #[test]
    fn non_finite_coordinates() {
        for (bad, shown) in [
            ("nan", "\"nan\""),
            ("inf", "\"inf\""),
            ("1e999", "\"1e999\""),
        ] {
            err(
                &TET.replace("1 0 0 1\n", &format!("1 {bad} 0 1\n")),
                &[
                    "line 6: ",
                    &format!("Vertices: vertex 2: y is {shown}, expected a finite coordinate"),
                ],
            );
        }
    }

    #[test]
    fn unknown_and_misplaced_tokens() {
        err(
            &TET.replace("Tetrahedra", "Tetraedres"),
            &[
                "line 9: ",
                "unknown keyword \"Tetraedres\"",
                "supported: MeshVersionFormatted",
            ],
        );
        err(
            &TET.replace("Tetrahedra", "TetrahedraP2"),
            &[
                "line 9: ",
                "\"TetrahedraP2\": higher-order elements are not supported",
            ],
        );
        err(
            &TET.replace("Tetrahedra", "HexahedraQ2"),
            &["higher-order", "expected linear Hexahedra"],
        );
        // A count larger than the entries: the next keyword comes early.
        err(
            &TET.replace("Vertices\n4", "Vertices\n5"),
            &[
                "line 9: ",
                "Vertices: expected 5 entries, found 4 before \"Tetrahedra\"",
            ],
        );
        // A count smaller than the entries: a number where a keyword belongs.
        err(
            &TET.replace("Vertices\n4", "Vertices\n3"),
            &["line 8: ", "expected a keyword, found the number \"0\""],
        );
        err(
            &TET.replace("0 1 0 1", "0 1 x 1"),
            &[
                "line 7: ",
                "Vertices: expected 4 numbers per vertex (x y z and a reference), found \
                 \"0 1\" then \"x\"",
            ],
        );
        err(
            &TET.replace("Vertices\n4", "Vertices\nfour"),
            &[
                "line 4: ",
                "Vertices (line 3): expected the vertex count, found \"four\"",
            ],
        );
        err(
            &TET.replace("Vertices\n4", "Vertices\n99999999999"),
            &["line 3: ", "more than 32-bit indices address"],
        );
        err(
            &TET.replace("Dimension 3", "Dimension 2"),
            &["line 2: ", "planar mesh"],
        );
        err(
            &TET.replace("MeshVersionFormatted 2", "MeshVersionFormatted 7"),
            &["line 1: ", "expected 1, 2, 3 or 4, found 7"],
        );
        let e = read(Path::new("b.mesh"), b"\x01\x00\x00\x00\x03\x00\x00\x00")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("b.mesh: line 1: ") && e.contains("binary data"),
            "{e}"
        );
    }
}
