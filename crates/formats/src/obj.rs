//! Wavefront OBJ triangle meshes: positions and faces, for stuffing a closed surface given as
//! OBJ (the PLY reader, [`crate::mesh_read`], reads the other common format).
//!
//! What is read:
//!
//! * `v x y z [w]`: a vertex. Only `x y z` are kept; a fourth number (the rational weight `w`)
//!   and the per-vertex colour some writers append (`v x y z r g b`) are read as numbers and
//!   dropped. Every coordinate must be finite.
//! * `f a b c …`: a polygon of at least three corners. Each corner is `i`, `i/t`, `i//n` or
//!   `i/t/n`: `i` is the 1-based position index, `t` and `n` (texture and normal indices) are
//!   checked to be integers and otherwise ignored. A negative `i` counts back from the last
//!   vertex defined before the face (`-1` is the latest). Positive indices may refer to
//!   vertices defined later in the file, as several writers rely on; they are checked against
//!   the final vertex count. A polygon `(v0, v1, v2, v3, …)` is fanned into `(v0, v1, v2)`,
//!   `(v0, v2, v3)`, … which keeps its winding.
//! * Everything else (`vt`, `vn`, `g`, `o`, `s`, `usemtl`, `mtllib`, `l`, `p`, free-form
//!   geometry, …) is ignored. `#` starts a comment that runs to the end of the line; a line
//!   ending in `\` continues on the next.
//!
//! Errors name the file and the 1-based line, what was expected and what was found: a token
//! that is not a number, a coordinate that is not finite, an index of 0 or outside the
//! vertices, a face with fewer than three corners. A file without any face is an error too
//! (a mesh is expected).
//!
//! The mesh is held in memory (24 bytes a vertex, 12 a triangle); the file is streamed
//! through a buffered reader, one line at a time.

use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::Path;

use crate::error::{Error, IoContext, Location, Result};
use crate::mesh::Mesh;

/// Read a Wavefront OBJ file as a triangle mesh (see the module docs for what is read).
pub fn read_obj(path: &Path) -> Result<Mesh> {
    crate::regular_file(path, "an OBJ file")?;
    let file = File::open(path).with_path(path)?;
    parse_obj(path, BufReader::with_capacity(1 << 20, file))
}

/// The largest positive index seen and the line it is on (checked at the end of the file).
#[derive(Clone, Copy, Default)]
struct MaxIndex {
    index: u64,
    line: u64,
}

/// Parse OBJ text from `reader`; `path` only names the file in errors.
fn parse_obj(path: &Path, mut reader: impl BufRead) -> Result<Mesh> {
    let mut mesh = Mesh::default();
    let mut buf: Vec<u8> = Vec::new();
    let mut logical: Vec<u8> = Vec::new();
    let mut line_no: u64 = 0;
    let mut max_index = MaxIndex::default();
    let mut corners: Vec<u32> = Vec::new();
    let mut faces: u64 = 0;
    loop {
        // One logical line: physical lines joined where one ends in a backslash.
        logical.clear();
        let first_line = line_no + 1;
        let mut any = false;
        loop {
            buf.clear();
            let n = reader.read_until(b'\n', &mut buf).with_path(path)?;
            if n == 0 {
                break;
            }
            any = true;
            line_no += 1;
            while matches!(buf.last(), Some(b'\n' | b'\r')) {
                buf.pop();
            }
            if buf.last() == Some(&b'\\') {
                buf.pop();
                logical.extend_from_slice(&buf);
                logical.push(b' ');
                continue;
            }
            logical.extend_from_slice(&buf);
            break;
        }
        if !any {
            break;
        }
        let content = match logical.iter().position(|&b| b == b'#') {
            Some(i) => &logical[..i],
            None => &logical[..],
        };
        let mut tokens = content
            .split(|b| b.is_ascii_whitespace())
            .filter(|t| !t.is_empty());
        let Some(keyword) = tokens.next() else {
            continue;
        };
        let at = Location::Line(first_line);
        match keyword {
            b"v" => {
                let mut p = [0.0f64; 3];
                let mut n = 0usize;
                for tok in tokens {
                    let v = parse_f64(tok).ok_or_else(|| {
                        Error::format(
                            path,
                            at,
                            format!("vertex value {} is {}, expected a number", n + 1, show(tok)),
                        )
                    })?;
                    if n < 3 {
                        if !v.is_finite() {
                            return Err(Error::format(
                                path,
                                at,
                                format!(
                                    "vertex {} is {v}, expected a finite coordinate",
                                    ["x", "y", "z"][n]
                                ),
                            ));
                        }
                        p[n] = v;
                    }
                    n += 1;
                }
                if n < 3 {
                    return Err(Error::format(
                        path,
                        at,
                        format!("vertex has {n} numbers, expected at least 3 (v x y z [w])"),
                    ));
                }
                mesh.vertices.push(p);
            }
            b"f" => {
                corners.clear();
                for tok in tokens {
                    let v = parse_corner(tok, mesh.vertices.len() as u64)
                        .map_err(|msg| Error::format(path, at, msg))?;
                    if v.positive && v.index > max_index.index {
                        max_index = MaxIndex {
                            index: v.index,
                            line: first_line,
                        };
                    }
                    let i = u32::try_from(v.index - 1).map_err(|_| {
                        Error::format(
                            path,
                            at,
                            format!(
                                "face index {} is beyond the 4294967296 vertices scanflow reads",
                                v.index
                            ),
                        )
                    })?;
                    corners.push(i);
                }
                if corners.len() < 3 {
                    return Err(Error::format(
                        path,
                        at,
                        format!(
                            "face has {} corner{}, expected at least 3",
                            corners.len(),
                            if corners.len() == 1 { "" } else { "s" }
                        ),
                    ));
                }
                faces += 1;
                for k in 1..corners.len() - 1 {
                    mesh.triangles
                        .push([corners[0], corners[k], corners[k + 1]]);
                }
            }
            _ => {}
        }
    }
    let n = mesh.vertices.len() as u64;
    if max_index.index > n {
        return Err(Error::format(
            path,
            Location::Line(max_index.line),
            format!(
                "face index {} is out of range: the file defines {n} vertices (indices 1..={n})",
                max_index.index
            ),
        ));
    }
    if faces == 0 {
        return Err(Error::input(
            path,
            format!(
                "has no faces (no \"f\" statement among {line_no} lines): expected a triangle mesh"
            ),
        ));
    }
    Ok(mesh)
}

