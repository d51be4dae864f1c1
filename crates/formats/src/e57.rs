//! ASTM E57 point clouds (the terrestrial scanners' exchange format: Leica, FARO, Trimble),
//! read through the `e57` crate.
//!
//! An E57 file holds one or more scans ("data3D" point clouds), each with its pose (a rigid
//! transform from the scanner's frame to the file's common frame), Cartesian or spherical
//! coordinates, and optionally colour and intensity. Points are read in the common frame
//! (each scan's pose applied; spherical coordinates converted), colours normalised by the
//! scan's colour limits to 16 bits, intensities as stored. Points a scanner marks invalid
//! (no return, or a direction without a range) are not surface samples: they are dropped
//! and counted as skipped.
//!
//! **Scans and viewpoints.** Ingest opens one input per scan ([`scan_inputs`]), whose
//! viewpoint is the scanner's position (its pose's translation), so normals estimated from
//! the points face the scanner that saw them, as for a `.conf` scan list.
//!
//! **Chunks.** E57's compressed vectors can only be decoded from a scan's start, so a
//! reader keeps decoding *streams*, each a thread that owns its own handle on the file: a
//! chunk goes to the stream that stopped where it starts, which continues; a chunk no stream
//! is at goes to a new stream (up to [`MAX_STREAMS`]) or to the one used least recently,
//! which restarts its scan and skips to it. Chunks never span two scans. Workers that each
//! read a run of consecutive chunks (as ingest's do) are each served by one stream, so each
//! point is decoded once.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use crossbeam_channel::{Receiver, Sender, bounded};

use super::{ChunkSpec, ChunkStats, Format, InputSpec, PointReader};
use crate::error::{Error, Result};
use crate::types::{Attributes, PointBatch, Rigid, Viewpoint};

/// The most decoding streams a reader keeps (see the module docs).
pub const MAX_STREAMS: usize = 16;

/// One scan of the file, as the reader sees it.
#[derive(Debug, Clone)]
struct Scan {
    /// Index among the file's point clouds.
    index: usize,
    /// Its records (valid or not).
    records: u64,
    /// Index of its first record among the reader's points.
    first: u64,
}

/// A request to the decoding thread: the chunk, and where to send its points.
struct Request {
    chunk: ChunkSpec,
    reply: Sender<Result<Decoded>>,
}

/// Points decoded for a chunk.
#[derive(Default)]
struct Decoded {
    pos: Vec<[f64; 3]>,
    color: Vec<[u16; 4]>,
    intensity: Vec<f32>,
    invalid: u64,
}

/// An E57 file's scans as one point source (see the module docs).
pub struct E57Reader {
    path: PathBuf,
    scans: Vec<Scan>,
    len: u64,
    attrs: Attributes,
    /// The scans' point clouds, for new streams.
    pcs: Vec<e57::PointCloud>,
    /// The decoding streams.
    streams: Mutex<Streams>,
}

/// The decoding threads and where each stopped.
#[derive(Default)]
struct Streams {
    /// Per stream: its requests, the index its next point has, when it was last given work.
    list: Vec<(Sender<Request>, u64, u64)>,
    tick: u64,
}

impl std::fmt::Debug for E57Reader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("E57Reader")
            .field("path", &self.path)
            .field("scans", &self.scans.len())
            .field("len", &self.len)
            .finish()
    }
}

/// An `e57` crate error as ours, naming the file.
fn bad(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::input(path, format!("not a readable E57 file: {e}"))
}

/// The file's point clouds.
fn point_clouds(path: &Path) -> Result<Vec<e57::PointCloud>> {
    crate::regular_file(path, "an E57 file")?;
    let r = e57::E57Reader::from_file(path).map_err(|e| bad(path, e))?;
    Ok(r.pointclouds())
}

