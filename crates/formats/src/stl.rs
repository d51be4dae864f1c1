//! STL triangle meshes, binary or ASCII, for `check` and as reference or hexmesh surfaces.
//!
//! **Binary**: an 80-byte header, a u32 triangle count, then 50 bytes a triangle (normal,
//! three corners as float32 little endian, a u16 attribute). A file is binary when its size
//! is exactly `84 + 50 × count`, whatever its header says: some binary writers start the
//! header with `solid`, the ASCII keyword. **ASCII**: `solid [name]`, then per triangle
//! `facet normal nx ny nz`, `outer loop`, three `vertex x y z`, `endloop`, `endfacet`, and
//! `endsolid`. Only the corners are read; the stored normals are checked to be numbers and
//! otherwise ignored (the winding gives the orientation, as the format says).
//!
//! STL repeats each corner in every triangle: corners with the same coordinates (bit for bit,
//! −0 taken as +0) become one vertex, numbered in order of first appearance, so the mesh's
//! topology (edges shared by two triangles, closed surfaces) can be checked.
//!
//! Errors name the file and the byte (binary) or line (ASCII), what was expected and what
//! was found: a truncated file, a count that does not match the size, a token that is not a
//! number, a coordinate that is not finite, a facet without three vertices.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

use crate::error::{Error, IoContext, Location, Result};
use crate::mesh::Mesh;

/// Bytes of the binary header and count, and of one binary triangle.
const HEADER: u64 = 84;
const TRIANGLE: u64 = 50;

/// Read an STL file, binary or ASCII, as an indexed triangle mesh (see the module docs).
pub fn read_stl(path: &Path) -> Result<Mesh> {
    let meta = crate::regular_file(path, "an STL file")?;
    let mut file = File::open(path).with_path(path)?;
    let mut head = [0u8; HEADER as usize];
    let got = read_up_to(&mut file, &mut head).with_path(path)?;
    if got == HEADER as usize {
        let count = u32::from_le_bytes(head[80..84].try_into().expect("4 bytes"));
        if meta.len() == HEADER + TRIANGLE * u64::from(count) {
            return read_binary(path, file, count);
        }
    }
    if !head[..got].trim_ascii_start().starts_with(b"solid") {
        return Err(Error::format(
            path,
            Location::Byte(0),
            format!(
                "not an STL file: {} bytes is not 84 + 50 × the binary triangle count, and the text does not start with \"solid\"",
                meta.len()
            ),
        ));
    }
    let file = File::open(path).with_path(path)?;
    read_ascii(path, BufReader::with_capacity(1 << 20, file))
}

/// Fill `buf` as far as the file goes; the bytes read.
fn read_up_to(f: &mut File, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match f.read(&mut buf[n..])? {
            0 => break,
            k => n += k,
        }
    }
    Ok(n)
}

/// Corners welded into vertices by their coordinates.
#[derive(Default)]
struct Welder {
    mesh: Mesh,
    index: HashMap<[u32; 3], u32>,
}

impl Welder {
    /// The vertex at `p` (float32 coordinates, finite).
    fn vertex(&mut self, p: [f32; 3]) -> u32 {
        // -0 and +0 are the same point.
        let key = p.map(|x| if x == 0.0 { 0 } else { x.to_bits() });
        let next = self.mesh.vertices.len() as u32;
        *self.index.entry(key).or_insert_with(|| {
            self.mesh.vertices.push(p.map(f64::from));
            next
        })
    }
}

/// The triangles of a binary STL, `file` read past its header.
fn read_binary(path: &Path, file: File, count: u32) -> Result<Mesh> {
    let mut r = BufReader::with_capacity(1 << 20, file);
    let mut w = Welder::default();
    w.mesh.triangles.reserve(count as usize);
    let mut rec = [0u8; TRIANGLE as usize];
    for t in 0..u64::from(count) {
        r.read_exact(&mut rec).with_path(path)?;
        let f = |k: usize| f32::from_le_bytes(rec[4 * k..4 * k + 4].try_into().expect("4"));
        let mut tri = [0u32; 3];
        for (c, v) in tri.iter_mut().enumerate() {
            let p = [f(3 + 3 * c), f(4 + 3 * c), f(5 + 3 * c)];
            if let Some(bad) = p.iter().find(|x| !x.is_finite()) {
                return Err(Error::format(
                    path,
                    Location::Byte(HEADER + TRIANGLE * t + 12 + 12 * c as u64),
                    format!("triangle {t}, corner {c}: coordinate {bad} is not finite"),
                ));
            }
            *v = w.vertex(p);
        }
        w.mesh.triangles.push(tri);
    }
    Ok(w.mesh)
}

