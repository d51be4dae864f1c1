//! Streaming mesh writers: binary or ASCII PLY, Wavefront OBJ and binary STL, chosen by the
//! output's extension (ARCHITECTURE.md step 5).
//!
//! [`MeshWriter`] takes vertices and triangles as the welder emits them, without knowing their
//! counts in advance, in memory independent of the mesh size. It stages them in temporary files
//! next to the output (`OUT.tmp-<pid>.vertices`, `.faces`, and `.normals` when writing
//! normals), then [`MeshWriter::finish`] writes the file in its format into `OUT.tmp-<pid>` (an
//! [`AtomicFile`]), syncs it and renames it into place, so a reader never sees a half-written
//! mesh under the final name. A writer dropped without `finish` removes every temporary file.
//!
//! **Normals come late.** A vertex's normal is the area-weighted sum of its triangles'
//! normals, known only once its last triangle is, long after the vertex itself (tiles
//! stream, and a vertex on a seam waits for the neighbouring tile). [`MeshWriter::normal`]
//! therefore takes a normal for any vertex already written, in any order; normals are
//! gathered in a small buffer and written in place (sorted runs) in the normals file, which
//! `finish` reads beside the vertices.
//!
//! **PLY** (binary little endian by default, ASCII with [`MeshFormat::PlyAscii`]). The binary
//! header has a fixed size for a vertex format ([`header_bytes`]): the room for the largest
//! counts, filled up by a comment line of spaces after `comment written by scanflow`, so a
//! file's layout does not depend on its counts:
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
//! property float nx           (nx, ny, nz only with normals)
//! property float ny
//! property float nz
//! property uchar red          (red, green, blue only with colour)
//! property uchar green
//! property uchar blue
//! property float scalar_intensity   (only with intensity)
//! property float quality      (only with the sampling density)
//! element face M
//! property list uchar int vertex_indices
//! end_header
//! ```
//!
//! A binary vertex record holds the properties in that order, little endian. The intensity is
//! named with CloudCompare's `scalar_` prefix, so CloudCompare shows it as a scalar field and
//! MeshLab, which reads a vertex property called `intensity` as the colour (showing the mesh
//! white), ignores it. The sampling density (input points per square unit near the vertex) is
//! called `quality` because MeshLab reads that as its per-vertex quality, which its "Select by
//! Vertex Quality" filter trims by (PoissonRecon's `--density` workflow); CloudCompare shows
//! it as a scalar field. **Precision** ([`VertexFormat::for_cube`]): float32 keeps 24 bits, so
//! it is used only where its spacing at the largest coordinate of the cube is at most `2^-20`
//! of the cube's edge (coordinates within about 8 edges of the origin: rounding below `5e-7`
//! of the extent); georeferenced data (UTM metres, ~5e6, on a scan of tens of metres) gets
//! `double`, which every PLY reader loads as is. A face record is the byte 3, then 3 vertex
//! indices as 32-bit little-endian integers, declared `int` while the vertex count fits an
//! `i32` and `uint` beyond (the bytes are the same for indices that fit both). The ASCII
//! header is the same without the padding line; numbers are written in their shortest form
//! that reads back to the same float32 (float64 for double positions).
//!
//! **OBJ**: `v x y z` per vertex (with `r g b` in [0, 1] appended when the mesh has colour,
//! the extension MeshLab, trimesh and Open3D read), `vn nx ny nz` per vertex with normals,
//! then `f a b c` (1-based; `f a//a b//b c//c` with normals). OBJ has no per-vertex scalar:
//! intensity is not written, and the density cannot be asked for ([`MeshFormat::carries`]).
//!
//! **STL** (binary): an 80-byte header that does not start with `solid`, the triangle count
//! (u32), then per triangle its unit normal, its three corners (float32) and a zero attribute
//! (u16). STL has no shared vertices: `finish` maps the staged vertices and looks each corner
//! up there (the page cache holds them, not the heap). It has no colour, intensity or
//! per-vertex data; coordinates are float32 whatever the cube needs (a warning is logged where
//! that loses the input's resolution).
//!
//! Triangles are counter-clockwise seen from outside, as extracted (`scanflow_recon::extract`), in
//! every format.
//!
//! This module holds the API ([`MeshWriter`], [`MeshFormat`], [`VertexFormat`], [`MeshTarget`]);
//! `staging` the temporary files where vertices, faces and normals wait until `finish`; the
//! encoders `ply` (binary and ASCII, its header written from [`crate::ply`]'s model, which the
//! PLY readers parse into), `obj` and `stl`, with `text` the numbers the text encoders write.

