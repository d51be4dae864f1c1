//! Streaming binary-little-endian PLY point writer (also reached as [`crate::ply_write`]).
//!
//! [`PointPlyWriter`] writes a header announcing a fixed number of points, then appends
//! [`PointBatch`]es as they come, so that memory stays proportional to one batch whatever the
//! size of the file. Bytes go to a temporary file next to the final one
//! (`OUT.ply.tmp-<pid>`, an [`AtomicFile`]); [`PointPlyWriter::finish`] checks the count,
//! flushes, syncs and renames it into place, so a reader never sees a half-written file under the final name. A
//! writer dropped without `finish` (an error upstream, a panic) removes its temporary file.
//!
//! Layout of one vertex record, in this order, each part only when its attribute was asked
//! for: `x y z` (float32, or float64 with [`PointFileOptions::double`]), `nx ny nz` (float32), `red green blue` (uchar), `alpha` (uchar),
//! `intensity` (float32), `confidence` (float32), then the extra scalar of
//! [`PointFileOptions::scalar`] (float32). Colours are the high byte of the 16-bit channels of
//! [`PointBatch::color`]. The header is written from the model the readers parse into
//! (`write.rs`), its vertex element starting as the mesh encoders' does; the record's size is
//! the one its header declares.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use super::write::{WRITTEN_BY, header_text, put_f32, put_position, vertex_element};
use super::{Element, Encoding, Property, Scalar};
use crate::error::{Error, IoContext, Result};
use crate::fs::atomic::AtomicFile;
use crate::types::{Attributes, PointBatch};

/// Size of the write buffer.
const BUF_BYTES: usize = 1 << 20;

/// Points encoded per block before handing the bytes to the buffered writer.
const ENCODE_BLOCK: usize = 4096;

/// A binary-little-endian PLY point file being written; see the [module docs](self).
#[derive(Debug)]
pub struct PointPlyWriter {
    /// The name the file gets on [`PointPlyWriter::finish`].
    final_path: PathBuf,
    /// Where the bytes go until then (the name errors while writing refer to).
    tmp_path: PathBuf,
    /// The open temporary file; `None` once finished or after a failed write. Dropping it
    /// removes the temporary file.
    out: Option<BufWriter<AtomicFile>>,
    /// Attributes written per point.
    attrs: Attributes,
    /// Points announced in the header.
    count: u64,
    /// Points written so far.
    written: u64,
    /// Bytes of one record.
    stride: usize,
    /// Scratch for encoding a block of records.
    scratch: Vec<u8>,
    /// Positions as double, and an extra scalar property.
    opts: PointFileOptions,
}

/// Options of a point file beyond its attributes.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct PointFileOptions {
    /// Positions as `double` instead of `float` (coordinates far from the origin).
    pub double: bool,
    /// Name of one extra `float` property per point, written after the attributes.
    pub scalar: Option<String>,
}

/// The `vertex` element of `count` points carrying `attrs`: [`vertex_element`]'s properties,
/// then `alpha`, `intensity`, `confidence` and the extra scalar, as the module docs list them.
fn vertex(count: u64, attrs: Attributes, opts: &PointFileOptions) -> Element {
    let mut v = vertex_element(count, opts.double, attrs.normal, attrs.color);
    let mut add = |ty: Scalar, name: &str| v.props.push(Property::scalar(ty, name));
    if attrs.color && attrs.alpha {
        add(Scalar::U8, "alpha");
    }
    if attrs.intensity {
        add(Scalar::F32, "intensity");
    }
    if attrs.confidence {
        add(Scalar::F32, "confidence");
    }
    if let Some(name) = &opts.scalar {
        add(Scalar::F32, name.as_str());
    }
    v
}

impl PointPlyWriter {
    /// Start writing `count` points carrying `attrs` to `path`.
    ///
    /// The header is written at once to the temporary file `path` + `.tmp-<pid>`. `alpha`
    /// needs `color` (the alpha channel is written with the colour); asking for it alone is an
    /// [`Error::Usage`].
    pub fn create(path: &Path, count: u64, attrs: Attributes) -> Result<Self> {
        Self::create_with(path, count, attrs, PointFileOptions::default())
    }

