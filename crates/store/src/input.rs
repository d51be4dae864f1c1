//! The opened inputs of an ingest: which attributes the store keeps, which record layout it
//! writes, and how one chunk of an input is loaded (decoded, colour-scaled, transformed and
//! tagged with its scan) by every pass that reads the inputs.

use std::sync::atomic::{AtomicBool, AtomicU16, Ordering};

use crate::cell_file::RecordLayout;
use crate::error::{Error, Result, Setting};
use crate::io::{ChunkSpec, InputSpec, PointReader};
use crate::manifest::InputEntry;
use crate::types::{Aabb, Attributes, PointBatch, Viewpoint};
use crate::{NormalsMode, StoreParams};

/// Most inputs a store can tell apart when its records carry their scan (a `u16` per point).
const MAX_SCANS: usize = u16::MAX as usize + 1;

/// Colour channels of LAS inputs whose values all fit in 8 bits are scaled by this factor
/// (`255 * 257 = 65535`), as the store's colours are always 16-bit.
const COLOR_8_TO_16: u16 = 257;

/// Open every input and check that the set is usable.
pub fn open_inputs(inputs: &[InputSpec]) -> Result<Vec<Box<dyn PointReader>>> {
    if inputs.is_empty() {
        return Err(Error::Usage("no input files given".into()));
    }
    inputs.iter().map(crate::io::open_input).collect()
}

/// The inputs of one ingest, opened, with what the store makes of them.
pub struct Inputs {
    /// The inputs, with the default viewpoint filled in where normals are to be estimated.
    pub specs: Vec<InputSpec>,
    /// One reader per input.
    pub readers: Vec<Box<dyn PointReader>>,
    /// Points in all inputs.
    pub total: u64,
    /// Layout of the records the passes write (without normals when they are estimated).
    pub layout: RecordLayout,
    /// Normals are to be estimated once the cells are written.
    pub estimate_normals: bool,
    skip_invalid: bool,
    /// Per input: the largest colour channel seen by the count pass.
    max_color: Vec<AtomicU16>,
    /// Per input: its colours are 8-bit values, scaled by [`COLOR_8_TO_16`] when loaded.
    scale8: Vec<AtomicBool>,
}

impl Inputs {
    /// Open `inputs` and decide the store's attributes and record layout.
    pub fn open(inputs: &[InputSpec], params: &StoreParams) -> Result<Inputs> {
        let mut readers = open_inputs(inputs)?;
        let total: u64 = readers.iter().map(|r| r.len()).sum();
        if total == 0 {
            return Err(Error::input(
                &inputs[0].path,
                "no points: the input files hold 0 points",
            ));
        }
        let mut attrs = common_attributes(&readers);
        // Positions are kept as f32 when that is exact: every input stores float32 coordinates
        // and none is transformed. Records shrink from 36 to 24 bytes for an oriented cloud.
        let pos_f32 = readers
            .iter()
            .zip(inputs)
            .all(|(r, i)| r.positions_f32() && i.transform.is_identity());
        // Normals: from the inputs, or estimated once the cells are written (the records then
        // carry each point's scan while a viewpoint is known, to orient them toward it).
        let estimate_normals = match params.normals {
            NormalsMode::Estimate => true,
            NormalsMode::Auto => !attrs.normal,
            NormalsMode::Use => {
                if let Some(r) = readers.iter().find(|r| !r.attributes().normal) {
                    return Err(Error::input(
                        r.path(),
                        format!(
                            "has no normals (nx ny nz) and {n} use was given; use {n} auto or estimate to estimate them",
                            n = Setting::Normals
                        ),
                    ));
                }
                false
            }
        };
        let mut specs: Vec<InputSpec> = inputs.to_vec();
        if estimate_normals {
            // The inputs' normals are not used, so their values are no error.
            readers.iter_mut().for_each(|r| r.ignore_normals());
            default_viewpoints(&mut specs, &readers);
            attrs.normal = false;
            attrs.source = specs.iter().any(|i| i.viewpoint.is_some());
            if attrs.source && specs.len() > MAX_SCANS {
                return Err(Error::Usage(format!(
                    "{} inputs with viewpoints: at most {MAX_SCANS} are supported",
                    specs.len(),
                )));
            }
        }
        Ok(Inputs {
            max_color: readers.iter().map(|_| AtomicU16::new(0)).collect(),
            scale8: readers.iter().map(|_| AtomicBool::new(false)).collect(),
            specs,
            readers,
            total,
            layout: RecordLayout::new(attrs, pos_f32),
            estimate_normals,
            skip_invalid: params.skip_invalid,
        })
    }