use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use super::islands::IslandFilter;
use crate::error::{Error, IoContext, Result, Setting};
use crate::fs::atomic::{AtomicFile, with_suffix};

mod obj;
mod ply;
mod staging;
mod stl;
pub(crate) mod text;

use ply::FACE_BYTES;
pub use ply::header_bytes;
use staging::{STAGE_BYTES, STAGE_FACE_BYTES, Stage, Staged, stream_faces};
use stl::{STL_HEADER, STL_TRIANGLE};

/// Size of each write buffer.
const BUF_BYTES: usize = 1 << 20;

/// Normals gathered before they are written in place.
const NORMAL_BATCH: usize = 1 << 16;

/// The file formats a mesh is written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshFormat {
    /// Binary little-endian PLY.
    Ply,
    /// ASCII PLY.
    PlyAscii,
    /// Wavefront OBJ.
    Obj,
    /// Binary STL.
    Stl,
}

impl MeshFormat {
    /// The extensions a mesh output may have.
    pub const EXTENSIONS: [&str; 3] = ["ply", "obj", "stl"];

    /// The format of an output named `path`: by its extension, ASCII case ignored (`.ply`,
    /// `.obj`, `.stl`); `ascii` asks for ASCII PLY and is refused for the other formats.
    pub fn for_path(path: &Path, ascii: bool) -> Result<MeshFormat> {
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
        let f = match ext.to_ascii_lowercase().as_str() {
            "ply" if ascii => MeshFormat::PlyAscii,
            "ply" => MeshFormat::Ply,
            "obj" => MeshFormat::Obj,
            "stl" => MeshFormat::Stl,
            _ => {
                return Err(Error::Usage(format!(
                    "{}: a mesh is written as PLY, OBJ or STL; name the output *.ply, *.obj or *.stl",
                    path.display()
                )));
            }
        };
        if ascii && f != MeshFormat::PlyAscii {
            return Err(Error::Usage(format!(
                "{}: {} is for PLY output; {} has one form only",
                path.display(),
                Setting::Ascii,
                f.name()
            )));
        }
        Ok(f)
    }

    /// The format's name, for messages.
    pub fn name(self) -> &'static str {
        match self {
            MeshFormat::Ply => "binary PLY",
            MeshFormat::PlyAscii => "ASCII PLY",
            MeshFormat::Obj => "OBJ",
            MeshFormat::Stl => "binary STL",
        }
    }

    /// Refuse the per-vertex data that the format cannot hold and a user asked for (`path`
    /// names the output): normals in STL (it has one per triangle, always written) and the
    /// density outside PLY. Colour and intensity come with the input and are left out where
    /// the format has no place for them.
    pub fn carries(self, path: &Path, normals: bool, density: bool) -> Result<()> {
        let refused = match self {
            MeshFormat::Stl if normals => Some((
                Setting::OutNormals,
                "STL has no vertex normals (it stores each triangle's, always written)",
            )),
            MeshFormat::Stl | MeshFormat::Obj if density => Some((
                Setting::Density,
                "only PLY has a per-vertex scalar to hold it; write *.ply",
            )),
            _ => None,
        };
        match refused {
            Some((setting, why)) => Err(Error::Usage(format!(
                "{}: {setting}: {why}",
                path.display()
            ))),
            None => Ok(()),
        }
    }
}

/// What a vertex carries besides its position, and the position's type.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct VertexFormat {
    /// `red green blue` uchar.
    pub color: bool,
    /// `scalar_intensity` float32.
    pub intensity: bool,
    /// `x y z` as float64 instead of float32.
    pub double: bool,
    /// `nx ny nz` float32, given by [`MeshWriter::normal`].
    pub normals: bool,
    /// `quality` float32: the sampling density.
    pub density: bool,
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
            ..VertexFormat::default()
        }
    }

    /// Bytes of one binary PLY vertex record.
    pub fn stride(&self) -> usize {
        (if self.double { 24 } else { 12 })
            + 12 * self.normals as usize
            + 3 * self.color as usize
            + 4 * self.intensity as usize
            + 4 * self.density as usize
    }
}

/// Where and how a mesh is written: its path, its format (by extension,
/// [`MeshFormat::for_path`]), whether its vertices get normals (`--out-normals`) and whether
/// a picture of it is drawn as it streams ([`crate::preview`], of this many pixels a
/// view's side).
#[derive(Debug, Clone, PartialEq)]
pub struct MeshTarget {
    /// The output file.
    pub path: PathBuf,
    /// Its format.
    pub format: MeshFormat,
    /// Vertex normals.
    pub normals: bool,
    /// A preview's side in pixels, when one is drawn.
    pub preview: Option<usize>,
    /// Connected pieces under this fraction of the area are left out
    /// ([`MeshWriter::drop_islands`]).
    pub islands: Option<f64>,
}