fn read_ascii(path: &Path, mut r: impl BufRead) -> Result<Mesh> {
    let mut w = Welder::default();
    let mut raw: Vec<u8> = Vec::new();
    let mut no = 0u64;
    let mut corners: Vec<u32> = Vec::with_capacity(3);
    let mut in_facet = false;
    let mut ended = false;
    let bad = |no: u64, msg: String| Error::format(path, Location::Line(no), msg);
    loop {
        raw.clear();
        if r.read_until(b'\n', &mut raw).with_path(path)? == 0 {
            break;
        }
        no += 1;
        let Ok(line) = std::str::from_utf8(&raw) else {
            return Err(bad(
                no,
                "not text: a binary STL whose size does not match its triangle count (truncated?), or a damaged ASCII one".to_string(),
            ));
        };
        let mut tok = line.split_ascii_whitespace();
        let Some(word) = tok.next() else { continue };
        let numbers = |tok: std::str::SplitAsciiWhitespace, what: &str| -> Result<[f32; 3]> {
            let v: Vec<&str> = tok.collect();
            if v.len() != 3 {
                return Err(bad(
                    no,
                    format!("{what}: expected 3 numbers, found {}", v.len()),
                ));
            }
            let mut p = [0f32; 3];
            for (x, s) in p.iter_mut().zip(&v) {
                *x = s
                    .parse()
                    .map_err(|_| bad(no, format!("{what}: expected a number, found {s:?}")))?;
                if !x.is_finite() {
                    return Err(bad(no, format!("{what}: coordinate {s} is not finite")));
                }
            }
            Ok(p)
        };
        match word {
            "solid" if no == 1 => {}
            "facet" => {
                if in_facet {
                    return Err(bad(no, "facet inside a facet (missing endfacet)".into()));
                }
                if tok.next() != Some("normal") {
                    return Err(bad(no, "expected \"facet normal nx ny nz\"".into()));
                }
                numbers(tok, "facet normal")?;
                in_facet = true;
                corners.clear();
            }
            "outer" | "endloop" => {}
            "vertex" => {
                if !in_facet {
                    return Err(bad(no, "vertex outside a facet".into()));
                }
                let p = numbers(tok, "vertex")?;
                corners.push(w.vertex(p));
            }
            "endfacet" => {
                if corners.len() != 3 {
                    return Err(bad(
                        no,
                        format!("facet with {} vertices, expected 3", corners.len()),
                    ));
                }
                w.mesh.triangles.push([corners[0], corners[1], corners[2]]);
                in_facet = false;
            }
            "endsolid" => {
                ended = true;
                break;
            }
            other => {
                return Err(bad(
                    no,
                    format!("expected facet, vertex, endfacet or endsolid, found {other:?}"),
                ));
            }
        }
    }
    if in_facet || !ended {
        return Err(bad(
            no,
            "the file ends before endsolid (truncated?)".to_string(),
        ));
    }
    Ok(w.mesh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh_write::{MeshFormat, MeshWriter, VertexFormat};

    const TETRA: [[f64; 3]; 4] = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    const FACES: [[u32; 3]; 4] = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];

    /// `m` is the tetrahedron: its corners numbered by first appearance (0, 2, 1, 3).
    fn is_tetra(m: &Mesh) {
        assert_eq!(
            m.vertices,
            [TETRA[0], TETRA[2], TETRA[1], TETRA[3]].to_vec()
        );
        let corners: Vec<[[f64; 3]; 3]> = m
            .triangles
            .iter()
            .map(|t| t.map(|i| m.vertices[i as usize]))
            .collect();
        let want: Vec<[[f64; 3]; 3]> = FACES.iter().map(|t| t.map(|i| TETRA[i as usize])).collect();
        assert_eq!(corners, want);
    }

    #[test]
    fn binary_stl_from_our_writer_welds_back_to_the_mesh() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.stl");
        let mut w = MeshWriter::create(&p, MeshFormat::Stl, VertexFormat::default()).unwrap();
        for v in TETRA {
            w.vertex(v, None).unwrap();
        }
        for t in FACES {
            w.triangle(t.map(u64::from)).unwrap();
        }
        w.finish().unwrap();
        is_tetra(&read_stl(&p).unwrap());
        // A header starting with "solid" is still binary when the size says so.
        let mut bytes = std::fs::read(&p).unwrap();
        bytes[..5].copy_from_slice(b"solid");
        std::fs::write(&p, &bytes).unwrap();
        assert_eq!(read_stl(&p).unwrap().triangles.len(), 4);
        // Truncated: the size no longer matches and the text is not ASCII STL.
        std::fs::write(&p, &bytes[..bytes.len() - 1]).unwrap();
        let e = read_stl(&p).unwrap_err().to_string();
        assert!(e.contains("t.stl") && e.contains("line"), "{e}");
        bytes[..5].copy_from_slice(b"abcde");
        std::fs::write(&p, &bytes[..bytes.len() - 1]).unwrap();
        let e = read_stl(&p).unwrap_err().to_string();
        assert!(e.contains("not an STL file"), "{e}");
        // A NaN corner.
        bytes[84 + 12..84 + 16].copy_from_slice(&f32::NAN.to_le_bytes());
        std::fs::write(&p, &bytes).unwrap();
        let e = read_stl(&p).unwrap_err().to_string();
        assert!(e.contains("byte 96") && e.contains("not finite"), "{e}");
    }

    #[test]
    fn ascii_stl_reads_and_its_errors_name_the_line() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.stl");
        let mut text = String::from("solid tetra\n");
        for t in FACES {
            text.push_str("  facet normal 0 0 0\n    outer loop\n");
            for i in t {
                let v = TETRA[i as usize];
                text.push_str(&format!("      vertex {} {} {}\n", v[0], v[1], -0.0 + v[2]));
            }
            text.push_str("    endloop\n  endfacet\n");
        }
        text.push_str("endsolid tetra\n");
        std::fs::write(&p, &text).unwrap();
        is_tetra(&read_stl(&p).unwrap());
        let broken = text.replacen("vertex 1 0 0", "vertex 1 zero 0", 1);
        std::fs::write(&p, broken).unwrap();
        let e = read_stl(&p).unwrap_err().to_string();
        assert!(e.contains("line 6") && e.contains("\"zero\""), "{e}");
        std::fs::write(&p, text.replace("endsolid tetra\n", "")).unwrap();
        let e = read_stl(&p).unwrap_err().to_string();
        assert!(e.contains("before endsolid"), "{e}");
        let two = text.replacen("      vertex 0 0 0\n", "", 1);
        std::fs::write(&p, two).unwrap();
        let e = read_stl(&p).unwrap_err().to_string();
        assert!(e.contains("facet with 2 vertices"), "{e}");
    }
}
