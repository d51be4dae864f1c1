//! Staging: where vertices and triangles wait until [`super::MeshWriter::finish`] writes
//! them. A [`Stage`] is a temporary file written once and read back in as many passes as
//! needed; a [`Staged`] vertex is its fixed-size little-endian record (the vertex file is
//! memory-mapped when normals or islands need random access to it).

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::PathBuf;

use super::{BUF_BYTES, MeshWriter};
use crate::error::{Error, IoContext, Result};
use crate::fs::atomic;

/// Bytes of a staged vertex: x y z as f64, colour, a pad byte, intensity and density as f32.
pub(super) const STAGE_BYTES: usize = 24 + 4 + 4 + 4;

/// Bytes of a staged face: three u32 indices.
pub(super) const STAGE_FACE_BYTES: usize = 12;

/// A staged temporary file: written once, then read in as many passes as needed.
#[derive(Debug, Default)]
pub(super) struct Stage {
    pub(super) path: PathBuf,
    pub(super) file: Option<BufWriter<File>>,
    /// A write failed: the file is short.
    pub(super) broken: bool,
}

impl Stage {
    pub(super) fn create(path: PathBuf) -> Result<Stage> {
        let f = atomic::create_temp_file(&path)?;
        Ok(Stage {
            path,
            file: Some(BufWriter::with_capacity(BUF_BYTES, f)),
            broken: false,
        })
    }

    pub(super) fn broken(&self) -> Error {
        Error::Internal(format!(
            "{}: staged mesh file used after a failed write",
            self.path.display()
        ))
    }

    /// The open file, for writing.
    pub(super) fn writer(&mut self) -> Result<&mut BufWriter<File>> {
        if self.broken || self.file.is_none() {
            return Err(self.broken());
        }
        Ok(self.file.as_mut().expect("checked above"))
    }

    /// Append `bytes`; a failed write breaks the stage.
    pub(super) fn write(&mut self, bytes: &[u8]) -> Result<()> {
        let path = self.path.clone();
        let res = self.writer()?.write_all(bytes).with_path(&path);
        self.broken |= res.is_err();
        res
    }

    /// Flush and close the file (once written).
    pub(super) fn close(&mut self) -> Result<()> {
        if self.broken {
            return Err(self.broken());
        }
        if let Some(w) = self.file.take() {
            w.into_inner()
                .map_err(|e| Error::io(&self.path, e.into_error()))?;
        }
        Ok(())
    }

    /// The whole file, from its start, for a pass of reading.
    pub(super) fn reader(&mut self) -> Result<BufReader<File>> {
        self.close()?;
        let f = File::open(&self.path).with_path(&self.path)?;
        Ok(BufReader::with_capacity(BUF_BYTES, f))
    }

    /// Close and remove the file.
    pub(super) fn remove(&mut self) {
        self.file = None;
        if !self.path.as_os_str().is_empty() {
            atomic::remove_temp(&self.path);
            self.path = PathBuf::new();
        }
    }
}

/// A staged vertex, read back.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Staged {
    pub(crate) p: [f64; 3],
    pub(crate) color: [u8; 3],
    pub(crate) intensity: f32,
    pub(crate) density: f32,
}

impl Staged {
    pub(super) fn encode(&self) -> [u8; STAGE_BYTES] {
        let mut r = [0u8; STAGE_BYTES];
        for d in 0..3 {
            r[8 * d..8 * d + 8].copy_from_slice(&self.p[d].to_le_bytes());
        }
        r[24..27].copy_from_slice(&self.color);
        r[28..32].copy_from_slice(&self.intensity.to_le_bytes());
        r[32..36].copy_from_slice(&self.density.to_le_bytes());
        r
    }

    pub(super) fn decode(r: &[u8]) -> Staged {
        let f64_at = |o: usize| f64::from_le_bytes(r[o..o + 8].try_into().expect("8 bytes"));
        let f32_at = |o: usize| f32::from_le_bytes(r[o..o + 4].try_into().expect("4 bytes"));
        Staged {
            p: [f64_at(0), f64_at(8), f64_at(16)],
            color: [r[24], r[25], r[26]],
            intensity: f32_at(28),
            density: f32_at(32),
        }
    }
}

/// The `count` staged faces of `stage`, in order.
pub(super) fn stream_faces(
    stage: &mut Stage,
    count: u64,
    mut f: impl FnMut([u32; 3]) -> Result<()>,
) -> Result<()> {
    let mut faces = stage.reader()?;
    let mut rec = [0u8; STAGE_FACE_BYTES];
    for _ in 0..count {
        faces.read_exact(&mut rec).with_path(&stage.path)?;
        f([0, 1, 2].map(|k| u32::from_le_bytes(rec[4 * k..4 * k + 4].try_into().expect("4"))))?;
    }
    Ok(())
}

/// Reading the stages back, for the encoders.
impl MeshWriter {
    /// The staged vertices, mapped (complete, no longer written: this writer's own file,
    /// which nothing else truncates while the map lives).
    pub(super) fn map_vertices(&mut self) -> Result<crate::fs::mmap::Window> {
        self.verts.close()?;
        let vpath = self.verts.path.clone();
        let verts = File::open(&vpath).with_path(&vpath)?;
        let len = verts.metadata().with_path(&vpath)?.len();
        let map = crate::fs::mmap::Window::map(&verts, &vpath, 0, len)?;
        if map.len() as u64 != self.vertices * STAGE_BYTES as u64 {
            return Err(Error::Internal(format!(
                "{}: {} bytes staged for {} vertices",
                vpath.display(),
                map.len(),
                self.vertices
            )));
        }
        Ok(map)
    }

    /// Each vertex written with its normal (zero without normals), in order: every staged
    /// one but those of dropped islands.
    pub(crate) fn each_vertex(
        &mut self,
        mut f: impl FnMut(Staged, [f32; 3]) -> Result<()>,
    ) -> Result<()> {
        let mut verts = self.verts.reader()?;
        let mut normals = match self.vf.normals {
            true => Some(self.normals.reader()?),
            false => None,
        };
        let mut rec = [0u8; STAGE_BYTES];
        let mut nrec = [0u8; 12];
        for i in 0..self.vertices {
            verts.read_exact(&mut rec).with_path(&self.verts.path)?;
            let mut n = [0f32; 3];
            if let Some(r) = normals.as_mut() {
                r.read_exact(&mut nrec).with_path(&self.normals.path)?;
                for d in 0..3 {
                    n[d] = f32::from_le_bytes(nrec[4 * d..4 * d + 4].try_into().expect("4"));
                }
            }
            if self.filter.as_ref().is_none_or(|k| k.keeps(i as u32)) {
                f(Staged::decode(&rec), n)?;
            }
        }
        Ok(())
    }

    /// Each face written, in order: every staged one but those of dropped islands, its
    /// corners numbered as written (`renumber`) or as staged.
    pub(crate) fn each_face(
        &mut self,
        renumber: bool,
        mut f: impl FnMut([u32; 3]) -> Result<()>,
    ) -> Result<()> {
        let filter = &self.filter;
        stream_faces(&mut self.faces, self.faces_written, |t| match filter {
            Some(k) if !k.keeps(t[0]) => Ok(()),
            Some(k) if renumber => f(t.map(|v| k.renumber(v))),
            _ => f(t),
        })
    }
}