impl MeshTarget {
    /// Binary PLY at `path`, without normals.
    pub fn ply(path: &Path) -> MeshTarget {
        MeshTarget {
            path: path.to_path_buf(),
            format: MeshFormat::Ply,
            normals: false,
            preview: None,
            islands: None,
        }
    }
}

/// What [`MeshWriter::finish`] wrote.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MeshWriteStats {
    /// Vertices written.
    pub vertices: u64,
    /// Faces (triangles) written.
    pub faces: u64,
    /// Size of the file, in bytes.
    pub bytes: u64,
}

/// A mesh being written; see the [module docs](self).
#[derive(Debug)]
pub struct MeshWriter {
    /// The name the file gets on [`MeshWriter::finish`].
    final_path: PathBuf,
    /// The file being written, until committed.
    out: Option<AtomicFile>,
    /// Its temporary name, which errors name.
    tmp_path: PathBuf,
    /// Staged vertices, faces and normals: (path, open file); the paths stay set until the
    /// files are removed.
    verts: Stage,
    faces: Stage,
    normals: Stage,
    /// Normals given but not yet written in place: (vertex, normal).
    pending: Vec<(u64, [f32; 3])>,
    format: MeshFormat,
    vf: VertexFormat,
    vertices: u64,
    faces_written: u64,
    normals_given: u64,
    /// Drop the connected pieces under this fraction of the area ([`crate::islands`]).
    islands: Option<f64>,
    /// What is kept, once `finish` has found the islands.
    filter: Option<IslandFilter>,
}

impl MeshWriter {
    /// Start writing a mesh to `path` in `format`, with vertices of format `vf` (its
    /// per-vertex data the format has no place for is left out; see [`MeshFormat::carries`]).
    ///
    /// Stages to `path` + `.tmp-<pid>.vertices` (and `.faces`, `.normals`) and writes the file
    /// as `path` + `.tmp-<pid>`, next to it.
    pub fn create(path: &Path, format: MeshFormat, vf: VertexFormat) -> Result<Self> {
        if path.as_os_str().is_empty() {
            return Err(Error::Usage("empty output file name".to_string()));
        }
        if vf.double && format == MeshFormat::Stl {
            log::warn!(
                "{}: STL holds float32 coordinates, which lose the input's resolution this far from the origin (PLY keeps float64)",
                path.display()
            );
        }
        let vf = match format {
            MeshFormat::Obj => VertexFormat {
                intensity: false,
                ..vf
            },
            MeshFormat::Stl => VertexFormat {
                color: false,
                intensity: false,
                double: false,
                ..vf
            },
            _ => vf,
        };
        let out = AtomicFile::create(path)?;
        let tmp = out.tmp_path().to_path_buf();
        let mut w = MeshWriter {
            final_path: path.to_path_buf(),
            out: Some(out),
            tmp_path: tmp.clone(),
            verts: Stage::default(),
            faces: Stage::default(),
            normals: Stage::default(),
            pending: Vec::new(),
            format,
            vf,
            vertices: 0,
            faces_written: 0,
            normals_given: 0,
            islands: None,
            filter: None,
        };
        // From here on, a failure drops `w`, which removes the temporary files.
        w.verts = Stage::create(with_suffix(&tmp, ".vertices"))?;
        w.faces = Stage::create(with_suffix(&tmp, ".faces"))?;
        if vf.normals {
            w.normals = Stage::create(with_suffix(&tmp, ".normals"))?;
        }
        Ok(w)
    }

    /// A binary PLY writer at `path`, with an RGB colour per vertex when `with_color`.
    pub fn ply(path: &Path, with_color: bool) -> Result<Self> {
        let vf = VertexFormat {
            color: with_color,
            ..VertexFormat::default()
        };
        Self::create(path, MeshFormat::Ply, vf)
    }

    /// Leave out of the file every connected piece of the mesh whose area is under `ratio`
    /// of the whole (PoissonRecon's SurfaceTrimmer `--aRatio`; [`crate::islands`]),
    /// with its vertices. [`MeshWriter::finish`] then holds
    /// [`islands::BYTES_PER_VERTEX`](crate::islands::BYTES_PER_VERTEX) per vertex.
    pub fn drop_islands(&mut self, ratio: f64) {
        self.islands = Some(ratio);
    }

