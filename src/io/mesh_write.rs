//! Streaming binary-little-endian PLY mesh writer (ARCHITECTURE.md step 5).
//!
//! [`MeshPlyWriter`] takes vertices and triangles as the welder emits them, without knowing
//! their counts in advance, in memory independent of the mesh size. Vertices go to a temporary
//! file next to the final one (`OUT.ply.tmp-<pid>`, an [`AtomicFile`]), after room reserved
//! for the header;
//! faces go to a second temporary file (`OUT.ply.tmp-<pid>.faces`). [`MeshPlyWriter::finish`]
//! appends the faces to the vertices, writes the header with the final counts into the
//! reserved room, syncs and renames the file into place, so a reader never sees a half-written
//! mesh under the final name. A writer dropped without `finish` removes both temporary files.
//!
//! The header has a fixed size, [`MeshPlyWriter::header_bytes`]: the room for the largest
//! counts, filled up by a comment line of spaces after `comment written by scanflow`:
//!
//! ```text
//! ply
//! format binary_little_endian 1.0
//! comment written by scanflow
//! comment <spaces>
//! element vertex N
//! property float x            (double x y z where float32 would lose the input's resolution)
//! property float y
//! property float z
//! property uchar red          (red, green, blue only when created with colour)
//! property uchar green
//! property uchar blue
//! property float scalar_intensity   (only when created with intensity)
//! element face M
//! property list uchar int vertex_indices
//! end_header
//! ```
//!
//! A vertex record is `x y z` as float32 (or float64, [`VertexFormat::double`]), then `red
//! green blue` as uchar, then the intensity as float32. The intensity is named with
//! CloudCompare's `scalar_` prefix, so CloudCompare shows it as a scalar field and MeshLab,
//! which reads a vertex property called `intensity` as the colour (showing the mesh white),
//! ignores it. **Precision** ([`VertexFormat::for_cube`]): float32 keeps 24 bits, so it is
//! used only where its spacing at the largest coordinate of the cube is at most `2^-20` of the
//! cube's edge (coordinates within about 8 edges of the origin: rounding below `5e-7` of the
//! extent); georeferenced data (UTM metres, ~5e6, on a scan of tens of metres) gets `double`,
//! which every PLY reader loads as is. A face record is the
//! byte 3, then 3 vertex indices as 32-bit little-endian integers, declared `int` while the
//! vertex count fits an `i32` and `uint` beyond (the bytes are the same for indices that fit
//! both). Triangles are counter-clockwise seen from outside, as extracted
//! ([`crate::extract`]).

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use super::atomic::{self, AtomicFile, with_suffix};
use crate::error::{Error, IoContext, Result};

/// Size of each write buffer.
const BUF_BYTES: usize = 1 << 20;

/// Bytes of one face record: the count byte and 3 indices.
const FACE_BYTES: u64 = 1 + 3 * 4;

/// What a vertex record carries besides its position, and the position's type.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct VertexFormat {
    /// `red green blue` uchar.
    pub color: bool,
    /// `scalar_intensity` float32.
    pub intensity: bool,
    /// `x y z` as float64 instead of float32.
    pub double: bool,
}

impl VertexFormat {
    /// The largest float32 spacing, relative to the cube's edge, that keeps the input's
    /// resolution (see the [module docs](self)).
    pub const FLOAT_SPACING: f64 = crate::types::FLOAT32_SPACING;

    /// The format for vertices inside the cube of lower corner `origin` and edge `size`:
    /// [`VertexFormat::double`] where float32's spacing at the cube's largest coordinate
    /// exceeds [`VertexFormat::FLOAT_SPACING`] of `size`.
    pub fn for_cube(origin: [f64; 3], size: f64, color: bool, intensity: bool) -> VertexFormat {
        let far = origin
            .iter()
            .map(|&o| o.abs().max((o + size).abs()))
            .fold(0f64, f64::max);
        // float32's spacing at `far`: 2^(e - 23) for far in [2^e, 2^(e+1)).
        let spacing = if far > 0.0 && far.is_finite() {
            2f64.powi(far.log2().floor() as i32 - 23)
        } else {
            0.0
        };
        let float_keeps_it = spacing <= Self::FLOAT_SPACING * size;
        VertexFormat {
            color,
            intensity,
            double: !float_keeps_it,
        }
    }

