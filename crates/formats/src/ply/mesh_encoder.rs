//! The PLY encoders of the streamed mesh writer ([`crate::mesh_write`], which stages the mesh
//! and calls them from `finish`): the binary little-endian writer with its fixed-size header
//! (the room for the largest counts, padded by a comment line), and the ASCII writer with the
//! same header unpadded. The header's grammar and the record layout are documented in
//! [`crate::mesh_write`].

use std::fmt::Write as _;
use std::io::Write;

use crate::error::{IoContext, Result};
use crate::mesh_write::text::num;
use crate::mesh_write::{MeshWriter, VertexFormat};

/// Bytes of one binary PLY face record: the count byte and 3 indices.
pub(crate) const FACE_BYTES: u64 = 1 + 3 * 4;

/// The header lines before the padding comment, and after it.
fn header_parts(vertices: u64, faces: u64, f: VertexFormat, ascii: bool) -> (String, String) {
    let head = format!(
        "ply\nformat {} 1.0\ncomment written by scanflow\n",
        if ascii {
            "ascii"
        } else {
            "binary_little_endian"
        }
    );
    let mut tail = format!("element vertex {vertices}\n");
    let ty = if f.double { "double" } else { "float" };
    for n in ["x", "y", "z"] {
        tail.push_str(&format!("property {ty} {n}\n"));
    }
    if f.normals {
        for n in ["nx", "ny", "nz"] {
            tail.push_str(&format!("property float {n}\n"));
        }
    }
    if f.color {
        for n in ["red", "green", "blue"] {
            tail.push_str(&format!("property uchar {n}\n"));
        }
    }
    if f.intensity {
        tail.push_str("property float scalar_intensity\n");
    }
    if f.density {
        tail.push_str("property float quality\n");
    }
    let index = if vertices <= i32::MAX as u64 {
        "int"
    } else {
        "uint"
    };
    tail.push_str(&format!(
        "element face {faces}\nproperty list uchar {index} vertex_indices\nend_header\n"
    ));
    (head, tail)
}

/// The padding line: `comment`, a space, spaces up to `len` bytes with its newline.
const PAD_MIN: usize = "comment \n".len();

/// Bytes of the header of every binary PLY of vertex format `f`.
pub fn header_bytes(f: VertexFormat) -> usize {
    let (h, t) = header_parts(u64::MAX, u64::MAX, f, false);
    h.len() + t.len() + PAD_MIN
}

/// The binary header for the given counts, padded to exactly `header_bytes(f)` bytes.
pub(crate) fn header(vertices: u64, faces: u64, f: VertexFormat) -> String {
    let (head, tail) = header_parts(vertices, faces, f, false);
    let pad = header_bytes(f) - head.len() - tail.len();
    let mut h = head;
    h.push_str("comment");
    h.extend(std::iter::repeat_n(' ', pad - "comment\n".len()));
    h.push('\n');
    h.push_str(&tail);
    h
}

impl MeshWriter {
    pub(crate) fn write_ply_binary(&mut self, w: &mut impl Write) -> Result<()> {
        let (vf, tmp) = (self.vertex_format(), self.tmp_path().to_path_buf());
        let (vertices, faces) = self.counts_out();
        w.write_all(header(vertices, faces, vf).as_bytes())
            .with_path(&tmp)?;
        let mut rec = Vec::with_capacity(vf.stride());
        self.each_vertex(|v, n| {
            rec.clear();
            for x in v.p {
                if vf.double {
                    rec.extend_from_slice(&x.to_le_bytes());
                } else {
                    rec.extend_from_slice(&(x as f32).to_le_bytes());
                }
            }
            if vf.normals {
                for x in n {
                    rec.extend_from_slice(&x.to_le_bytes());
                }
            }
            if vf.color {
                rec.extend_from_slice(&v.color);
            }
            if vf.intensity {
                rec.extend_from_slice(&v.intensity.to_le_bytes());
            }
            if vf.density {
                rec.extend_from_slice(&v.density.to_le_bytes());
            }
            w.write_all(&rec).with_path(&tmp)
        })?;
        self.each_face(true, |t| {
            let mut r = [0u8; FACE_BYTES as usize];
            r[0] = 3;
            for k in 0..3 {
                r[1 + 4 * k..5 + 4 * k].copy_from_slice(&t[k].to_le_bytes());
            }
            w.write_all(&r).with_path(&tmp)
        })
    }

    pub(crate) fn write_ply_ascii(&mut self, w: &mut impl Write) -> Result<()> {
        let (vf, tmp) = (self.vertex_format(), self.tmp_path().to_path_buf());
        let (vertices, faces) = self.counts_out();
        let (h, t) = header_parts(vertices, faces, vf, true);
        w.write_all(h.as_bytes()).with_path(&tmp)?;
        w.write_all(t.as_bytes()).with_path(&tmp)?;
        let mut line = String::new();
        self.each_vertex(|v, n| {
            line.clear();
            for (k, x) in v.p.into_iter().enumerate() {
                if k > 0 {
                    line.push(' ');
                }
                num(&mut line, x, vf.double);
            }
            if vf.normals {
                for x in n {
                    line.push(' ');
                    num(&mut line, x.into(), false);
                }
            }
            if vf.color {
                let [r, g, b] = v.color;
                let _ = write!(line, " {r} {g} {b}");
            }
            if vf.intensity {
                line.push(' ');
                num(&mut line, v.intensity.into(), false);
            }
            if vf.density {
                line.push(' ');
                num(&mut line, v.density.into(), false);
            }
            line.push('\n');
            w.write_all(line.as_bytes()).with_path(&tmp)
        })?;
        self.each_face(true, |[a, b, c]| {
            writeln!(w, "3 {a} {b} {c}").with_path(&tmp)
        })
    }
}