/// One input per scan of the E57 file `path`: its scan index, and the scanner's position
/// (the pose's translation) as the viewpoint.
pub fn scan_inputs(path: &Path) -> Result<Vec<InputSpec>> {
    let pcs = point_clouds(path)?;
    if pcs.is_empty() {
        return Err(Error::input(path, "holds no scan (no data3D point cloud)"));
    }
    Ok(pcs
        .iter()
        .enumerate()
        .map(|(i, pc)| InputSpec {
            path: path.to_path_buf(),
            transform: Rigid::IDENTITY,
            viewpoint: Some(Viewpoint::Point(
                pc.transform.as_ref().map_or([0.0; 3], |t| {
                    [t.translation.x, t.translation.y, t.translation.z]
                }),
            )),
            scan: Some(i),
        })
        .collect())
}

/// What `info` shows of an E57 file: its header and every scan's pose and sensor.
#[derive(Debug, Clone, serde::Serialize)]
pub struct E57Meta {
    /// Format version, `major.minor`.
    pub version: String,
    /// The file's GUID.
    pub guid: String,
    /// The library that wrote it, where recorded.
    pub library: Option<String>,
    /// The coordinate reference system as written (`coordinateMetadata`: WKT, an EPSG code or
    /// free text), where recorded.
    pub crs: Option<String>,
    /// The scans.
    pub scans: Vec<ScanMeta>,
    /// Where the CRS contradicts the coordinates, as for LAS
    /// ([`Crs::from_text`](crate::las_meta::Crs::from_text), then its warnings); filled by
    /// `info`, which knows the points' bounds.
    pub warnings: Vec<String>,
}

/// One scan of an E57 file.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ScanMeta {
    /// Its name, where recorded.
    pub name: Option<String>,
    /// Records (valid or not).
    pub points: u64,
    /// The pose's translation: the scanner's position in the file's frame.
    pub position: [f64; 3],
    /// The pose's rotation as a unit quaternion `w x y z`.
    pub rotation: [f64; 4],
    /// Vendor, model and serial number of the sensor, where recorded.
    pub sensor: Option<String>,
    /// Coordinates stored: `cartesian`, `spherical` or both.
    pub coordinates: String,
    /// Colour and intensity stored.
    pub color: bool,
    /// Intensity stored.
    pub intensity: bool,
}

/// The header and scans of the E57 file `path`.
pub fn file_meta(path: &Path) -> Result<E57Meta> {
    crate::regular_file(path, "an E57 file")?;
    let r = e57::E57Reader::from_file(path).map_err(|e| bad(path, e))?;
    let h = r.header();
    let scans = r
        .pointclouds()
        .iter()
        .map(|pc| {
            let t = pc.transform.clone().unwrap_or_default();
            let sensor: Vec<&str> = [&pc.sensor_vendor, &pc.sensor_model, &pc.sensor_serial]
                .into_iter()
                .filter_map(|s| s.as_deref())
                .collect();
            ScanMeta {
                name: pc.name.clone(),
                points: pc.records,
                position: [t.translation.x, t.translation.y, t.translation.z],
                rotation: [t.rotation.w, t.rotation.x, t.rotation.y, t.rotation.z],
                sensor: (!sensor.is_empty()).then(|| sensor.join(" ")),
                coordinates: match (pc.has_cartesian(), pc.has_spherical()) {
                    (true, true) => "cartesian and spherical",
                    (true, false) => "cartesian",
                    _ => "spherical",
                }
                .to_string(),
                color: pc.has_color(),
                intensity: pc.has_intensity(),
            }
        })
        .collect();
    Ok(E57Meta {
        version: format!("{}.{}", h.major, h.minor),
        guid: r.guid().to_string(),
        library: r.library_version().map(str::to_string),
        crs: r
            .coordinate_metadata()
            .filter(|c| !c.trim().is_empty())
            .map(str::to_string),
        scans,
        warnings: Vec::new(),
    })
}

