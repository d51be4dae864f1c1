//! The PLY encoders of the streamed mesh writer ([`super`], which stages the mesh and calls
//! them from `finish`): the binary little-endian writer with its fixed-size header (the room
//! for the largest counts, padded by a comment line), and the ASCII writer with the same
//! header unpadded. The header's grammar and the record layout are documented in [`super`];
//! the header is written from the model the PLY readers parse into ([`crate::ply`]'s header
//! writer), its vertex element starting as the point writer's does.

use std::fmt::Write as _;
use std::io::Write;

use super::text::num;
use super::{MeshWriter, VertexFormat};
use crate::error::{IoContext, Result};
use crate::ply::write::{WRITTEN_BY, header_text, put_f32, put_position, vertex_element};
use crate::ply::{Element, Encoding, Property, Scalar};

/// Bytes of one binary PLY face record: the count byte and 3 indices.
pub(super) const FACE_BYTES: u64 = 1 + 3 * 4;

/// The header's elements: the vertex element of format `f` ([`vertex_element`] and
/// `scalar_intensity`, `quality`), then the faces, their indices declared `int` while the
/// vertex count fits an `i32`.
fn elements(vertices: u64, faces: u64, f: VertexFormat) -> [Element; 2] {
    let mut vertex = vertex_element(vertices, f.double, f.normals, f.color);
    if f.intensity {
        vertex
            .props
            .push(Property::scalar(Scalar::F32, "scalar_intensity"));
    }
    if f.density {
        vertex.props.push(Property::scalar(Scalar::F32, "quality"));
    }
    let index = if vertices <= i32::MAX as u64 {
        Scalar::I32
    } else {
        Scalar::U32
    };
    let face = Element::new(
        "face",
        faces,
        vec![Property::list(Scalar::U8, index, "vertex_indices")],
    );
    [vertex, face]
}

/// The padding line's least length: `comment`, a space and its newline.
const PAD_MIN: usize = "comment \n".len();

/// Bytes of the header of every binary PLY of vertex format `f`.
pub fn header_bytes(f: VertexFormat) -> usize {
    let els = elements(u64::MAX, u64::MAX, f);
    header_text(Encoding::BinaryLe, &[WRITTEN_BY], &els).len() + PAD_MIN
}

/// The binary header for the given counts, padded to exactly `header_bytes(f)` bytes by a
/// comment of spaces after [`WRITTEN_BY`].
pub(super) fn header(vertices: u64, faces: u64, f: VertexFormat) -> String {
    let els = elements(vertices, faces, f);
    let unpadded = header_text(Encoding::BinaryLe, &[WRITTEN_BY], &els).len();
    let pad = " ".repeat(header_bytes(f) - unpadded - PAD_MIN);
    header_text(Encoding::BinaryLe, &[WRITTEN_BY, &pad], &els)
}

impl MeshWriter {
    pub(super) fn write_ply_binary(&mut self, w: &mut impl Write) -> Result<()> {
        let (vf, tmp) = (self.vf, self.tmp_path.clone());
        let (vertices, faces) = self.counts_out();
        w.write_all(header(vertices, faces, vf).as_bytes())
            .with_path(&tmp)?;
        let mut rec = Vec::with_capacity(vf.stride());
        self.each_vertex(|v, n| {
            rec.clear();
            put_position(&mut rec, v.p, vf.double);
            if vf.normals {
                put_f32(&mut rec, &n);
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

    pub(super) fn write_ply_ascii(&mut self, w: &mut impl Write) -> Result<()> {
        let (vf, tmp) = (self.vf, self.tmp_path.clone());
        let (vertices, faces) = self.counts_out();
        let h = header_text(
            Encoding::Ascii,
            &[WRITTEN_BY],
            &elements(vertices, faces, vf),
        );
        w.write_all(h.as_bytes()).with_path(&tmp)?;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_declared_vertex_record_is_the_stride() {
        for bits in 0..32u32 {
            let bit = |k: u32| bits & (1 << k) != 0;
            let f = VertexFormat {
                color: bit(0),
                intensity: bit(1),
                double: bit(2),
                normals: bit(3),
                density: bit(4),
            };
            let [vertex, face] = elements(3, 1, f);
            assert_eq!(vertex.fixed_size(), Some(f.stride() as u64), "{f:?}");
            assert_eq!(face.fixed_size(), None);
        }
    }
}