/// A face corner's position index, 1-based and resolved (a negative index made absolute).
struct Corner {
    index: u64,
    /// Written as a positive index (so possibly a forward reference, checked at the end).
    positive: bool,
}

/// Parse one face corner `i`, `i/t`, `i//n` or `i/t/n`, with `defined` vertices so far.
fn parse_corner(tok: &[u8], defined: u64) -> std::result::Result<Corner, String> {
    let mut parts = tok.split(|&b| b == b'/');
    let first = parts.next().unwrap_or_default();
    let idx = parse_i64(first).ok_or_else(|| {
        format!(
            "face corner {} has vertex index {}, expected an integer (forms i, i/t, i//n, i/t/n)",
            show(tok),
            show(first)
        )
    })?;
    let mut extra = 0;
    for (k, part) in parts.enumerate() {
        extra += 1;
        if extra > 2 {
            return Err(format!(
                "face corner {} has more than three '/'-separated parts, expected i, i/t, i//n or i/t/n",
                show(tok)
            ));
        }
        if part.is_empty() && k == 0 {
            continue; // i//n
        }
        if parse_i64(part).is_none() {
            let what = if k == 0 { "texture" } else { "normal" };
            return Err(format!(
                "face corner {} has {what} index {}, expected an integer",
                show(tok),
                show(part)
            ));
        }
    }
    if idx == 0 {
        return Err(format!(
            "face corner {} has vertex index 0, expected a 1-based index (or a negative, relative one)",
            show(tok)
        ));
    }
    if idx > 0 {
        return Ok(Corner {
            index: idx as u64,
            positive: true,
        });
    }
    let back = idx.unsigned_abs();
    if back > defined {
        return Err(format!(
            "face corner {} has relative index {idx}, but only {defined} vertices are defined before this line",
            show(tok)
        ));
    }
    Ok(Corner {
        index: defined - back + 1,
        positive: false,
    })
}

/// A token as text for messages (lossy for bytes that are not UTF-8, cut when long).
fn show(tok: &[u8]) -> String {
    let s = String::from_utf8_lossy(tok);
    if s.chars().count() > 40 {
        format!("\"{}…\"", s.chars().take(40).collect::<String>())
    } else {
        format!("\"{s}\"")
    }
}

fn parse_f64(tok: &[u8]) -> Option<f64> {
    std::str::from_utf8(tok).ok()?.parse().ok()
}