    /// Every input cut into chunks of about `chunk_points` points, tagged with their input.
    pub fn chunks(&self, chunk_points: u64) -> Result<Vec<(usize, ChunkSpec)>> {
        let mut chunks = Vec::new();
        for (i, r) in self.readers.iter().enumerate() {
            chunks.extend(r.chunks(chunk_points)?.into_iter().map(|c| (i, c)));
        }
        Ok(chunks)
    }

    /// Bytes of all input files (0 for a file that cannot be measured).
    pub fn input_bytes(&self) -> u64 {
        self.specs
            .iter()
            .map(|i| std::fs::metadata(&i.path).map(|m| m.len()).unwrap_or(0))
            .sum()
    }

    /// The union of the headers' bounds (after each input's transform), when every input has
    /// them.
    pub fn header_bounds(&self) -> Option<Aabb> {
        self.readers
            .iter()
            .zip(&self.specs)
            .map(|(r, i)| r.header_bounds().map(|b| transform_box(&b, i)))
            .try_fold(Aabb::EMPTY, |acc, b| b.map(|b| acc.union(&b)))
    }

    /// Load chunk `spec` of input `ri` into `batch` as the store records it; returns the
    /// points skipped as invalid.
    pub fn load(&self, batch: &mut PointBatch, ri: usize, spec: &ChunkSpec) -> Result<u64> {
        batch.clear();
        let st = self.readers[ri].read_chunk(spec, self.skip_invalid, batch)?;
        // LAS files often hold 8-bit colour in their 16-bit fields: the count pass records
        // each input's largest channel ([`Inputs::settle_colour_scale`] then decides).
        if self.layout.attrs.color && self.readers[ri].format().is_las() {
            let m = batch
                .color
                .iter()
                .map(|c| c[0].max(c[1]).max(c[2]))
                .max()
                .unwrap_or(0);
            self.max_color[ri].fetch_max(m, Ordering::Relaxed);
            if self.scale8[ri].load(Ordering::Relaxed) {
                for c in &mut batch.color {
                    for v in &mut c[..3] {
                        *v = v.saturating_mul(COLOR_8_TO_16);
                    }
                }
            }
        }
        let t = &self.specs[ri].transform;
        if !t.is_identity() {
            batch.transform(t);
        }
        if self.layout.attrs.source {
            batch.source.clear();
            batch.source.resize(batch.len(), ri as u16);
        }
        Ok(st.skipped_invalid)
    }

    /// Each input's largest colour channel seen so far by the count pass.
    pub fn max_colors(&self) -> Vec<u16> {
        self.max_color
            .iter()
            .map(|m| m.load(Ordering::Relaxed))
            .collect()
    }

    /// Raise each input's largest colour channel to at least `m`'s (what other processes'
    /// counts saw, for a store built by shards).
    pub fn raise_max_colors(&self, m: &[u16]) {
        for (a, &b) in self.max_color.iter().zip(m) {
            a.fetch_max(b, Ordering::Relaxed);
        }
    }

    /// After the count pass: scale the colours of every LAS input whose channels all fit in
    /// 0..=255 from then on.
    pub fn settle_colour_scale(&self) {
        for (ri, r) in self.readers.iter().enumerate() {
            let m = self.max_color[ri].load(Ordering::Relaxed);
            if self.layout.attrs.color && r.format().is_las() && m <= 255 {
                log::info!(
                    "{}: colours are 8-bit (at most {m}) in 16-bit fields; scaled by 257",
                    r.path().display()
                );
                self.scale8[ri].store(true, Ordering::Relaxed);
            }
        }
    }