impl E57Reader {
    /// Open `path`: scan `scan` only, or every scan.
    pub fn open(path: &Path, scan: Option<usize>) -> Result<E57Reader> {
        let pcs = point_clouds(path)?;
        let chosen: Vec<usize> = match scan {
            Some(i) if i < pcs.len() => vec![i],
            Some(i) => {
                return Err(Error::input(
                    path,
                    format!("has {} scans; scan {i} does not exist", pcs.len()),
                ));
            }
            None => (0..pcs.len()).collect(),
        };
        if chosen.is_empty() {
            return Err(Error::input(path, "holds no scan (no data3D point cloud)"));
        }
        let mut scans = Vec::new();
        let mut len = 0;
        for &i in &chosen {
            let pc = &pcs[i];
            if !pc.has_cartesian() && !pc.has_spherical() {
                return Err(Error::input(
                    path,
                    format!("scan {i} has neither Cartesian nor spherical coordinates"),
                ));
            }
            scans.push(Scan {
                index: i,
                records: pc.records,
                first: len,
            });
            len += pc.records;
        }
        let color = chosen.iter().all(|&i| pcs[i].has_color());
        let intensity = chosen.iter().all(|&i| pcs[i].has_intensity());
        let attrs = Attributes {
            color,
            intensity,
            ..Attributes::default()
        };
        Ok(E57Reader {
            path: path.to_path_buf(),
            scans,
            len,
            attrs,
            pcs: chosen.iter().map(|&i| pcs[i].clone()).collect(),
            streams: Mutex::default(),
        })
    }

    /// The stream for `chunk` (see the module docs), marked as stopping at its end.
    fn stream_for(&self, chunk: &ChunkSpec) -> Result<Sender<Request>> {
        let mut st = self
            .streams
            .lock()
            .map_err(|_| Error::Internal("E57 reader lock poisoned".into()))?;
        st.tick += 1;
        let tick = st.tick;
        let end = chunk.first_index + chunk.count;
        let at = match st.list.iter().position(|s| s.1 == chunk.first_index) {
            Some(i) => i,
            None if st.list.len() < MAX_STREAMS => {
                let (tx, rx) = bounded::<Request>(0);
                let (p, s, pcs, attrs) = (
                    self.path.clone(),
                    self.scans.clone(),
                    self.pcs.clone(),
                    self.attrs,
                );
                std::thread::Builder::new()
                    .name("e57".into())
                    .spawn(move || decode(&p, &s, &pcs, attrs, rx))
                    .map_err(|e| Error::io(&self.path, e))?;
                st.list.push((tx, u64::MAX, 0));
                st.list.len() - 1
            }
            None => (0..st.list.len())
                .min_by_key(|&i| st.list[i].2)
                .expect("MAX_STREAMS > 0"),
        };
        let s = &mut st.list[at];
        s.1 = end;
        s.2 = tick;
        Ok(s.0.clone())
    }
}

