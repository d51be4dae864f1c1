//! PLY, read and written: the header model every PLY reader and writer of scanflow shares, and
//! the readers and writers built on it.
//!
//! # The format
//!
//! PLY is described by Greg Turk, "The PLY Polygon File Format" (1994; mirrored at
//! `paulbourke.net/dataformats/ply/`): its header section, with the table of property types,
//! and its data section are what this module follows. A file starts with a text header of
//! newline-terminated lines:
//!
//! ```text
//! ply
//! format <ascii | binary_little_endian | binary_big_endian> 1.0
//! comment <text>                       (any number, anywhere; obj_info lines alike)
//! element <name> <count>
//! property <type> <name>               (a scalar)
//! property list <count type> <item type> <name>
//! ...                                  (more elements, each with its properties)
//! end_header
//! ```
//!
//! The types are `char uchar short ushort int uint float double` (1, 1, 2, 2, 4, 4, 4 and 8
//! bytes), also spelt `int8 uint8 int16 uint16 int32 uint32 float32 float64`. The data follows
//! `end_header`: the records of each element in the order of declaration, `count` of them,
//! each holding its properties in order (a list: its count, then that many items). In ascii
//! files a record is a line of whitespace-separated numbers; in binary files the values are
//! packed without padding in the byte order of the `format` line.
//!
//! # Files
//!
//! * `header.rs`: the header model ([`PlyHeader`], [`Element`], [`Property`], [`Scalar`] with
//!   the table of type names, [`Encoding`] with the `format` keywords) and its parser,
//!   [`parse_header`], which every reader goes through;
//! * `write.rs`: the header writer both writers go through (the text of a header from the same
//!   model), the vertex properties they share and their binary encoding: the point writer
//!   here, and the PLY encoders of the streamed mesh writer ([`crate::mesh_write`], which
//!   stages the mesh and encodes it as PLY, OBJ or STL from its `finish`);
//! * `point_reader/`: [`PlyReader`], the `vertex` element as points (`decode.rs` the records);
//! * `mesh_reader/`: [`read_mesh`] and [`read_scan_mesh`], the vertices through [`PlyReader`]
//!   and the triangles from the `face` element (`faces.rs`) or a scan's `range_grid`
//!   (`range_grid.rs`), and [`ply_face_count`] (all re-exported by [`crate::mesh_read`]).
//! * `point_writer.rs`: [`point_writer::PointPlyWriter`], points as binary little-endian PLY
//!   (also reached as [`crate::ply_write`]).
//!
//! Nothing here imports the mesh writer: it depends on this module, not the other way.

mod header;
mod mesh_reader;
mod point_reader;
pub mod point_writer;
pub(crate) mod write;

pub use header::{Element, Encoding, PlyHeader, Property, Scalar, parse_header};
pub use mesh_reader::{ply_face_count, read_mesh, read_scan_mesh};
pub use point_reader::PlyReader;