    /// Bytes of one vertex record.
    pub fn stride(&self) -> usize {
        (if self.double { 24 } else { 12 }) + 3 * self.color as usize + 4 * self.intensity as usize
    }
}

/// What [`MeshPlyWriter::finish`] wrote.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MeshWriteStats {
    /// Vertices written.
    pub vertices: u64,
    /// Faces (triangles) written.
    pub faces: u64,
    /// Size of the file, in bytes.
    pub bytes: u64,
}

/// A binary-little-endian PLY mesh being written; see the [module docs](self).
#[derive(Debug)]
pub struct MeshPlyWriter {
    /// The name the file gets on [`MeshPlyWriter::finish`].
    final_path: PathBuf,
    /// Header room and vertices, then the whole file (the name errors refer to).
    tmp_path: PathBuf,
    /// Face records until `finish` (empty once removed).
    faces_path: PathBuf,
    /// The open vertex file; `None` once finished or after a failed write. Dropping it
    /// removes the temporary file.
    out: Option<BufWriter<AtomicFile>>,
    /// The open face file; `None` once finished or after a failed write.
    faces: Option<BufWriter<File>>,
    /// What a vertex record holds.
    format: VertexFormat,
    /// Vertices written.
    vertices: u64,
    /// Faces written.
    faces_written: u64,
    /// Bytes reserved for the header.
    header_bytes: usize,
}