/// The decoding thread: serve `rx`'s chunks of `scans` (point clouds `pcs`, in order) from
/// the file at `path`, continuing the stream where a chunk follows the previous one.
fn decode(
    path: &Path,
    scans: &[Scan],
    pcs: &[e57::PointCloud],
    attrs: Attributes,
    rx: Receiver<Request>,
) {
    let mut reader = match e57::E57Reader::from_file(path) {
        Ok(r) => r,
        Err(e) => {
            let msg = bad(path, e).to_string();
            for r in rx {
                let _ = r.reply.send(Err(Error::input(path, msg.clone())));
            }
            return;
        }
    };
    let mut next = rx.recv().ok();
    while let Some(req) = next.take() {
        let Some(k) = scans.iter().rposition(|s| s.first <= req.chunk.first_index) else {
            let _ = req.reply.send(Err(Error::Internal(
                "E57 chunk before the first scan".into(),
            )));
            next = rx.recv().ok();
            continue;
        };
        let scan = &scans[k];
        let mut points = match reader.pointcloud_simple(&pcs[k]) {
            Ok(p) => p,
            Err(e) => {
                let _ = req.reply.send(Err(bad(path, e)));
                next = rx.recv().ok();
                continue;
            }
        };
        points.apply_pose(true);
        points.spherical_to_cartesian(true);
        points.intensity_to_color(false);
        points.normalize_intensity(false);
        points.normalize_color(true);
        // Index (among the reader's points) of the next point the stream gives.
        let mut at = scan.first;
        let mut req = req;
        loop {
            let mut out = Decoded::default();
            let mut failed = None;
            let end = req.chunk.first_index + req.chunk.count;
            while at < end {
                let Some(p) = points.next() else {
                    failed = Some(Error::input(
                        path,
                        format!(
                            "scan {} ends after {} of the {} points it declares",
                            scan.index,
                            at - scan.first,
                            scan.records
                        ),
                    ));
                    break;
                };
                let p = match p {
                    Ok(p) => p,
                    Err(e) => {
                        failed = Some(bad(path, e));
                        break;
                    }
                };
                let here = at;
                at += 1;
                if here < req.chunk.first_index {
                    continue;
                }
                let e57::CartesianCoordinate::Valid { x, y, z } = p.cartesian else {
                    out.invalid += 1;
                    continue;
                };
                out.pos.push([x, y, z]);
                if attrs.color {
                    let c = p.color.unwrap_or(e57::Color {
                        red: 0.5,
                        green: 0.5,
                        blue: 0.5,
                    });
                    let q = |v: f32| (v.clamp(0.0, 1.0) * 65535.0).round() as u16;
                    out.color.push([q(c.red), q(c.green), q(c.blue), u16::MAX]);
                }
                if attrs.intensity {
                    out.intensity.push(p.intensity.unwrap_or(0.0));
                }
            }
            let broke = failed.is_some();
            let _ = req.reply.send(match failed {
                Some(e) => Err(e),
                None => Ok(out),
            });
            match rx.recv() {
                Ok(r) if !broke && r.chunk.first_index == at && at < scan.first + scan.records => {
                    req = r;
                }
                Ok(r) => {
                    next = Some(r);
                    break;
                }
                Err(_) => return,
            }
        }
    }
}

impl PointReader for E57Reader {
    fn path(&self) -> &Path {
        &self.path
    }

    fn format(&self) -> Format {
        Format::E57
    }

    fn attributes(&self) -> Attributes {
        self.attrs
    }

    fn len(&self) -> u64 {
        self.len
    }

    fn chunks(&self, target_points: u64) -> Result<Vec<ChunkSpec>> {
        let target = target_points.max(1);
        let mut out = Vec::new();
        for s in &self.scans {
            let mut i = 0;
            while i < s.records {
                let n = target.min(s.records - i);
                out.push(ChunkSpec {
                    byte_start: 0,
                    byte_end: 0,
                    first_index: s.first + i,
                    count: n,
                    first_line: 0,
                });
                i += n;
            }
        }
        Ok(out)
    }

    fn read_chunk(
        &self,
        chunk: &ChunkSpec,
        _skip_invalid: bool,
        out: &mut PointBatch,
    ) -> Result<ChunkStats> {
        let (tx, rx) = bounded(1);
        self.stream_for(chunk)?
            .send(Request {
                chunk: *chunk,
                reply: tx,
            })
            .map_err(|_| Error::Internal("the E57 decoding thread stopped".into()))?;
        let d = rx
            .recv()
            .map_err(|_| Error::Internal("the E57 decoding thread stopped".into()))??;
        out.pos.extend_from_slice(&d.pos);
        out.color.extend_from_slice(&d.color);
        out.intensity.extend_from_slice(&d.intensity);
        Ok(ChunkStats {
            skipped_invalid: d.invalid,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_that_is_not_e57_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.e57");
        std::fs::write(&p, b"not an e57 file at all, just text").unwrap();
        let e = E57Reader::open(&p, None).unwrap_err().to_string();
        assert!(e.contains("x.e57") && e.contains("E57"), "{e}");
        let e = scan_inputs(&p).unwrap_err().to_string();
        assert!(e.contains("x.e57"), "{e}");
    }
}
