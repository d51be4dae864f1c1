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
//! property float x
//! property float y
//! property float z
//! property uchar red          (red, green, blue only when created with colour)
//! property uchar green
//! property uchar blue
//! element face M
//! property list uchar int vertex_indices
//! end_header
//! ```
//!
//! A vertex record is `x y z` as float32, then `red green blue` as uchar. A face record is the
//! byte 3, then 3 vertex indices as 32-bit little-endian integers, declared `int` while the
//! vertex count fits an `i32` and `uint` beyond (the bytes are the same for indices that fit
//! both). Triangles are counter-clockwise seen from outside, as extracted
//! ([`crate::extract`]).

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use super::atomic::{AtomicFile, with_suffix};
use crate::error::{Error, IoContext, Result};

/// Size of each write buffer.
const BUF_BYTES: usize = 1 << 20;

/// Bytes of one face record: the count byte and 3 indices.
const FACE_BYTES: u64 = 1 + 3 * 4;

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
    /// Whether vertices carry a colour.
    with_color: bool,
    with_intensity: bool,
    /// Vertices written.
    vertices: u64,
    /// Faces written.
    faces_written: u64,
    /// Bytes reserved for the header.
    header_bytes: usize,
}

/// The header lines before the padding comment, and after it.
fn header_parts(
    vertices: u64,
    faces: u64,
    with_color: bool,
    with_intensity: bool,
) -> (String, String) {
    let head = "ply\nformat binary_little_endian 1.0\ncomment written by scanflow\n".to_string();
    let mut tail = format!("element vertex {vertices}\n");
    for n in ["x", "y", "z"] {
        tail.push_str(&format!("property float {n}\n"));
    }
    if with_color {
        for n in ["red", "green", "blue"] {
            tail.push_str(&format!("property uchar {n}\n"));
        }
    }
    if with_intensity {
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

/// Bytes reserved for the header of a file with or without colour.
fn reserved_bytes(with_color: bool, with_intensity: bool) -> usize {
    let (h, t) = header_parts(u64::MAX, u64::MAX, with_color, with_intensity);
    h.len() + t.len() + PAD_MIN
}

/// The header for the given counts, padded to exactly `reserved_bytes(..)` bytes.
fn header(vertices: u64, faces: u64, with_color: bool, with_intensity: bool) -> String {
    let (head, tail) = header_parts(vertices, faces, with_color, with_intensity);
    let pad = reserved_bytes(with_color, with_intensity) - head.len() - tail.len();
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

    /// As [`create`](Self::create), with a float `intensity` per vertex when `with_intensity`.
    pub fn create_with(path: &Path, with_color: bool, with_intensity: bool) -> Result<Self> {
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
            with_color,
            with_intensity,
            vertices: 0,
            faces_written: 0,
            header_bytes: reserved_bytes(with_color, with_intensity),
        };
        // From here on, a failure drops `w`, which removes the temporary files.
        let faces = File::options()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(&faces_path)
            .with_path(&faces_path)?;
        w.faces_path = faces_path;
        w.faces = Some(BufWriter::with_capacity(BUF_BYTES, faces));
        // A valid header for an empty mesh holds the room until `finish`.
        let h = header(0, 0, with_color, with_intensity);
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
        reserved_bytes(with_color, false)
    }

    fn closed(&self) -> Error {
        Error::Internal(format!(
            "{}: mesh writer used after it was closed or after a failed write",
            self.final_path.display()
        ))
    }

    /// Append a vertex: `p` as float32, and `color` when the writer was created with colour
    /// (a colour given to a writer without is ignored).
    ///
    /// A coordinate that a float32 cannot hold, or a missing colour, is an [`Error::Usage`] and
    /// writes nothing.
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
        for (axis, &v) in ["x", "y", "z"].iter().zip(&p) {
            if !(v as f32).is_finite() {
                return Err(Error::Usage(format!(
                    "{}: vertex {}: {axis} is {v}, which a float32 cannot hold",
                    self.final_path.display(),
                    self.vertices
                )));
            }
        }
        let mut rec = [0u8; 19];
        for d in 0..3 {
            rec[4 * d..4 * d + 4].copy_from_slice(&(p[d] as f32).to_le_bytes());
        }
        let mut n = if self.with_color {
            let Some(c) = color else {
                return Err(Error::Usage(format!(
                    "{}: vertex {} has no colour, which the file was created with",
                    self.final_path.display(),
                    self.vertices
                )));
            };
            rec[12..15].copy_from_slice(&c);
            15
        } else {
            12
        };
        if self.with_intensity {
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
        let h = header(
            self.vertices,
            self.faces_written,
            self.with_color,
            self.with_intensity,
        );
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
        let stride = 12 + 3 * self.with_color as u64 + 4 * self.with_intensity as u64;
        let expect = self.header_bytes as u64 + self.vertices * stride + face_bytes;
        if bytes != expect {
            return Err(Error::Internal(format!(
                "{}: wrote {bytes} bytes, expected {expect}",
                self.tmp_path.display()
            )));
        }
        atomic.commit()?;
        let _ = std::fs::remove_file(&self.faces_path);
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
            let _ = std::fs::remove_file(&self.faces_path);
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
                let h = header(v, f, color, false);
                assert_eq!(header(v, f, color, true).len(), reserved_bytes(color, true));
                assert_eq!(h.len(), n, "{v} {f}");
                let want = if v <= i32::MAX as u64 {
                    " int "
                } else {
                    " uint "
                };
                assert!(h.contains(&format!("property list uchar{want}vertex_indices")));
            }
            assert!(header(i32::MAX as u64, 1, color, false).contains("uchar int"));
            assert!(header(i32::MAX as u64 + 1, 1, color, true).contains("uchar uint"));
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
