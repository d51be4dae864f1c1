//! What both PLY writers share, the point writer (`point_writer.rs`) and the mesh encoders
//! (the streamed mesh writer's, in [`crate::mesh_write`]): the header text, written from the header model the readers parse into
//! ([`header_text`]); the vertex properties both start with ([`vertex_element`]); and the
//! binary little-endian encoding of those ([`put_position`], [`put_f32`]). Each writer adds
//! its own properties and elements after them.

use std::fmt::Write as _;

use super::{Element, Encoding, Property, Scalar};

/// The comment every header scanflow writes carries first.
pub(crate) const WRITTEN_BY: &str = "written by scanflow";

/// A header's text: `ply`, the `format` line of `encoding` (version 1.0), a `comment` line
/// per entry of `comments`, each element's `element` line followed by its `property` lines
/// (types in the specification's spelling, [`Scalar::name`]), and `end_header`.
pub(crate) fn header_text(encoding: Encoding, comments: &[&str], elements: &[Element]) -> String {
    let mut h = String::with_capacity(256);
    let _ = write!(h, "ply\nformat {} 1.0\n", encoding.keyword());
    for c in comments {
        let _ = writeln!(h, "comment {c}");
    }
    for el in elements {
        let _ = writeln!(h, "element {} {}", el.name, el.count);
        for p in &el.props {
            let _ = match p {
                Property::Scalar { name, ty } => writeln!(h, "property {} {name}", ty.name()),
                Property::List { name, count, item } => {
                    writeln!(h, "property list {} {} {name}", count.name(), item.name())
                }
            };
        }
    }
    h.push_str("end_header\n");
    h
}

/// The `vertex` element of `count` records that both writers start with: `x y z` (`double`
/// when `double`, else `float`), then `nx ny nz` (`float`) with `normals`, then `red green
/// blue` (`uchar`) with `color`.
pub(crate) fn vertex_element(count: u64, double: bool, normals: bool, color: bool) -> Element {
    let pos = if double { Scalar::F64 } else { Scalar::F32 };
    let mut props: Vec<Property> = ["x", "y", "z"].map(|n| Property::scalar(pos, n)).into();
    if normals {
        props.extend(["nx", "ny", "nz"].map(|n| Property::scalar(Scalar::F32, n)));
    }
    if color {
        props.extend(["red", "green", "blue"].map(|n| Property::scalar(Scalar::U8, n)));
    }
    Element::new("vertex", count, props)
}

/// Append position `p` as [`vertex_element`] declares it: three float64 when `double`, else
/// three float32, little endian.
#[inline(always)]
pub(crate) fn put_position(out: &mut Vec<u8>, p: [f64; 3], double: bool) {
    for v in p {
        if double {
            out.extend_from_slice(&v.to_le_bytes());
        } else {
            out.extend_from_slice(&(v as f32).to_le_bytes());
        }
    }
}

/// Append float32 values (a normal, say), little endian.
#[inline(always)]
pub(crate) fn put_f32(out: &mut Vec<u8>, values: &[f32]) {
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ply::parse_header;
    use std::path::Path;

    const ALL: [Scalar; 8] = [
        Scalar::I8,
        Scalar::U8,
        Scalar::I16,
        Scalar::U16,
        Scalar::I32,
        Scalar::U32,
        Scalar::F32,
        Scalar::F64,
    ];

    #[test]
    fn names_and_keywords_read_back() {
        for ty in ALL {
            assert_eq!(Scalar::parse(ty.name()), Some(ty));
        }
        let names: Vec<&str> = ALL.iter().map(|t| t.name()).collect();
        assert_eq!(
            names,
            [
                "char", "uchar", "short", "ushort", "int", "uint", "float", "double"
            ]
        );
        for e in [Encoding::Ascii, Encoding::BinaryLe, Encoding::BinaryBe] {
            assert_eq!(Encoding::parse(e.keyword()), Some(e));
        }
    }

    #[test]
    fn written_header_parses_to_its_model() {
        let mut v = vertex_element(7, true, true, true);
        v.props.push(Property::scalar(Scalar::U16, "flags"));
        let face = Element::new(
            "face",
            3,
            vec![Property::list(Scalar::U8, Scalar::U32, "vertex_indices")],
        );
        let elements = [v, face];
        let text = header_text(Encoding::BinaryBe, &[WRITTEN_BY, "two"], &elements);
        assert!(text.starts_with(
            "ply\nformat binary_big_endian 1.0\ncomment written by scanflow\ncomment two\n\
             element vertex 7\nproperty double x\n"
        ));
        assert!(text.ends_with(
            "property ushort flags\nelement face 3\nproperty list uchar uint vertex_indices\n\
             end_header\n"
        ));
        let h = parse_header(Path::new("w.ply"), text.as_bytes()).unwrap();
        assert_eq!(h.encoding, Encoding::BinaryBe);
        assert_eq!(h.data_start, text.len() as u64);
        assert_eq!(h.elements.len(), 2);
        for (read, written) in h.elements.iter().zip(&elements) {
            assert_eq!((&read.name, read.count), (&written.name, written.count));
            assert_eq!(read.props, written.props);
        }
        assert_eq!(
            h.elements[0].fixed_size(),
            Some(3 * 8 + 3 * 4 + 3 + 2),
            "x y z double, normals, rgb, flags"
        );
    }

    #[test]
    fn positions_and_floats_are_little_endian() {
        let mut out = Vec::new();
        put_position(&mut out, [1.0, -2.0, 0.5], false);
        put_f32(&mut out, &[3.0]);
        put_position(&mut out, [1.0, 0.0, 0.0], true);
        assert_eq!(out.len(), 12 + 4 + 24);
        assert_eq!(&out[..4], &1.0f32.to_le_bytes());
        assert_eq!(&out[4..8], &(-2.0f32).to_le_bytes());
        assert_eq!(&out[12..16], &3.0f32.to_le_bytes());
        assert_eq!(&out[16..24], &1.0f64.to_le_bytes());
    }
}