/// The header lines before the padding comment, and after it.
fn header_parts(vertices: u64, faces: u64, f: VertexFormat) -> (String, String) {
    let head = "ply\nformat binary_little_endian 1.0\ncomment written by scanflow\n".to_string();
    let mut tail = format!("element vertex {vertices}\n");
    let ty = if f.double { "double" } else { "float" };
    for n in ["x", "y", "z"] {
        tail.push_str(&format!("property {ty} {n}\n"));
    }
    if f.color {
        for n in ["red", "green", "blue"] {
            tail.push_str(&format!("property uchar {n}\n"));
        }
    }
    if f.intensity {
        tail.push_str("property float scalar_intensity\n");
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

/// Bytes reserved for the header of a file of vertex format `f`.
fn reserved_bytes(f: VertexFormat) -> usize {
    let (h, t) = header_parts(u64::MAX, u64::MAX, f);
    h.len() + t.len() + PAD_MIN
}

/// The header for the given counts, padded to exactly `reserved_bytes(f)` bytes.
fn header(vertices: u64, faces: u64, f: VertexFormat) -> String {
    let (head, tail) = header_parts(vertices, faces, f);
    let pad = reserved_bytes(f) - head.len() - tail.len();
    let mut h = head;
    h.push_str("comment");
    h.extend(std::iter::repeat_n(' ', pad - "comment\n".len()));
    h.push('\n');
    h.push_str(&tail);
    h
}

impl MeshPlyWriter {
    /// Start writing a mesh to `path`, with an RGB colour per vertex when `with_color`.
    ///
    /// Writes to the temporary file `path` + `.tmp-<pid>`, and faces to `path` +
    /// `.tmp-<pid>.faces`, next to it.
    pub fn create(path: &Path, with_color: bool) -> Result<Self> {
        Self::create_with(path, with_color, false)
    }

    /// As [`create`](Self::create), with a float `scalar_intensity` per vertex when
    /// `with_intensity`.
    pub fn create_with(path: &Path, with_color: bool, with_intensity: bool) -> Result<Self> {
        let format = VertexFormat {
            color: with_color,
            intensity: with_intensity,
            double: false,
        };
        Self::create_format(path, format)
    }

    /// As [`create`](Self::create), with vertex records of format `format`.
    pub fn create_format(path: &Path, format: VertexFormat) -> Result<Self> {
        if path.as_os_str().is_empty() {
            return Err(Error::Usage("empty output file name".to_string()));
        }
        let file = AtomicFile::create(path)?;
        let tmp_path = file.tmp_path().to_path_buf();
        let faces_path = with_suffix(&tmp_path, ".faces");
        let mut w = MeshPlyWriter {
            final_path: path.to_path_buf(),
            tmp_path,
            faces_path: PathBuf::new(),
            out: Some(BufWriter::with_capacity(BUF_BYTES, file)),
            faces: None,
            format,
            vertices: 0,
            faces_written: 0,
            header_bytes: reserved_bytes(format),
        };
        // From here on, a failure drops `w`, which removes the temporary files.
        let faces = atomic::create_temp_file(&faces_path)?;
        w.faces_path = faces_path;
        w.faces = Some(BufWriter::with_capacity(BUF_BYTES, faces));
        // A valid header for an empty mesh holds the room until `finish`.
        let h = header(0, 0, format);
        let tmp = &w.tmp_path;
        match w.out.as_mut() {
            Some(o) => o.write_all(h.as_bytes()).with_path(tmp)?,
            None => return Err(w.closed()),
        }
        Ok(w)
    }

    /// The final path of the file.
    pub fn path(&self) -> &Path {
        &self.final_path
    }

    /// Vertices written so far.
    pub fn vertices(&self) -> u64 {
        self.vertices
    }

    /// Triangles written so far.
    pub fn triangles(&self) -> u64 {
        self.faces_written
    }

    /// Size of the header of every file written with or without colour, in bytes.
    pub fn header_bytes(with_color: bool) -> usize {
        reserved_bytes(VertexFormat {
            color: with_color,
            ..VertexFormat::default()
        })
    }

    fn closed(&self) -> Error {
        Error::Internal(format!(
            "{}: mesh writer used after it was closed or after a failed write",
            self.final_path.display()
        ))
    }

    /// Append a vertex: `p` as float32 (float64 for a [`VertexFormat::double`] writer), and
    /// `color` when the writer was created with colour (a colour given to a writer without is
    /// ignored).
    ///
    /// A coordinate that the vertex type cannot hold, or a missing colour, is an
    /// [`Error::Usage`] and writes nothing.
    pub fn vertex(&mut self, p: [f64; 3], color: Option<[u8; 3]>) -> Result<()> {
        self.vertex_with(p, color, None)
    }

    /// As [`vertex`](Self::vertex), with the intensity for a writer created with intensity
    /// (a missing one is an [`Error::Usage`]).
    pub fn vertex_with(
        &mut self,
        p: [f64; 3],
        color: Option<[u8; 3]>,
        intensity: Option<f32>,
    ) -> Result<()> {
        let double = self.format.double;
        for (axis, &v) in ["x", "y", "z"].iter().zip(&p) {
            if !(if double {
                v.is_finite()
            } else {
                (v as f32).is_finite()
            }) {
                return Err(Error::Usage(format!(
                    "{}: vertex {}: {axis} is {v}, which a {} cannot hold",
                    self.final_path.display(),
                    self.vertices,
                    if double { "float64" } else { "float32" }
                )));
            }
        }
        let mut rec = [0u8; 31];
        let mut n = if double {
            for d in 0..3 {
                rec[8 * d..8 * d + 8].copy_from_slice(&p[d].to_le_bytes());
            }
            24
        } else {
            for d in 0..3 {
                rec[4 * d..4 * d + 4].copy_from_slice(&(p[d] as f32).to_le_bytes());
            }
            12
        };
        if self.format.color {
            let Some(c) = color else {
                return Err(Error::Usage(format!(
                    "{}: vertex {} has no colour, which the file was created with",
                    self.final_path.display(),
                    self.vertices
                )));
            };
            rec[n..n + 3].copy_from_slice(&c);
            n += 3;
        }
        if self.format.intensity {
            let Some(i) = intensity else {
                return Err(Error::Usage(format!(
                    "{}: vertex {} has no intensity, which the file was created with",
                    self.final_path.display(),
                    self.vertices
                )));
            };
            rec[n..n + 4].copy_from_slice(&i.to_le_bytes());
            n += 4;
        }
        let res = match self.out.as_mut() {
            Some(o) => o.write_all(&rec[..n]).with_path(&self.tmp_path),
            None => return Err(self.closed()),
        };
        if res.is_err() {
            self.out = None;
        }
        res?;
        self.vertices += 1;
        Ok(())
    }

    /// Append a triangle of vertex indices, each of a vertex already written.
    ///
    /// An index of a vertex not yet written is an [`Error::Internal`] (a bug upstream), and an
    /// index beyond `u32::MAX`, which PLY's 32-bit indices cannot hold, an [`Error::Usage`];
    /// neither writes anything.
    pub fn triangle(&mut self, t: [u64; 3]) -> Result<()> {
        let mut rec = [0u8; FACE_BYTES as usize];
        rec[0] = 3;
        for (k, &i) in t.iter().enumerate() {
            if i >= self.vertices {
                return Err(Error::Internal(format!(
                    "{}: triangle {} names vertex {i}, but only {} vertices were written",
                    self.final_path.display(),
                    self.faces_written,
                    self.vertices
                )));
            }
            let Ok(i32b) = u32::try_from(i) else {
                return Err(Error::Usage(format!(
                    "{}: triangle {} names vertex {i}; PLY vertex indices are 32-bit",
                    self.final_path.display(),
                    self.faces_written
                )));
            };
            rec[1 + 4 * k..5 + 4 * k].copy_from_slice(&i32b.to_le_bytes());
        }
        let res = match self.faces.as_mut() {
            Some(f) => f.write_all(&rec).with_path(&self.faces_path),
            None => return Err(self.closed()),
        };
        if res.is_err() {
            self.faces = None;
        }
        res?;
        self.faces_written += 1;
        Ok(())
    }

    /// Append the faces after the vertices, write the real header with the final counts into
    /// the room reserved at the start, and commit the file ([`AtomicFile::commit`]: sync,
    /// rename to its final name, directory sync). On error both temporary files are removed and
    /// the final path is left as it was.
    pub fn finish(mut self) -> Result<MeshWriteStats> {
        let (Some(out), Some(faces)) = (self.out.take(), self.faces.take()) else {
            return Err(self.closed());
        };
        let mut atomic = out
            .into_inner()
            .map_err(|e| Error::io(&self.tmp_path, e.into_error()))?;
        let file = atomic.file();
        let mut faces = faces
            .into_inner()
            .map_err(|e| Error::io(&self.faces_path, e.into_error()))?;
        faces.seek(SeekFrom::Start(0)).with_path(&self.faces_path)?;
        let copied = std::io::copy(&mut faces, file).with_path(&self.tmp_path)?;
        drop(faces);
        let face_bytes = self.faces_written * FACE_BYTES;
        if copied != face_bytes {
            return Err(Error::Internal(format!(
                "{}: copied {copied} bytes of faces, expected {face_bytes}",
                self.faces_path.display()
            )));
        }
        let h = header(self.vertices, self.faces_written, self.format);
        if h.len() != self.header_bytes {
            return Err(Error::Internal(format!(
                "{}: header of {} bytes does not fit the {} reserved",
                self.final_path.display(),
                h.len(),
                self.header_bytes
            )));
        }
        file.seek(SeekFrom::Start(0)).with_path(&self.tmp_path)?;
        file.write_all(h.as_bytes()).with_path(&self.tmp_path)?;
        let bytes = file.metadata().with_path(&self.tmp_path)?.len();
        let stride = self.format.stride() as u64;
        let expect = self.header_bytes as u64 + self.vertices * stride + face_bytes;
        if bytes != expect {
            return Err(Error::Internal(format!(
                "{}: wrote {bytes} bytes, expected {expect}",
                self.tmp_path.display()
            )));
        }
        atomic.commit()?;
        atomic::remove_temp(&self.faces_path);
        self.faces_path = PathBuf::new();
        Ok(MeshWriteStats {
            vertices: self.vertices,
            faces: self.faces_written,
            bytes,
        })
    }
}

impl Drop for MeshPlyWriter {
    fn drop(&mut self) {
        // Close before removing (some platforms cannot remove an open file); dropping the
        // vertex file removes it.
        self.out = None;
        self.faces = None;
        if !self.faces_path.as_os_str().is_empty() {
            atomic::remove_temp(&self.faces_path);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::PointReader;
    use crate::io::ply::PlyReader;
    use crate::types::PointBatch;

    const TETRA: [[f64; 3]; 4] = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    /// Outward (counter-clockwise seen from outside).
    const TETRA_FACES: [[u64; 3]; 4] = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];

    fn write_tetra(path: &Path, color: bool) -> MeshWriteStats {
        let mut w = MeshPlyWriter::create(path, color).unwrap();
        for (i, p) in TETRA.iter().enumerate() {
            let c = [10 * i as u8, 100, 255 - i as u8];
            w.vertex(*p, Some(c)).unwrap();
        }
        for t in TETRA_FACES {
            w.triangle(t).unwrap();
        }
        assert_eq!((w.vertices(), w.triangles()), (4, 4));
        w.finish().unwrap()
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn tetrahedron_round_trips() {
        for color in [false, true] {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("t.ply");
            let stats = write_tetra(&path, color);
            assert_eq!(names(dir.path()), vec!["t.ply".to_string()]);
            let bytes = std::fs::read(&path).unwrap();
            assert_eq!(stats.vertices, 4);
            assert_eq!(stats.faces, 4);
            assert_eq!(stats.bytes, bytes.len() as u64);

            let hb = MeshPlyWriter::header_bytes(color);
            let text = std::str::from_utf8(&bytes[..hb]).unwrap();
            let lines: Vec<&str> = text.lines().collect();
            let mut want = vec![
                "ply",
                "format binary_little_endian 1.0",
                "comment written by scanflow",
                lines[3],
                "element vertex 4",
                "property float x",
                "property float y",
                "property float z",
            ];
            if color {
                want.extend([
                    "property uchar red",
                    "property uchar green",
                    "property uchar blue",
                ]);
            }
            want.extend([
                "element face 4",
                "property list uchar int vertex_indices",
                "end_header",
            ]);
            assert_eq!(lines, want);
            assert!(lines[3].starts_with("comment ") && lines[3].trim() == "comment");
            assert!(text.ends_with("end_header\n"));

            let stride = if color { 15 } else { 12 };
            let faces = &bytes[hb + 4 * stride..];
            assert_eq!(faces.len(), 4 * 13);
            for (f, t) in faces.chunks(13).zip(TETRA_FACES) {
                assert_eq!(f[0], 3);
                for k in 0..3 {
                    let i = i32::from_le_bytes(f[1 + 4 * k..5 + 4 * k].try_into().unwrap());
                    assert_eq!(i as u64, t[k]);
                }
            }
            if color {
                assert_eq!(&bytes[hb + 12..hb + 15], &[0, 100, 255]);
                assert_eq!(&bytes[hb + 3 * 15 + 12..hb + 4 * 15], &[30, 100, 252]);
            }

            // Our own reader: it walks the face lists at open, then reads the vertices.
            let r = PlyReader::open(&path).unwrap();
            assert_eq!(r.len(), 4);
            assert_eq!(r.header().elements[1].name, "face");
            assert_eq!(r.header().elements[1].count, 4);
            assert_eq!(r.header().data_start as usize, hb);
            let mut batch = PointBatch::default();
            for c in r.chunks(1000).unwrap() {
                r.read_chunk(&c, false, &mut batch).unwrap();
            }
            assert_eq!(batch.pos, TETRA.to_vec());
            if color {
                assert_eq!(batch.color[1][0], 10 * 257);
            }
            plyfile_check(&path, 4, 4);
        }
    }

    /// Read `path` with Python's plyfile, when installed, and compare the counts.
    fn plyfile_check(path: &Path, vertices: usize, faces: usize) {
        let probe = std::process::Command::new("python3")
            .args(["-c", "import plyfile"])
            .output();
        match probe {
            Ok(o) if o.status.success() => {}
            _ => {
                eprintln!("skipping the plyfile check: python3 with plyfile is not available");
                return;
            }
        }
        let script = "import sys, plyfile\n\
                      d = plyfile.PlyData.read(sys.argv[1])\n\
                      f = d['face']['vertex_indices']\n\
                      assert all(len(t) == 3 for t in f)\n\
                      print(len(d['vertex']), len(f))";
        let out = std::process::Command::new("python3")
            .args(["-c", script])
            .arg(path)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "plyfile failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let s = String::from_utf8(out.stdout).unwrap();
        assert_eq!(s.trim(), format!("{vertices} {faces}"));
    }

    #[test]
    fn utm_coordinates_are_written_as_doubles_with_scalar_intensity() {
        // A 40 m cube at UTM-sized coordinates: float32 steps by 0.5 m there.
        let utm = VertexFormat::for_cube([5.0e6, 5.0e6, 100.0], 40.0, true, true);
        assert!(utm.double && utm.color && utm.intensity);
        // Near the origin float32 keeps far more than the extent needs.
        assert!(!VertexFormat::for_cube([-1.1, -1.1, -1.1], 2.2, false, false).double);
        assert!(!VertexFormat::for_cube([1e-30; 3], 1e-30, false, false).double);
        assert!(VertexFormat::for_cube([1e30; 3], 1.0, false, false).double);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("utm.ply");
        let mut w = MeshPlyWriter::create_format(&path, utm).unwrap();
        let ps = [
            [5.0e6 + 0.123456, 5.0e6 + 1.0, 100.25],
            [5.0e6 + 2.0, 5.0e6 + 0.000001, 101.0],
            [5.0e6, 5.0e6 + 3.5, 102.0],
        ];
        for (i, p) in ps.iter().enumerate() {
            w.vertex_with(*p, Some([i as u8, 2, 3]), Some(0.5 * i as f32))
                .unwrap();
        }
        w.triangle([0, 1, 2]).unwrap();
        let stats = w.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let hb = reserved_bytes(utm);
        assert_eq!(stats.bytes as usize, hb + 3 * utm.stride() + 13);
        let text = std::str::from_utf8(&bytes[..hb]).unwrap();
        assert!(text.contains("property double x\nproperty double y\nproperty double z\n"));
        assert!(text.contains("property float scalar_intensity\n"));
        assert!(!text.contains(" intensity"));
        let m = crate::io::mesh_read::read_mesh(&path).unwrap();
        assert_eq!(m.vertices, ps.to_vec());
        plyfile_check(&path, 3, 1);
    }

    #[test]
    fn empty_mesh_is_valid() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("e.ply");
        let stats = MeshPlyWriter::create(&path, false)
            .unwrap()
            .finish()
            .unwrap();
        assert_eq!(stats.bytes, MeshPlyWriter::header_bytes(false) as u64);
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("element vertex 0\n") && text.contains("element face 0\n"));
        plyfile_check(&path, 0, 0);
    }

    #[test]
    fn header_size_is_fixed_and_index_type_follows_the_count() {
        for color in [false, true] {
            let n = MeshPlyWriter::header_bytes(color);
            for (v, f) in [(0, 0), (4, 4), (1 << 31, 7), (u64::MAX, u64::MAX)] {
                let fmt = |intensity, double| VertexFormat {
                    color,
                    intensity,
                    double,
                };
                let h = header(v, f, fmt(false, false));
                for (i, d) in [(true, false), (false, true), (true, true)] {
                    assert_eq!(header(v, f, fmt(i, d)).len(), reserved_bytes(fmt(i, d)));
                }
                assert_eq!(h.len(), n, "{v} {f}");
                let want = if v <= i32::MAX as u64 {
                    " int "
                } else {
                    " uint "
                };
                assert!(h.contains(&format!("property list uchar{want}vertex_indices")));
            }
            let f = VertexFormat {
                color,
                ..VertexFormat::default()
            };
            assert!(header(i32::MAX as u64, 1, f).contains("uchar int"));
            assert!(header(i32::MAX as u64 + 1, 1, f).contains("uchar uint"));
        }
    }

    #[test]
    fn bad_triangles_and_vertices_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("b.ply");
        let mut w = MeshPlyWriter::create(&path, true).unwrap();
        let e = w.vertex([0.0; 3], None).unwrap_err();
        assert!(matches!(e, Error::Usage(_)), "{e}");
        let e = w.vertex([0.0, f64::NAN, 0.0], Some([0; 3])).unwrap_err();
        assert!(e.to_string().contains("y is NaN"), "{e}");
        let e = w.vertex([1e300, 0.0, 0.0], Some([0; 3])).unwrap_err();
        assert!(matches!(e, Error::Usage(_)), "{e}");
        w.vertex([0.0; 3], Some([1, 2, 3])).unwrap();
        w.vertex([1.0; 3], Some([1, 2, 3])).unwrap();
        let e = w.triangle([0, 1, 2]).unwrap_err();
        assert!(matches!(e, Error::Internal(_)), "{e}");
        assert!(e.to_string().contains("vertex 2"), "{e}");
        w.vertex([2.0; 3], Some([1, 2, 3])).unwrap();
        w.triangle([0, 1, 2]).unwrap();
        let s = w.finish().unwrap();
        assert_eq!((s.vertices, s.faces), (3, 1));
        assert_eq!(names(dir.path()), vec!["b.ply".to_string()]);
    }

    #[test]
    fn drop_without_finish_removes_both_temporary_files() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.ply");
        std::fs::write(&path, b"old").unwrap();
        {
            let mut w = MeshPlyWriter::create(&path, false).unwrap();
            w.vertex([0.0; 3], None).unwrap();
            w.triangle([0, 0, 0]).unwrap();
            assert_eq!(names(dir.path()).len(), 3);
        }
        assert_eq!(names(dir.path()), vec!["d.ply".to_string()]);
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
    }

    #[test]
    fn missing_directory_is_an_io_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("no/such/m.ply");
        let e = MeshPlyWriter::create(&path, false).unwrap_err();
        assert!(matches!(e, Error::Io { .. }), "{e}");
    }

    #[test]
    fn larger_mesh_spans_buffers() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("l.ply");
        let mut w = MeshPlyWriter::create(&path, false).unwrap();
        let n = 100_000u64;
        for i in 0..n {
            w.vertex([i as f64, 0.0, -(i as f64)], None).unwrap();
        }
        for i in 0..n - 2 {
            w.triangle([i, i + 1, i + 2]).unwrap();
        }
        let s = w.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(s.bytes as usize, bytes.len());
        let hb = MeshPlyWriter::header_bytes(false);
        let last = &bytes[bytes.len() - 13..];
        assert_eq!(last[0], 3);
        assert_eq!(
            u32::from_le_bytes(last[9..13].try_into().unwrap()) as u64,
            n - 1
        );
        let v = hb + (n as usize - 1) * 12;
        assert_eq!(
            f32::from_le_bytes(bytes[v..v + 4].try_into().unwrap()),
            (n - 1) as f32
        );
        plyfile_check(&path, n as usize, n as usize - 2);
    }
}