    /// [`PointPlyWriter::create`] with positions as `double` and an extra scalar when `opts`
    /// says so.
    pub fn create_with(
        path: &Path,
        count: u64,
        attrs: Attributes,
        opts: PointFileOptions,
    ) -> Result<Self> {
        if attrs.alpha && !attrs.color {
            return Err(Error::Usage(format!(
                "{}: cannot write alpha without colour (red green blue)",
                path.display()
            )));
        }
        if path.as_os_str().is_empty() {
            return Err(Error::Usage("empty output file name".to_string()));
        }
        let vertex = vertex(count, attrs, &opts);
        let stride = vertex.fixed_size().expect("a vertex element of scalars") as usize;
        let file = AtomicFile::create(path)?;
        let mut w = PointPlyWriter {
            final_path: path.to_path_buf(),
            tmp_path: file.tmp_path().to_path_buf(),
            out: Some(BufWriter::with_capacity(BUF_BYTES, file)),
            attrs,
            count,
            written: 0,
            stride,
            scratch: Vec::new(),
            opts,
        };
        // From here on, a failure drops `w`, which removes the temporary file.
        let h = header_text(Encoding::BinaryLe, &[WRITTEN_BY], &[vertex]);
        w.sink()?.write_all(h.as_bytes()).with_path(&w.tmp_path)?;
        Ok(w)
    }

    /// The final path of the file.
    pub fn path(&self) -> &Path {
        &self.final_path
    }

    /// The attributes written per point.
    pub fn attributes(&self) -> Attributes {
        self.attrs
    }

    /// Points announced in the header.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Points written so far.
    pub fn written(&self) -> u64 {
        self.written
    }

    /// The open file, or an error once the writer is unusable.
    fn sink(&mut self) -> Result<&mut BufWriter<AtomicFile>> {
        match self.out.as_mut() {
            Some(w) => Ok(w),
            None => Err(Error::Internal(format!(
                "{}: PLY writer used after it was closed",
                self.final_path.display()
            ))),
        }
    }

    /// Check that `batch` carries what the header announces and holds writable values, so
    /// that a bad batch is refused whole, before any of its bytes is written.
    fn check(&self, batch: &PointBatch, scalars: Option<&[f32]>) -> Result<()> {
        let n = batch.pos.len();
        if self.opts.scalar.is_some() && scalars.map(|s| s.len()) != Some(n) {
            return Err(Error::Usage(format!(
                "{}: cannot write batch: the file has a scalar per point, the batch {} of {n}",
                self.final_path.display(),
                scalars.map_or(0, |s| s.len())
            )));
        }
        let left = self.count - self.written;
        if n as u64 > left {
            return Err(Error::Usage(format!(
                "{}: {} points announced, {} written, cannot append {n} more",
                self.final_path.display(),
                self.count,
                self.written
            )));
        }
        let mut need: Vec<(&str, usize)> = Vec::new();
        if self.attrs.normal {
            need.push(("normals", batch.normal.len()));
        }
        if self.attrs.color {
            need.push(("colours", batch.color.len()));
        }
        if self.attrs.intensity {
            need.push(("intensities", batch.intensity.len()));
        }
        if self.attrs.confidence {
            need.push(("confidences", batch.confidence.len()));
        }
        for (what, len) in need {
            if len != n {
                let msg = if len == 0 {
                    format!("the points carry no {what}, which the file was created with")
                } else {
                    format!("{len} {what} for {n} points")
                };
                return Err(Error::Usage(format!(
                    "{}: cannot write batch: {msg}",
                    self.final_path.display()
                )));
            }
        }
        for (i, p) in batch.pos.iter().enumerate() {
            for (axis, &v) in ["x", "y", "z"].iter().zip(p) {
                let (held, ty) = if self.opts.double {
                    (v.is_finite(), "double")
                } else {
                    ((v as f32).is_finite(), "float32")
                };
                if !held {
                    return Err(Error::Usage(format!(
                        "{}: point {}: {axis} is {v}, which a {ty} cannot hold",
                        self.final_path.display(),
                        self.written + i as u64
                    )));
                }
            }
        }
        Ok(())
    }