    /// The final path of the file.
    pub fn path(&self) -> &Path {
        &self.final_path
    }

    /// The file's format.
    pub fn format(&self) -> MeshFormat {
        self.format
    }

    /// What its vertices carry (less what the format has no place for).
    pub fn vertex_format(&self) -> VertexFormat {
        self.vf
    }

    /// Vertices written so far.
    pub fn vertices(&self) -> u64 {
        self.vertices
    }

    /// Triangles written so far.
    pub fn triangles(&self) -> u64 {
        self.faces_written
    }

    /// Append a vertex at `p`, with `color` when the writer was created with colour (a colour
    /// given to a writer without is ignored).
    ///
    /// A coordinate that the file's type cannot hold, or a missing colour, is an
    /// [`Error::Usage`] and writes nothing.
    pub fn vertex(&mut self, p: [f64; 3], color: Option<[u8; 3]>) -> Result<()> {
        self.vertex_with(p, color, None, None)
    }

    /// As [`vertex`](Self::vertex), with the intensity and the density for a writer created
    /// with them (a missing one is an [`Error::Usage`]; one the writer does not carry is
    /// ignored).
    pub fn vertex_with(
        &mut self,
        p: [f64; 3],
        color: Option<[u8; 3]>,
        intensity: Option<f32>,
        density: Option<f32>,
    ) -> Result<()> {
        let double = self.vf.double;
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
        let missing = |what: &str| {
            Error::Usage(format!(
                "{}: vertex {} has no {what}, which the file was created with",
                self.final_path.display(),
                self.vertices
            ))
        };
        let color = match (self.vf.color, color) {
            (true, None) => return Err(missing("colour")),
            (_, c) => c.unwrap_or_default(),
        };
        let intensity = match (self.vf.intensity, intensity) {
            (true, None) => return Err(missing("intensity")),
            (_, i) => i.unwrap_or_default(),
        };
        let density = match (self.vf.density, density) {
            (true, None) => return Err(missing("density")),
            (_, d) => d.unwrap_or_default(),
        };
        let rec = Staged {
            p,
            color,
            intensity,
            density,
        };
        self.verts.write(&rec.encode())?;
        self.vertices += 1;
        Ok(())
    }

    /// Give vertex `i` (already written) its normal, once, in any order. Ignored by a writer
    /// without normals.
    pub fn normal(&mut self, i: u64, n: [f32; 3]) -> Result<()> {
        if !self.vf.normals {
            return Ok(());
        }
        if i >= self.vertices {
            return Err(Error::Internal(format!(
                "{}: normal of vertex {i}, but only {} vertices were written",
                self.final_path.display(),
                self.vertices
            )));
        }
        self.pending.push((i, n));
        self.normals_given += 1;
        if self.pending.len() >= NORMAL_BATCH {
            self.write_normals()?;
        }
        Ok(())
    }

    /// Write the pending normals in place, in runs of consecutive vertices.
    fn write_normals(&mut self) -> Result<()> {
        self.pending.sort_unstable_by_key(|e| e.0);
        let path = self.normals.path.clone();
        let f = self.normals.writer()?;
        let mut run: Vec<u8> = Vec::new();
        // Where the file's position is (none known before the first run).
        let mut start = u64::MAX;
        let mut at = 0usize;
        while at < self.pending.len() {
            let first = self.pending[at].0;
            let mut end = at;
            run.clear();
            while end < self.pending.len() && self.pending[end].0 == first + (end - at) as u64 {
                for v in self.pending[end].1 {
                    run.extend_from_slice(&v.to_le_bytes());
                }
                end += 1;
            }
            if first != start {
                f.seek(SeekFrom::Start(first * 12)).with_path(&path)?;
            }
            f.write_all(&run).with_path(&path)?;
            start = first + (end - at) as u64;
            at = end;
        }
        self.pending.clear();
        Ok(())
    }