    /// The manifest's entries for the inputs.
    pub fn entries(&self) -> Vec<InputEntry> {
        self.specs
            .iter()
            .zip(&self.readers)
            .enumerate()
            .map(|(k, (i, r))| InputEntry {
                path: i.path.display().to_string(),
                format: r.format(),
                points: r.len(),
                transform: i.transform,
                viewpoint: i.viewpoint,
                color_scale: if self.scale8[k].load(Ordering::Relaxed) {
                    COLOR_8_TO_16 as u32
                } else {
                    1
                },
            })
            .collect()
    }
}

/// The attributes every input carries; an input that carries more is told what is dropped.
fn common_attributes(readers: &[Box<dyn PointReader>]) -> Attributes {
    let attrs = readers
        .iter()
        .map(|r| r.attributes())
        .reduce(Attributes::intersect)
        .unwrap_or_default();
    for r in readers {
        if r.attributes() != attrs {
            log::warn!(
                "{}: carries {:?}, but not every input does; the store keeps {:?}",
                r.path().display(),
                r.attributes().names(),
                attrs.names()
            );
        }
    }
    attrs
}

/// Airborne LiDAR is seen from above: LAS and LAZ inputs without a viewpoint face up.
fn default_viewpoints(specs: &mut [InputSpec], readers: &[Box<dyn PointReader>]) {
    for (i, r) in specs.iter_mut().zip(readers) {
        if i.viewpoint.is_none() && r.format().is_las() {
            log::info!(
                "{}: {} without {}: normals face up (+z), as seen from the air",
                i.path.display(),
                r.format().name(),
                Setting::Viewpoint
            );
            i.viewpoint = Some(Viewpoint::Direction([0.0, 0.0, 1.0]));
        }
    }
}

/// The box holding `b` after the input's transform.
fn transform_box(b: &Aabb, i: &InputSpec) -> Aabb {
    let mut out = Aabb::EMPTY;
    for k in 0..8 {
        let c = [
            if k & 1 == 0 { b.min[0] } else { b.max[0] },
            if k & 2 == 0 { b.min[1] } else { b.max[1] },
            if k & 4 == 0 { b.min[2] } else { b.max[2] },
        ];
        out.add(i.transform.apply(c));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// A small terrain of `n * n` points (point format 0, no normals) as LAS or LAZ, by
    /// extension.
    fn write_terrain(path: &Path, n: usize) {
        let mut builder = las::Builder::default();
        builder.point_format = las::point::Format::new(0).unwrap();
        let header = builder.into_header().unwrap();
        let mut w = las::Writer::from_path(path, header).unwrap();
        for i in 0..n {
            for j in 0..n {
                let (x, y) = (i as f64, j as f64);
                let p = las::Point {
                    x,
                    y,
                    z: 0.1 * (x * 0.3).sin() * (y * 0.2).cos(),
                    ..Default::default()
                };
                w.write_point(p).unwrap();
            }
        }
        w.close().unwrap();
    }

    #[test]
    fn laz_without_viewpoint_faces_up_like_las() {
        let d = tempfile::tempdir().unwrap();
        for name in ["t.las", "t.laz", "t.LAZ"] {
            let p = d.path().join(name);
            write_terrain(&p, 8);
            let inputs = Inputs::open(&[InputSpec::plain(&p)], &StoreParams::default()).unwrap();
            assert!(inputs.readers[0].format().is_las(), "{name}");
            assert!(inputs.estimate_normals, "{name}");
            assert_eq!(
                inputs.specs[0].viewpoint,
                Some(Viewpoint::Direction([0.0, 0.0, 1.0])),
                "{name}"
            );
            assert!(inputs.layout.attrs.source, "{name}");
        }
    }
}