    /// Append the points of `batch`.
    ///
    /// The batch must carry every attribute the writer was created with (its extra attributes
    /// are ignored), its positions must be finite in float32, and the total must not exceed the
    /// count announced in the header; otherwise nothing of the batch is written and an
    /// [`Error::Usage`] says why.
    pub fn write(&mut self, batch: &PointBatch) -> Result<()> {
        self.write_with(batch, None)
    }

    /// [`PointPlyWriter::write`] with the extra scalar of each point (required when the file
    /// was created with one, ignored otherwise).
    pub fn write_with(&mut self, batch: &PointBatch, scalars: Option<&[f32]>) -> Result<()> {
        self.check(batch, scalars)?;
        let double = self.opts.double;
        let scalars = scalars.filter(|_| self.opts.scalar.is_some());
        let attrs = self.attrs;
        let stride = self.stride;
        let n = batch.pos.len();
        let mut scratch = std::mem::take(&mut self.scratch);
        let mut start = 0;
        let mut result = Ok(());
        while start < n {
            let end = (start + ENCODE_BLOCK).min(n);
            scratch.clear();
            scratch.reserve(stride * (end - start));
            for i in start..end {
                put_position(&mut scratch, batch.pos[i], double);
                if attrs.normal {
                    put_f32(&mut scratch, &batch.normal[i]);
                }
                if attrs.color {
                    let c = batch.color[i];
                    scratch.extend_from_slice(&[
                        (c[0] >> 8) as u8,
                        (c[1] >> 8) as u8,
                        (c[2] >> 8) as u8,
                    ]);
                    if attrs.alpha {
                        scratch.push((c[3] >> 8) as u8);
                    }
                }
                if attrs.intensity {
                    scratch.extend_from_slice(&batch.intensity[i].to_le_bytes());
                }
                if attrs.confidence {
                    scratch.extend_from_slice(&batch.confidence[i].to_le_bytes());
                }
                if let Some(s) = scalars {
                    scratch.extend_from_slice(&s[i].to_le_bytes());
                }
            }
            let tmp = &self.tmp_path;
            result = match self.out.as_mut() {
                Some(w) => w.write_all(&scratch).with_path(tmp),
                None => Err(Error::Internal(format!(
                    "{}: PLY writer used after it was closed",
                    self.final_path.display()
                ))),
            };
            if result.is_err() {
                // The file now holds part of the batch: it cannot be finished any more.
                self.out = None;
                break;
            }
            self.written += (end - start) as u64;
            start = end;
        }
        self.scratch = scratch;
        result
    }