    /// Append a triangle of vertex indices, each of a vertex already written.
    ///
    /// An index of a vertex not yet written is an [`Error::Internal`] (a bug upstream), and an
    /// index beyond `u32::MAX`, which 32-bit indices cannot hold, an [`Error::Usage`]; neither
    /// writes anything.
    pub fn triangle(&mut self, t: [u64; 3]) -> Result<()> {
        let mut rec = [0u8; STAGE_FACE_BYTES];
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
                    "{}: triangle {} names vertex {i}; {} vertex indices are 32-bit",
                    self.final_path.display(),
                    self.faces_written,
                    self.format.name()
                )));
            };
            rec[4 * k..4 * k + 4].copy_from_slice(&i32b.to_le_bytes());
        }
        self.faces.write(&rec)?;
        self.faces_written += 1;
        Ok(())
    }

    /// Write the file in its format from the staged vertices, normals and faces, and commit
    /// it ([`AtomicFile::commit`]: sync, rename to its final name, directory sync). On error
    /// every temporary file is removed and the final path is left as it was.
    pub fn finish(mut self) -> Result<MeshWriteStats> {
        if self.vf.normals {
            if self.normals_given != self.vertices {
                return Err(Error::Internal(format!(
                    "{}: {} normals given for {} vertices",
                    self.final_path.display(),
                    self.normals_given,
                    self.vertices
                )));
            }
            self.write_normals()?;
        }
        if let Some(ratio) = self.islands {
            let f = self.find_islands(ratio)?;
            if f.triangles == 0 {
                return Err(Error::Usage(format!(
                    "{}: dropping the pieces under {ratio} of the area leaves no triangle: each of its {} pieces is smaller than that",
                    self.final_path.display(),
                    f.components
                )));
            }
            log::info!(
                "{}: dropped {} of {} connected pieces under {ratio} of the area ({} of {} triangles kept)",
                self.final_path.display(),
                f.dropped,
                f.components,
                f.triangles,
                self.faces_written
            );
            self.filter = Some(f);
        }
        let (vertices, faces) = self.counts_out();
        let Some(mut out) = self.out.take() else {
            return Err(Error::Internal(format!(
                "{}: mesh writer finished twice",
                self.final_path.display()
            )));
        };
        let tmp = self.tmp_path.clone();
        let mut w = BufWriter::with_capacity(BUF_BYTES, out.file());
        match self.format {
            MeshFormat::Ply => self.write_ply_binary(&mut w)?,
            MeshFormat::PlyAscii => self.write_ply_ascii(&mut w)?,
            MeshFormat::Obj => self.write_obj(&mut w)?,
            MeshFormat::Stl => self.write_stl(&mut w)?,
        }
        w.flush().with_path(&tmp)?;
        drop(w);
        let bytes = out.file().metadata().with_path(&tmp)?.len();
        if let Some(expect) = self.expected_bytes()
            && bytes != expect
        {
            return Err(Error::Internal(format!(
                "{}: wrote {bytes} bytes, expected {expect}",
                tmp.display()
            )));
        }
        out.commit()?;
        self.verts.remove();
        self.faces.remove();
        self.normals.remove();
        Ok(MeshWriteStats {
            vertices,
            faces,
            bytes,
        })
    }

    /// The vertices and triangles the file holds: all those staged, less the islands.
    pub(crate) fn counts_out(&self) -> (u64, u64) {
        match &self.filter {
            Some(f) => (f.vertices, f.triangles),
            None => (self.vertices, self.faces_written),
        }
    }

    /// The pieces of the staged mesh under `ratio` of its area.
    fn find_islands(&mut self, ratio: f64) -> Result<IslandFilter> {
        let map = self.map_vertices()?;
        let n = u32::try_from(self.vertices).map_err(|_| {
            Error::Usage(format!(
                "{}: {} vertices; islands are found among at most {} (32-bit indices)",
                self.final_path.display(),
                self.vertices,
                u32::MAX
            ))
        })?;
        let pos = |i: u32| {
            let o = i as usize * STAGE_BYTES;
            Staged::decode(&map[o..o + STAGE_BYTES]).p
        };
        let (faces, count) = (&mut self.faces, self.faces_written);
        IslandFilter::new(
            n,
            pos,
            |f: &mut dyn FnMut([u32; 3])| {
                stream_faces(faces, count, |t| {
                    f(t);
                    Ok(())
                })
            },
            ratio,
        )
    }

    /// The size of a binary file, known from the counts.
    fn expected_bytes(&self) -> Option<u64> {
        let (vertices, faces) = self.counts_out();
        match self.format {
            MeshFormat::Ply => Some(
                header_bytes(self.vf) as u64
                    + vertices * self.vf.stride() as u64
                    + faces * FACE_BYTES,
            ),
            MeshFormat::Stl => Some(STL_HEADER as u64 + 4 + faces * STL_TRIANGLE),
            _ => None,
        }
    }
}

impl Drop for MeshWriter {
    fn drop(&mut self) {
        // Close before removing (some platforms cannot remove an open file); dropping the
        // output's AtomicFile removes its temporary file.
        self.out = None;
        self.verts.remove();
        self.faces.remove();
        self.normals.remove();
    }
}

#[cfg(test)]
mod tests;
