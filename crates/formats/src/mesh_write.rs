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

use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use super::islands::IslandFilter;
use crate::error::{Error, IoContext, Result};
use crate::fs::atomic::{self, AtomicFile, with_suffix};
use crate::geom::vec::{cross, norm, sub};

/// Size of each write buffer.
const BUF_BYTES: usize = 1 << 20;

/// Bytes of one binary PLY face record: the count byte and 3 indices.
const FACE_BYTES: u64 = 1 + 3 * 4;

/// Bytes of a staged vertex: x y z as f64, colour, a pad byte, intensity and density as f32.
const STAGE_BYTES: usize = 24 + 4 + 4 + 4;

/// Bytes of a staged face: three u32 indices.
const STAGE_FACE_BYTES: usize = 12;

/// Normals gathered before they are written in place.
const NORMAL_BATCH: usize = 1 << 16;

/// Bytes of a binary STL's header, and of one of its triangles.
const STL_HEADER: usize = 80;
const STL_TRIANGLE: u64 = 50;

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
                "{}: --ascii is for PLY output; {} has one form only",
                path.display(),
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
            MeshFormat::Stl if normals => Some(
                "--out-normals: STL has no vertex normals (it stores each triangle's, always written)",
            ),
            MeshFormat::Stl | MeshFormat::Obj if density => {
                Some("--density: only PLY has a per-vertex scalar to hold it; write *.ply")
            }
            _ => None,
        };
        match refused {
            Some(why) => Err(Error::Usage(format!("{}: {why}", path.display()))),
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

/// A staged temporary file: written once, then read in as many passes as needed.
#[derive(Debug, Default)]
struct Stage {
    path: PathBuf,
    file: Option<BufWriter<File>>,
    /// A write failed: the file is short.
    broken: bool,
}

impl Stage {
    fn create(path: PathBuf) -> Result<Stage> {
        let f = atomic::create_temp_file(&path)?;
        Ok(Stage {
            path,
            file: Some(BufWriter::with_capacity(BUF_BYTES, f)),
            broken: false,
        })
    }

    fn broken(&self) -> Error {
        Error::Internal(format!(
            "{}: staged mesh file used after a failed write",
            self.path.display()
        ))
    }

    /// The open file, for writing.
    fn writer(&mut self) -> Result<&mut BufWriter<File>> {
        if self.broken || self.file.is_none() {
            return Err(self.broken());
        }
        Ok(self.file.as_mut().expect("checked above"))
    }

    /// Append `bytes`; a failed write breaks the stage.
    fn write(&mut self, bytes: &[u8]) -> Result<()> {
        let path = self.path.clone();
        let res = self.writer()?.write_all(bytes).with_path(&path);
        self.broken |= res.is_err();
        res
    }

    /// Flush and close the file (once written).
    fn close(&mut self) -> Result<()> {
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
    fn reader(&mut self) -> Result<BufReader<File>> {
        self.close()?;
        let f = File::open(&self.path).with_path(&self.path)?;
        Ok(BufReader::with_capacity(BUF_BYTES, f))
    }

    /// Close and remove the file.
    fn remove(&mut self) {
        self.file = None;
        if !self.path.as_os_str().is_empty() {
            atomic::remove_temp(&self.path);
            self.path = PathBuf::new();
        }
    }
}

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
fn header(vertices: u64, faces: u64, f: VertexFormat) -> String {
    let (head, tail) = header_parts(vertices, faces, f, false);
    let pad = header_bytes(f) - head.len() - tail.len();
    let mut h = head;
    h.push_str("comment");
    h.extend(std::iter::repeat_n(' ', pad - "comment\n".len()));
    h.push('\n');
    h.push_str(&tail);
    h
}

/// A staged vertex, read back.
#[derive(Debug, Clone, Copy)]
struct Staged {
    p: [f64; 3],
    color: [u8; 3],
    intensity: f32,
    density: f32,
}

impl Staged {
    fn encode(&self) -> [u8; STAGE_BYTES] {
        let mut r = [0u8; STAGE_BYTES];
        for d in 0..3 {
            r[8 * d..8 * d + 8].copy_from_slice(&self.p[d].to_le_bytes());
        }
        r[24..27].copy_from_slice(&self.color);
        r[28..32].copy_from_slice(&self.intensity.to_le_bytes());
        r[32..36].copy_from_slice(&self.density.to_le_bytes());
        r
    }

    fn decode(r: &[u8]) -> Staged {
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

/// A float written as text: the shortest form that reads back to the same value.
fn num(s: &mut String, v: f64, double: bool) {
    if double {
        let _ = write!(s, "{v:?}");
    } else {
        let _ = write!(s, "{:?}", v as f32);
    }
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
    fn counts_out(&self) -> (u64, u64) {
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

    /// The staged vertices, mapped (complete, no longer written: this writer's own file,
    /// which nothing else truncates while the map lives).
    fn map_vertices(&mut self) -> Result<crate::fs::mmap::Window> {
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

    /// Each vertex written with its normal (zero without normals), in order: every staged
    /// one but those of dropped islands.
    fn each_vertex(&mut self, mut f: impl FnMut(Staged, [f32; 3]) -> Result<()>) -> Result<()> {
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
    fn each_face(
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

    fn write_ply_binary(&mut self, w: &mut impl Write) -> Result<()> {
        let (vf, tmp) = (self.vf, self.tmp_path.clone());
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

    fn write_ply_ascii(&mut self, w: &mut impl Write) -> Result<()> {
        let (vf, tmp) = (self.vf, self.tmp_path.clone());
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

    fn write_obj(&mut self, w: &mut impl Write) -> Result<()> {
        let (vf, tmp) = (self.vf, self.tmp_path.clone());
        let (vertices, faces) = self.counts_out();
        writeln!(
            w,
            "# written by scanflow\n# {vertices} vertices, {faces} triangles"
        )
        .with_path(&tmp)?;
        let mut line = String::new();
        // Positions (and colours), then the normals: two passes over the staged vertices.
        self.each_vertex(|v, _| {
            line.clear();
            line.push('v');
            for x in v.p {
                line.push(' ');
                num(&mut line, x, vf.double);
            }
            if vf.color {
                for c in v.color {
                    line.push(' ');
                    num(&mut line, f64::from(c) / 255.0, false);
                }
            }
            line.push('\n');
            w.write_all(line.as_bytes()).with_path(&tmp)
        })?;
        if vf.normals {
            self.each_vertex(|_, n| {
                line.clear();
                line.push_str("vn");
                for x in n {
                    line.push(' ');
                    num(&mut line, x.into(), false);
                }
                line.push('\n');
                w.write_all(line.as_bytes()).with_path(&tmp)
            })?;
        }
        let normals = vf.normals;
        self.each_face(true, |t| {
            let [a, b, c] = t.map(|i| u64::from(i) + 1);
            if normals {
                writeln!(w, "f {a}//{a} {b}//{b} {c}//{c}").with_path(&tmp)
            } else {
                writeln!(w, "f {a} {b} {c}").with_path(&tmp)
            }
        })
    }

    fn write_stl(&mut self, w: &mut impl Write) -> Result<()> {
        let tmp = self.tmp_path.clone();
        let faces = self.counts_out().1;
        let Ok(count) = u32::try_from(faces) else {
            return Err(Error::Usage(format!(
                "{}: {faces} triangles; binary STL counts at most {} (write *.ply)",
                self.final_path.display(),
                u32::MAX
            )));
        };
        let mut head = [b' '; STL_HEADER];
        let title = b"binary STL written by scanflow";
        head[..title.len()].copy_from_slice(title);
        w.write_all(&head).with_path(&tmp)?;
        w.write_all(&count.to_le_bytes()).with_path(&tmp)?;
        let map = self.map_vertices()?;
        let corner = |i: u32| {
            let o = i as usize * STAGE_BYTES;
            Staged::decode(&map[o..o + STAGE_BYTES]).p.map(|x| x as f32)
        };
        let path = self.final_path.clone();
        // Corners are looked up by their staged numbers.
        self.each_face(false, |t| {
            let p = t.map(corner);
            if p.iter().flatten().any(|x| !x.is_finite()) {
                return Err(Error::Usage(format!(
                    "{}: a corner of triangle {t:?} does not fit STL's float32",
                    path.display()
                )));
            }
            let n = unit_normal(p);
            let mut r = [0u8; STL_TRIANGLE as usize];
            for (k, x) in n.iter().chain(p.iter().flatten()).enumerate() {
                r[4 * k..4 * k + 4].copy_from_slice(&x.to_le_bytes());
            }
            w.write_all(&r).with_path(&tmp)
        })
    }
}

/// The `count` staged faces of `stage`, in order.
fn stream_faces(
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

/// The unit normal of triangle `p` (counter-clockwise seen from its front), zero where it has
/// no area.
fn unit_normal(p: [[f32; 3]; 3]) -> [f32; 3] {
    let p = p.map(|c| c.map(f64::from));
    let c = cross(sub(p[1], p[0]), sub(p[2], p[0]));
    let len = norm(c);
    if len > 0.0 && len.is_finite() {
        c.map(|x| (x / len) as f32)
    } else {
        [0.0; 3]
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
mod tests {
    use super::*;
    use crate::PointReader;
    use crate::ply::PlyReader;
    use crate::types::PointBatch;

    const TETRA: [[f64; 3]; 4] = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    /// Outward (counter-clockwise seen from outside).
    const TETRA_FACES: [[u64; 3]; 4] = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];

    fn ply_header_bytes(color: bool) -> usize {
        header_bytes(VertexFormat {
            color,
            ..VertexFormat::default()
        })
    }

    fn write_tetra(path: &Path, color: bool) -> MeshWriteStats {
        let mut w = MeshWriter::ply(path, color).unwrap();
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

            let hb = ply_header_bytes(color);
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
        let mut w = MeshWriter::create(&path, MeshFormat::Ply, utm).unwrap();
        let ps = [
            [5.0e6 + 0.123456, 5.0e6 + 1.0, 100.25],
            [5.0e6 + 2.0, 5.0e6 + 0.000001, 101.0],
            [5.0e6, 5.0e6 + 3.5, 102.0],
        ];
        for (i, p) in ps.iter().enumerate() {
            w.vertex_with(*p, Some([i as u8, 2, 3]), Some(0.5 * i as f32), None)
                .unwrap();
        }
        w.triangle([0, 1, 2]).unwrap();
        let stats = w.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let hb = header_bytes(utm);
        assert_eq!(stats.bytes as usize, hb + 3 * utm.stride() + 13);
        let text = std::str::from_utf8(&bytes[..hb]).unwrap();
        assert!(text.contains("property double x\nproperty double y\nproperty double z\n"));
        assert!(text.contains("property float scalar_intensity\n"));
        assert!(!text.contains(" intensity"));
        let m = crate::mesh_read::read_mesh(&path).unwrap();
        assert_eq!(m.vertices, ps.to_vec());
        plyfile_check(&path, 3, 1);
    }

    #[test]
    fn empty_mesh_is_valid() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("e.ply");
        let stats = MeshWriter::ply(&path, false).unwrap().finish().unwrap();
        assert_eq!(stats.bytes, ply_header_bytes(false) as u64);
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("element vertex 0\n") && text.contains("element face 0\n"));
        plyfile_check(&path, 0, 0);
    }

    #[test]
    fn header_size_is_fixed_and_index_type_follows_the_count() {
        for color in [false, true] {
            let n = ply_header_bytes(color);
            for (v, f) in [(0, 0), (4, 4), (1 << 31, 7), (u64::MAX, u64::MAX)] {
                let fmt = |intensity, double| VertexFormat {
                    color,
                    intensity,
                    double,
                    ..VertexFormat::default()
                };
                let h = header(v, f, fmt(false, false));
                for (i, d) in [(true, false), (false, true), (true, true)] {
                    assert_eq!(header(v, f, fmt(i, d)).len(), header_bytes(fmt(i, d)));
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
        let mut w = MeshWriter::ply(&path, true).unwrap();
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
            let mut w = MeshWriter::ply(&path, false).unwrap();
            w.vertex([0.0; 3], None).unwrap();
            w.triangle([0, 0, 0]).unwrap();
            assert_eq!(names(dir.path()).len(), 4);
        }
        assert_eq!(names(dir.path()), vec!["d.ply".to_string()]);
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
    }

    #[test]
    fn missing_directory_is_an_io_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("no/such/m.ply");
        let e = MeshWriter::ply(&path, false).unwrap_err();
        assert!(matches!(e, Error::Io { .. }), "{e}");
    }

    #[test]
    fn larger_mesh_spans_buffers() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("l.ply");
        let mut w = MeshWriter::ply(&path, false).unwrap();
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
        let hb = ply_header_bytes(false);
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

    /// The tetrahedron in `format`, with normals given last-first and colours and densities.
    fn write_tetra_as(path: &Path, format: MeshFormat, vf: VertexFormat) -> MeshWriteStats {
        let mut w = MeshWriter::create(path, format, vf).unwrap();
        for (i, p) in TETRA.iter().enumerate() {
            let c = [10 * i as u8, 100, 255 - i as u8];
            w.vertex_with(*p, Some(c), Some(i as f32), Some(0.25 + i as f32))
                .unwrap();
        }
        for t in TETRA_FACES {
            w.triangle(t).unwrap();
        }
        // Vertex 0 gets (0, 0, -1), the others their own direction.
        for i in (0..4u64).rev() {
            let p = TETRA[i as usize];
            let l = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            let n = if l > 0.0 {
                p.map(|x| (x / l) as f32)
            } else {
                [0.0, 0.0, -1.0]
            };
            w.normal(i, n).unwrap();
        }
        w.finish().unwrap()
    }

    /// A tetrahedron a hundredth the size (vertices 0–3), the unit one (4–7), a lone vertex
    /// (8): with islands under 1% of the area dropped, every format holds exactly the unit
    /// tetrahedron, renumbered from 0, with its own normals and colours.
    #[test]
    fn dropped_islands_leave_every_format_with_the_large_piece() {
        let dir = tempfile::tempdir().unwrap();
        let vf = VertexFormat {
            color: true,
            normals: true,
            ..VertexFormat::default()
        };
        for (name, format) in [
            ("a.ply", MeshFormat::Ply),
            ("b.ply", MeshFormat::PlyAscii),
            ("c.obj", MeshFormat::Obj),
            ("d.stl", MeshFormat::Stl),
        ] {
            let path = dir.path().join(name);
            let vf = VertexFormat {
                normals: format != MeshFormat::Stl,
                ..vf
            };
            let mut w = MeshWriter::create(&path, format, vf).unwrap();
            w.drop_islands(0.01);
            let small = TETRA.map(|p| p.map(|x| 5.0 + 0.01 * x));
            for (k, p) in small.iter().chain(&TETRA).enumerate() {
                w.vertex(*p, Some([k as u8, 0, 0])).unwrap();
            }
            w.vertex([9.0; 3], Some([8, 0, 0])).unwrap();
            for base in [0, 4] {
                for t in TETRA_FACES {
                    w.triangle(t.map(|i| i + base)).unwrap();
                }
            }
            if vf.normals {
                for i in 0..9 {
                    w.normal(i, [0.0, 0.0, i as f32]).unwrap();
                }
            }
            let st = w.finish().unwrap();
            assert_eq!(st.bytes, std::fs::metadata(&path).unwrap().len(), "{name}");
            assert_eq!(st.faces, 4, "{name}");
            let m = crate::mesh_read::read_any_mesh(&path).unwrap();
            if format == MeshFormat::Stl {
                // STL's reader numbers corners as they come.
                let corners: Vec<[f64; 3]> = m
                    .triangles
                    .iter()
                    .flat_map(|t| t.map(|i| m.vertices[i as usize]))
                    .collect();
                let want: Vec<[f64; 3]> = TETRA_FACES
                    .iter()
                    .flat_map(|t| t.map(|i| TETRA[i as usize]))
                    .collect();
                assert_eq!(corners, want);
                continue;
            }
            assert_eq!(m.vertices, TETRA.to_vec(), "{name}");
            assert_eq!(
                m.triangles,
                TETRA_FACES.map(|t| t.map(|i| i as u32)).to_vec(),
                "{name}"
            );
            if format == MeshFormat::Ply {
                assert_eq!(st.vertices, 4);
                let bytes = std::fs::read(&path).unwrap();
                let hb = header_bytes(vf);
                assert!(
                    std::str::from_utf8(&bytes[..hb])
                        .unwrap()
                        .contains("element vertex 4\n")
                );
                // The first vertex written is staged vertex 4: its normal and colour.
                let rec = &bytes[hb..hb + vf.stride()];
                assert_eq!(f32::from_le_bytes(rec[20..24].try_into().unwrap()), 4.0);
                assert_eq!(rec[24], 4);
                plyfile_check(&path, 4, 4);
            }
        }
        assert_eq!(names(dir.path()), ["a.ply", "b.ply", "c.obj", "d.stl"]);
    }

    #[test]
    fn islands_that_leave_nothing_are_refused_and_nothing_is_written() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("n.ply");
        let mut w = MeshWriter::ply(&path, false).unwrap();
        w.drop_islands(0.6);
        for base in [0.0, 3.0] {
            for p in TETRA {
                w.vertex(p.map(|x| x + base), None).unwrap();
            }
        }
        for base in [0, 4] {
            for t in TETRA_FACES {
                w.triangle(t.map(|i| i + base)).unwrap();
            }
        }
        let e = w.finish().unwrap_err().to_string();
        assert!(e.contains("n.ply") && e.contains("2 pieces"), "{e}");
        assert!(names(dir.path()).is_empty());
    }

    #[test]
    fn every_format_holds_the_tetrahedron() {
        let dir = tempfile::tempdir().unwrap();
        let all = VertexFormat {
            color: true,
            intensity: true,
            normals: true,
            density: true,
            double: false,
        };
        // Binary PLY with everything: the records in the header's order.
        let path = dir.path().join("a.ply");
        let s = write_tetra_as(&path, MeshFormat::Ply, all);
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(s.bytes as usize, bytes.len());
        let hb = header_bytes(all);
        let text = std::str::from_utf8(&bytes[..hb]).unwrap();
        assert!(text.contains(
            "property float nx\nproperty float ny\nproperty float nz\nproperty uchar red\n"
        ));
        assert!(text.ends_with("property float scalar_intensity\nproperty float quality\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n"));
        assert_eq!(all.stride(), 12 + 12 + 3 + 4 + 4);
        let v1 = &bytes[hb + all.stride()..hb + 2 * all.stride()];
        assert_eq!(f32::from_le_bytes(v1[0..4].try_into().unwrap()), 1.0);
        assert_eq!(f32::from_le_bytes(v1[12..16].try_into().unwrap()), 1.0);
        assert_eq!(&v1[24..27], &[10, 100, 254]);
        assert_eq!(f32::from_le_bytes(v1[27..31].try_into().unwrap()), 1.0);
        assert_eq!(f32::from_le_bytes(v1[31..35].try_into().unwrap()), 1.25);
        let m = crate::mesh_read::read_mesh(&path).unwrap();
        assert_eq!(m.vertices, TETRA.to_vec());
        plyfile_check(&path, 4, 4);

        // ASCII PLY: the same mesh, read back by our own reader.
        let path = dir.path().join("b.ply");
        write_tetra_as(&path, MeshFormat::PlyAscii, all);
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.starts_with("ply\nformat ascii 1.0\n"), "{text}");
        assert!(
            text.contains("\n1.0 0.0 0.0 1.0 0.0 0.0 10 100 254 1.0 1.25\n"),
            "{text}"
        );
        assert!(text.ends_with("\n3 1 2 3\n"), "{text}");
        let m = crate::mesh_read::read_mesh(&path).unwrap();
        assert_eq!(m.vertices, TETRA.to_vec());
        assert_eq!(m.triangles.len(), 4);
        plyfile_check(&path, 4, 4);

        // OBJ: colours in [0, 1], normals as `vn`, 1-based faces; no intensity or density.
        let path = dir.path().join("c.obj");
        let obj = VertexFormat {
            density: false,
            ..all
        };
        write_tetra_as(&path, MeshFormat::Obj, obj);
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(
            text.contains("\nv 1.0 0.0 0.0 0.039215688 0.39215687 0.99607843\n"),
            "{text}"
        );
        assert!(text.contains("\nvn 0.0 1.0 0.0\n"), "{text}");
        assert!(text.ends_with("f 2//2 3//3 4//4\n"), "{text}");
        let m = crate::obj::read_obj(&path).unwrap();
        assert_eq!(m.vertices, TETRA.to_vec());
        assert_eq!(
            m.triangles,
            TETRA_FACES.map(|t| t.map(|i| i as u32)).to_vec()
        );

        // STL: 80 + 4 + 50 bytes a triangle, outward unit normals, corners in order.
        let path = dir.path().join("d.stl");
        let stl = VertexFormat {
            normals: false,
            density: false,
            ..all
        };
        let s = write_tetra_as(&path, MeshFormat::Stl, stl);
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(bytes.len(), 84 + 4 * 50);
        assert_eq!(s.bytes as usize, bytes.len());
        assert!(!bytes.starts_with(b"solid"));
        assert_eq!(u32::from_le_bytes(bytes[80..84].try_into().unwrap()), 4);
        let f = |o: usize| f32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
        // The first face, (0, 2, 1), lies in z = 0 and faces -z.
        assert_eq!([f(84), f(88), f(92)], [0.0, 0.0, -1.0]);
        assert_eq!([f(108), f(112), f(116)], [0.0, 1.0, 0.0]);
        let s3 = 1.0 / 3f32.sqrt();
        let last = 84 + 3 * 50;
        for k in 0..3 {
            assert!((f(last + 4 * k) - s3).abs() < 1e-6);
        }
        assert_eq!(names(dir.path()), ["a.ply", "b.ply", "c.obj", "d.stl"]);
    }

    #[test]
    fn formats_follow_the_extension_and_refuse_what_they_cannot_hold() {
        let f = |p: &str, ascii| MeshFormat::for_path(Path::new(p), ascii);
        assert_eq!(f("x.ply", false).unwrap(), MeshFormat::Ply);
        assert_eq!(f("x.PLY", true).unwrap(), MeshFormat::PlyAscii);
        assert_eq!(f("x.Obj", false).unwrap(), MeshFormat::Obj);
        assert_eq!(f("x.stl", false).unwrap(), MeshFormat::Stl);
        let e = f("x.off", false).unwrap_err().to_string();
        assert!(e.contains("x.off") && e.contains("*.stl"), "{e}");
        let e = f("x.obj", true).unwrap_err().to_string();
        assert!(e.contains("--ascii"), "{e}");
        let p = Path::new("m.stl");
        let e = MeshFormat::Stl
            .carries(p, true, false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("m.stl") && e.contains("--out-normals"), "{e}");
        let e = MeshFormat::Obj
            .carries(p, false, true)
            .unwrap_err()
            .to_string();
        assert!(e.contains("--density"), "{e}");
        MeshFormat::Obj.carries(p, true, false).unwrap();
        MeshFormat::PlyAscii.carries(p, true, true).unwrap();
    }

    #[test]
    fn missing_or_extra_normals_are_internal_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("n.ply");
        let vf = VertexFormat {
            normals: true,
            ..VertexFormat::default()
        };
        let mut w = MeshWriter::create(&path, MeshFormat::Ply, vf).unwrap();
        w.vertex([0.0; 3], None).unwrap();
        w.vertex([1.0; 3], None).unwrap();
        let e = w.normal(2, [0.0; 3]).unwrap_err();
        assert!(matches!(e, Error::Internal(_)), "{e}");
        w.normal(1, [0.0, 0.0, 1.0]).unwrap();
        let e = w.finish().unwrap_err();
        assert!(
            e.to_string().contains("1 normals given for 2 vertices"),
            "{e}"
        );
        assert!(names(dir.path()).is_empty());
    }

    #[test]
    fn many_normals_in_scattered_order_land_in_place() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.ply");
        let vf = VertexFormat {
            normals: true,
            ..VertexFormat::default()
        };
        let mut w = MeshWriter::create(&path, MeshFormat::Ply, vf).unwrap();
        let n = 3 * NORMAL_BATCH as u64 + 7;
        for i in 0..n {
            w.vertex([i as f64, 0.0, 0.0], None).unwrap();
        }
        // A permutation of the vertices: i -> i * 7919 mod n (n is not a multiple of 7919).
        for k in 0..n {
            let i = k * 7919 % n;
            w.normal(i, [i as f32, 1.0, 2.0]).unwrap();
        }
        w.triangle([0, 1, 2]).unwrap();
        w.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let hb = header_bytes(vf);
        for i in [0, 1, 12345, n - 1] {
            let o = hb + i as usize * 24 + 12;
            let nx = f32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
            assert_eq!(nx, i as f32);
        }
    }
}