fn parse_i64(tok: &[u8]) -> Option<i64> {
    std::str::from_utf8(tok).ok()?.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn parse(text: &str) -> Result<Mesh> {
        parse_obj(Path::new("m.obj"), text.as_bytes())
    }

    fn err(text: &str) -> String {
        match parse(text) {
            Ok(m) => panic!("parsed: {m:?}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn reads_vertices_and_every_face_form() {
        let m = parse(
            "# a quad and a triangle\n\
             mtllib x.mtl\n\
             o thing\n\
             v 0 0 0\n\
             v 1 0 0 1.0\n\
             v 1 1 0 0.5 0.5 0.5\n\
             v 0 1 0\n\
             vt 0 0\n\
             vn 0 0 1\n\
             g g1\n\
             s off\n\
             usemtl m\n\
             f 1/1/1 2/1/1 3/1/1 4/1/1\n\
             f 1//1 2//1 3//1\n\
             f 1/1 3/1 4/1   # trailing comment\n\
             f 2 3 4\n\
             l 1 2\n",
        )
        .unwrap();
        assert_eq!(m.vertices.len(), 4);
        assert_eq!(m.vertices[2], [1.0, 1.0, 0.0]);
        assert_eq!(
            m.triangles,
            vec![[0, 1, 2], [0, 2, 3], [0, 1, 2], [0, 2, 3], [1, 2, 3]]
        );
    }

    #[test]
    fn negative_indices_are_relative_and_positive_may_look_ahead() {
        let m =
            parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nf 1 2 4\nv 0 0 1\nf -1 -2 -3\n").unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 1, 3], [3, 2, 1]]);
    }

    #[test]
    fn pentagon_is_fanned_keeping_the_winding() {
        let m = parse("v 0 0 0\nv 1 0 0\nv 2 1 0\nv 1 2 0\nv 0 1 0\nf 1 2 3 4 5\n").unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 3, 4]]);
    }

    #[test]
    fn continuation_lines_and_crlf() {
        let m = parse("v 0 0 0\r\nv 1 0 0\r\nv 0 1 \\\r\n 0\r\nf 1 2 \\\n3\r\n").unwrap();
        assert_eq!(m.vertices[2], [0.0, 1.0, 0.0]);
        assert_eq!(m.triangles, vec![[0, 1, 2]]);
    }

    #[test]
    fn errors_name_the_line_and_what_was_found() {
        let e = err("v 0 0 0\nv 1 x 0\n");
        assert!(
            e.contains("m.obj: line 2") && e.contains("\"x\"") && e.contains("expected a number"),
            "{e}"
        );
        let e = err("v 0 0\n");
        assert!(
            e.contains("line 1") && e.contains("has 2 numbers, expected at least 3"),
            "{e}"
        );
        let e = err("v 0 0 nan\n");
        assert!(e.contains("line 1") && e.contains("z is NaN"), "{e}");
        let e = err("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n");
        assert!(e.contains("line 4") && e.contains("vertex index 0"), "{e}");
        let e = err("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n# x\nf 1 2 9\n");
        assert!(
            e.contains("line 6")
                && e.contains("index 9 is out of range")
                && e.contains("3 vertices"),
            "{e}"
        );
        let e = err("v 0 0 0\nv 1 0 0\nf 1 -3 2\n");
        assert!(
            e.contains("line 3") && e.contains("relative index -3") && e.contains("only 2"),
            "{e}"
        );
        let e = err("v 0 0 0\nv 1 0 0\nf 1 2\n");
        assert!(
            e.contains("line 3") && e.contains("face has 2 corners, expected at least 3"),
            "{e}"
        );
        let e = err("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3/a\n");
        assert!(
            e.contains("line 4") && e.contains("texture index \"a\""),
            "{e}"
        );
        let e = err("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3/1/1/1\n");
        assert!(e.contains("more than three"), "{e}");
        let e = err("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 1.5\n");
        assert!(e.contains("vertex index \"1.5\""), "{e}");
        let e = err("v 0 0 0\nv 1 0 0\nv 0 1 0\n");
        assert!(e.contains("has no faces"), "{e}");
        let e = parse_obj(Path::new("m.obj"), &b"v 0 0 0\xff\n"[..])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 1") && e.contains("expected a number"),
            "{e}"
        );
    }

    #[test]
    fn reads_a_file_and_refuses_a_directory() {
        let d = tempfile::tempdir().unwrap();
        let p: PathBuf = d.path().join("t.obj");
        std::fs::write(
            &p,
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
        )
        .unwrap();
        let m = read_obj(&p).unwrap();
        assert_eq!(m.vertices.len(), 4);
        assert_eq!(m.triangles.len(), 4);
        assert!(m.check_indices().is_none());
        let e = read_obj(d.path()).unwrap_err().to_string();
        assert!(e.contains("is a directory"), "{e}");
        let e = read_obj(&d.path().join("missing.obj"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing.obj"), "{e}");
    }
}