    /// Check that exactly the announced number of points was written, flush, and commit the
    /// file ([`AtomicFile::commit`]: sync, rename to its final name, directory sync). On error
    /// the temporary file is removed and the final path is left as it was.
    pub fn finish(mut self) -> Result<()> {
        if self.written != self.count {
            return Err(Error::Internal(format!(
                "{}: the header announces {} points but {} were written",
                self.final_path.display(),
                self.count,
                self.written
            )));
        }
        let out = match self.out.take() {
            Some(w) => w,
            None => {
                return Err(Error::Internal(format!(
                    "{}: PLY writer finished after a failed write",
                    self.final_path.display()
                )));
            }
        };
        let file = out
            .into_inner()
            .map_err(|e| Error::io(&self.tmp_path, e.into_error()))?;
        file.commit()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fs::atomic::temp_name;

    fn read_f32(b: &[u8], at: usize) -> f32 {
        f32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
    }

    fn split_header(bytes: &[u8]) -> (String, &[u8]) {
        let tag = b"end_header\n";
        let end = bytes
            .windows(tag.len())
            .position(|w| w == tag)
            .expect("end_header")
            + tag.len();
        (
            String::from_utf8(bytes[..end].to_vec()).expect("ascii header"),
            &bytes[end..],
        )
    }

    fn full_attrs() -> Attributes {
        Attributes {
            normal: true,
            color: true,
            alpha: true,
            intensity: true,
            confidence: true,
            source: false,
        }
    }

    #[test]
    fn writes_positions_only() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.ply");
        let mut w = PointPlyWriter::create(&path, 3, Attributes::default()).unwrap();
        let batch = PointBatch {
            pos: vec![[1.0, 2.0, 3.0], [-0.5, 0.25, 1e3]],
            ..Default::default()
        };
        w.write(&batch).unwrap();
        w.write(&PointBatch::default()).unwrap();
        w.write(&PointBatch {
            pos: vec![[0.1, 0.2, 0.3]],
            ..Default::default()
        })
        .unwrap();
        assert_eq!(w.written(), 3);
        w.finish().unwrap();

        let bytes = std::fs::read(&path).unwrap();
        let (h, data) = split_header(&bytes);
        assert_eq!(
            h,
            "ply\nformat binary_little_endian 1.0\ncomment written by scanflow\n\
             element vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
             end_header\n"
        );
        assert_eq!(data.len(), 3 * 12);
        let expect = [1.0f32, 2.0, 3.0, -0.5, 0.25, 1e3, 0.1, 0.2, 0.3];
        for (i, e) in expect.iter().enumerate() {
            assert_eq!(read_f32(data, 4 * i), *e);
        }
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("p.ply")]);
    }

    #[test]
    fn writes_all_attributes() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.ply");
        let mut w = PointPlyWriter::create(&path, 2, full_attrs()).unwrap();
        let batch = PointBatch {
            pos: vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]],
            normal: vec![[0.0, 0.0, 1.0], [0.6, 0.8, 0.0]],
            color: vec![[65535, 0x1234, 257, 0x8000], [0, 255, 256, 65535]],
            intensity: vec![0.5, 7.0],
            confidence: vec![0.25, 1.0],
            source: vec![],
        };
        w.write(&batch).unwrap();
        w.finish().unwrap();

        let bytes = std::fs::read(&path).unwrap();
        let (h, data) = split_header(&bytes);
        let lines: Vec<&str> = h.lines().collect();
        assert_eq!(
            lines,
            vec![
                "ply",
                "format binary_little_endian 1.0",
                "comment written by scanflow",
                "element vertex 2",
                "property float x",
                "property float y",
                "property float z",
                "property float nx",
                "property float ny",
                "property float nz",
                "property uchar red",
                "property uchar green",
                "property uchar blue",
                "property uchar alpha",
                "property float intensity",
                "property float confidence",
                "end_header",
            ]
        );
        let stride = 12 + 12 + 4 + 4 + 4;
        assert_eq!(data.len(), 2 * stride);
        let r1 = &data[stride..];
        assert_eq!(read_f32(data, 8), 3.0);
        assert_eq!(read_f32(data, 20), 1.0);
        assert_eq!(&data[24..28], &[255, 0x12, 1, 0x80]);
        assert_eq!(read_f32(data, 28), 0.5);
        assert_eq!(read_f32(data, 32), 0.25);
        assert_eq!(read_f32(r1, 0), 4.0);
        assert_eq!(read_f32(r1, 12), 0.6);
        assert_eq!(read_f32(r1, 16), 0.8);
        assert_eq!(&r1[24..28], &[0, 0, 1, 255]);
        assert_eq!(read_f32(r1, 28), 7.0);
        assert_eq!(read_f32(r1, 32), 1.0);
    }

    #[test]
    fn colour_without_alpha_and_extra_batch_attributes_ignored() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.ply");
        let attrs = Attributes {
            color: true,
            ..Default::default()
        };
        let mut w = PointPlyWriter::create(&path, 1, attrs).unwrap();
        w.write(&PointBatch {
            pos: vec![[0.0; 3]],
            normal: vec![[1.0, 0.0, 0.0]],
            color: vec![[0xff00, 0x7fff, 0x0100, 0]],
            intensity: vec![3.0],
            confidence: vec![],
            source: vec![],
        })
        .unwrap();
        w.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let (h, data) = split_header(&bytes);
        assert!(h.contains("property uchar blue\nend_header\n"));
        assert!(!h.contains("alpha") && !h.contains("nx"));
        assert_eq!(
            data,
            &[0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0xff, 0x7f, 0x01]
        );
    }

    #[test]
    fn missing_attribute_is_refused_whole() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.ply");
        let attrs = Attributes {
            normal: true,
            ..Default::default()
        };
        let mut w = PointPlyWriter::create(&path, 2, attrs).unwrap();
        let err = w
            .write(&PointBatch {
                pos: vec![[0.0; 3]],
                ..Default::default()
            })
            .unwrap_err();
        assert!(matches!(err, Error::Usage(_)), "{err}");
        assert!(err.to_string().contains("normals"), "{err}");
        let err = w
            .write(&PointBatch {
                pos: vec![[0.0; 3], [1.0; 3]],
                normal: vec![[0.0, 0.0, 1.0]],
                ..Default::default()
            })
            .unwrap_err();
        assert!(matches!(err, Error::Usage(_)), "{err}");
        assert_eq!(w.written(), 0);
        // Still usable after a refused batch.
        w.write(&PointBatch {
            pos: vec![[0.0; 3], [1.0; 3]],
            normal: vec![[0.0, 0.0, 1.0]; 2],
            ..Default::default()
        })
        .unwrap();
        w.finish().unwrap();
        assert!(path.exists());
    }

    #[test]
    fn too_many_points_and_non_finite_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.ply");
        let mut w = PointPlyWriter::create(&path, 1, Attributes::default()).unwrap();
        let two = PointBatch {
            pos: vec![[0.0; 3]; 2],
            ..Default::default()
        };
        assert!(matches!(w.write(&two), Err(Error::Usage(_))));
        let nan = PointBatch {
            pos: vec![[0.0, f64::NAN, 0.0]],
            ..Default::default()
        };
        let err = w.write(&nan).unwrap_err();
        assert!(err.to_string().contains("y is NaN"), "{err}");
        let big = PointBatch {
            pos: vec![[1e300, 0.0, 0.0]],
            ..Default::default()
        };
        assert!(matches!(w.write(&big), Err(Error::Usage(_))));
        assert_eq!(w.written(), 0);
    }

    #[test]
    fn alpha_without_colour_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.ply");
        let attrs = Attributes {
            alpha: true,
            ..Default::default()
        };
        assert!(matches!(
            PointPlyWriter::create(&path, 1, attrs),
            Err(Error::Usage(_))
        ));
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn short_count_fails_and_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.ply");
        std::fs::write(&path, b"old").unwrap();
        let mut w = PointPlyWriter::create(&path, 5, Attributes::default()).unwrap();
        w.write(&PointBatch {
            pos: vec![[0.0; 3]; 4],
            ..Default::default()
        })
        .unwrap();
        let err = w.finish().unwrap_err();
        assert!(
            err.to_string().contains("announces 5 points but 4"),
            "{err}"
        );
        // The old file is untouched and the temporary one is gone.
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn drop_without_finish_removes_temp() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.ply");
        {
            let mut w = PointPlyWriter::create(&path, 1, Attributes::default()).unwrap();
            assert!(temp_name(&path).exists());
            w.write(&PointBatch {
                pos: vec![[0.0; 3]],
                ..Default::default()
            })
            .unwrap();
        }
        assert!(!temp_name(&path).exists());
        assert!(!path.exists());
    }

    #[test]
    fn missing_directory_is_an_io_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("no/such/dir/p.ply");
        let err = PointPlyWriter::create(&path, 1, Attributes::default()).unwrap_err();
        assert!(matches!(err, Error::Io { .. }), "{err}");
    }

    #[test]
    fn large_batch_spans_encode_blocks() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("l.ply");
        let n = ENCODE_BLOCK * 2 + 17;
        let attrs = Attributes {
            normal: true,
            ..Default::default()
        };
        let mut w = PointPlyWriter::create(&path, n as u64, attrs).unwrap();
        let batch = PointBatch {
            pos: (0..n).map(|i| [i as f64, 0.0, -(i as f64)]).collect(),
            normal: vec![[0.0, 1.0, 0.0]; n],
            ..Default::default()
        };
        w.write(&batch).unwrap();
        w.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let (_, data) = split_header(&bytes);
        assert_eq!(data.len(), n * 24);
        for i in [0, ENCODE_BLOCK - 1, ENCODE_BLOCK, n - 1] {
            assert_eq!(read_f32(data, i * 24), i as f32);
            assert_eq!(read_f32(data, i * 24 + 8), -(i as f32));
            assert_eq!(read_f32(data, i * 24 + 16), 1.0);
        }
    }
}
