//! Cell files: fixed-width little-endian records, written as a sequence of zstd frames.
//!
//! A record holds, in this order and only for the attributes the store carries:
//!
//! | field | type | bytes |
//! | --- | --- | --- |
//! | x y z | f64 ×3, or f32 ×3 where every input coordinate is a float32 | 24 or 12 |
//! | nx ny nz | f32 ×3 | 12 |
//! | red green blue | u16 ×3 | 6 |
//! | alpha | u16 | 2 |
//! | intensity | f32 | 4 |
//! | confidence | f32 | 4 |
//! | scan | u16 (the input's index, while normals are estimated from viewpoints) | 2 |
//!
//! No padding. A cell file is the concatenation of independent zstd frames (one per flush),
//! which decodes as one stream of records.

use std::io::Read;
use std::path::Path;

use crate::error::{Error, IoContext, Result};
use crate::fs::atomic::{self, Durability};
use crate::types::{Aabb, Attributes, PointBatch};

/// Record layout for an attribute set.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RecordLayout {
    /// Attributes carried.
    pub attrs: Attributes,
    /// Positions stored as f32 (exact: every input coordinate was a float32).
    pub pos_f32: bool,
    /// Bytes per record.
    pub stride: usize,
}

impl RecordLayout {
    /// The layout for `attrs`, with f32 positions when `pos_f32`.
    pub fn new(attrs: Attributes, pos_f32: bool) -> RecordLayout {
        // Field sizes as in the table of the module docs.
        let mut stride = if pos_f32 { 3 * 4 } else { 3 * 8 };
        if attrs.normal {
            stride += 3 * 4;
        }
        if attrs.color {
            stride += 3 * 2;
            if attrs.alpha {
                stride += 2;
            }
        }
        if attrs.intensity {
            stride += 4;
        }
        if attrs.confidence {
            stride += 4;
        }
        if attrs.source {
            stride += 2;
        }
        RecordLayout {
            attrs,
            pos_f32,
            stride,
        }
    }

    /// The same layout with normals.
    pub fn with_normals(&self) -> RecordLayout {
        RecordLayout::new(
            Attributes {
                normal: true,
                ..self.attrs
            },
            self.pos_f32,
        )
    }

    /// Append point `i` of `b` to `out`.
    #[inline]
    pub fn encode(&self, b: &PointBatch, i: usize, out: &mut Vec<u8>) {
        let at = out.len();
        out.resize(at + self.stride, 0);
        self.encode_into(b, i, &mut out[at..]);
    }

    /// Write point `i` of `b` into `r` (exactly one record long).
    #[inline(always)]
    pub fn encode_into(&self, b: &PointBatch, i: usize, r: &mut [u8]) {
        let p = b.pos[i];
        let mut o = if self.pos_f32 {
            r[0..4].copy_from_slice(&(p[0] as f32).to_le_bytes());
            r[4..8].copy_from_slice(&(p[1] as f32).to_le_bytes());
            r[8..12].copy_from_slice(&(p[2] as f32).to_le_bytes());
            12
        } else {
            r[0..8].copy_from_slice(&p[0].to_le_bytes());
            r[8..16].copy_from_slice(&p[1].to_le_bytes());
            r[16..24].copy_from_slice(&p[2].to_le_bytes());
            24
        };
        let a = self.attrs;
        if a.normal {
            let n = b.normal[i];
            r[o..o + 4].copy_from_slice(&n[0].to_le_bytes());
            r[o + 4..o + 8].copy_from_slice(&n[1].to_le_bytes());
            r[o + 8..o + 12].copy_from_slice(&n[2].to_le_bytes());
            o += 12;
        }
        if a.color {
            let c = b.color[i];
            r[o..o + 2].copy_from_slice(&c[0].to_le_bytes());
            r[o + 2..o + 4].copy_from_slice(&c[1].to_le_bytes());
            r[o + 4..o + 6].copy_from_slice(&c[2].to_le_bytes());
            o += 6;
            if a.alpha {
                r[o..o + 2].copy_from_slice(&c[3].to_le_bytes());
                o += 2;
            }
        }
        if a.intensity {
            r[o..o + 4].copy_from_slice(&b.intensity[i].to_le_bytes());
            o += 4;
        }
        if a.confidence {
            r[o..o + 4].copy_from_slice(&b.confidence[i].to_le_bytes());
            o += 4;
        }
        if a.source {
            r[o..o + 2].copy_from_slice(&b.source[i].to_le_bytes());
        }
    }

    /// Decode whole records from `bytes` (a multiple of the stride) into `out`.
    pub fn decode(&self, bytes: &[u8], out: &mut PointBatch) {
        let f64_at = |r: &[u8], o: usize| f64::from_le_bytes(arr(&r[o..o + 8]));
        let f32_at = |r: &[u8], o: usize| f32::from_le_bytes(arr(&r[o..o + 4]));
        let u16_at = |r: &[u8], o: usize| u16::from_le_bytes(arr(&r[o..o + 2]));
        let a = self.attrs;
        for r in bytes.chunks_exact(self.stride) {
            let mut o = if self.pos_f32 {
                out.pos.push([
                    f32_at(r, 0) as f64,
                    f32_at(r, 4) as f64,
                    f32_at(r, 8) as f64,
                ]);
                12
            } else {
                out.pos.push([f64_at(r, 0), f64_at(r, 8), f64_at(r, 16)]);
                24
            };
            if a.normal {
                out.normal
                    .push([f32_at(r, o), f32_at(r, o + 4), f32_at(r, o + 8)]);
                o += 12;
            }
            if a.color {
                let mut c = [u16_at(r, o), u16_at(r, o + 2), u16_at(r, o + 4), u16::MAX];
                o += 6;
                if a.alpha {
                    c[3] = u16_at(r, o);
                    o += 2;
                }
                out.color.push(c);
            }
            if a.intensity {
                out.intensity.push(f32_at(r, o));
                o += 4;
            }
            if a.confidence {
                out.confidence.push(f32_at(r, o));
                o += 4;
            }
            if a.source {
                out.source.push(u16_at(r, o));
            }
        }
    }
}

#[inline(always)]
fn arr<const N: usize>(s: &[u8]) -> [u8; N] {
    let mut a = [0u8; N];
    a.copy_from_slice(s);
    a
}

/// Records decoded per read of a whole cell file: 64 Ki records, a few MiB of buffer.
const READ_RECORDS: usize = 1 << 16;

/// Read every record of the cell file at `path`, checking its record count and CRC-32.
pub fn read_cell_file(
    path: &Path,
    layout: RecordLayout,
    count: u64,
    crc32: u32,
) -> Result<PointBatch> {
    let mut rd = CellReader::open(path, layout)?;
    let mut out = PointBatch::default();
    let mut buf = Vec::new();
    while rd.read(READ_RECORDS, &mut out, &mut buf)? > 0 {
        if out.len() as u64 > count {
            break;
        }
    }
    if out.len() as u64 != count {
        return Err(Error::input(
            path,
            format!(
                "corrupt cell file: the manifest lists {} points, the file holds {}",
                count,
                out.len()
            ),
        ));
    }
    let crc = rd.finish_crc();
    if crc != crc32 {
        return Err(Error::input(
            path,
            format!("corrupt cell file: CRC-32 {crc:08x}, the manifest says {crc32:08x}"),
        ));
    }
    Ok(out)
}

/// Write `b` as a whole cell file at `path` (one zstd frame, through a temporary name, not
/// synced: see [`Durability::Renamed`]); returns the compressed size and its CRC-32.
pub fn write_cell_file(
    path: &Path,
    layout: RecordLayout,
    b: &PointBatch,
    zstd_level: i32,
) -> Result<(u64, u32)> {
    let mut raw = Vec::with_capacity(b.len() * layout.stride);
    for i in 0..b.len() {
        layout.encode(b, i, &mut raw);
    }
    let z = zstd::bulk::compress(&raw, zstd_level)
        .map_err(|e| Error::Internal(format!("zstd compression failed: {e}")))?;
    // Inside the store's temporary directory, which is committed as a whole.
    atomic::write(path, &z, Durability::Renamed)?;
    Ok((z.len() as u64, crc32fast::hash(&z)))
}

/// Streaming reader of a cell file's records, with a running CRC-32 of the compressed bytes.
pub struct CellReader<'a> {
    path: &'a Path,
    layout: RecordLayout,
    dec: zstd::stream::read::Decoder<'static, std::io::BufReader<CrcRead<std::fs::File>>>,
    records_read: u64,
}

/// A reader that hashes what passes through it.
pub struct CrcRead<R> {
    inner: R,
    crc: crc32fast::Hasher,
}

impl<R: Read> Read for CrcRead<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.crc.update(&buf[..n]);
        Ok(n)
    }
}

impl<'a> CellReader<'a> {
    /// Open a cell file.
    pub fn open(path: &'a Path, layout: RecordLayout) -> Result<CellReader<'a>> {
        let f = std::fs::File::open(path).with_path(path)?;
        let dec = zstd::stream::read::Decoder::new(CrcRead {
            inner: f,
            crc: crc32fast::Hasher::new(),
        })
        .with_path(path)?;
        Ok(CellReader {
            path,
            layout,
            dec,
            records_read: 0,
        })
    }

    /// Read up to `max` records into `out`; returns how many were read (0 at the end).
    pub fn read(&mut self, max: usize, out: &mut PointBatch, buf: &mut Vec<u8>) -> Result<usize> {
        let stride = self.layout.stride;
        buf.resize(max * stride, 0);
        let mut filled = 0;
        while filled < buf.len() {
            let n = self.dec.read(&mut buf[filled..]).map_err(|e| {
                Error::input(
                    self.path,
                    format!(
                        "corrupt cell file: decompression failed at record {} ({e})",
                        self.records_read + (filled / stride) as u64
                    ),
                )
            })?;
            if n == 0 {
                break;
            }
            filled += n;
        }
        if filled % stride != 0 {
            return Err(Error::input(
                self.path,
                format!(
                    "corrupt cell file: it ends inside record {} ({} bytes past the last whole record of {} bytes)",
                    self.records_read + (filled / stride) as u64,
                    filled % stride,
                    stride
                ),
            ));
        }
        self.layout.decode(&buf[..filled], out);
        let n = filled / stride;
        self.records_read += n as u64;
        Ok(n)
    }

    /// Records read so far.
    pub fn records_read(&self) -> u64 {
        self.records_read
    }

    /// The CRC-32 of every compressed byte read; valid once `read` returned 0.
    pub fn finish_crc(self) -> u32 {
        self.dec.finish().into_inner().crc.finalize()
    }
}

/// The bounds of a batch's positions.
pub fn batch_bounds(b: &PointBatch) -> Aabb {
    let mut a = Aabb::EMPTY;
    for p in &b.pos {
        a.add(*p);
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encode_decode_round_trip() {
        for attrs in [
            Attributes::default(),
            Attributes {
                normal: true,
                color: true,
                alpha: true,
                intensity: true,
                confidence: true,
                source: true,
            },
            Attributes {
                color: true,
                intensity: true,
                ..Default::default()
            },
        ] {
            let l = RecordLayout::new(attrs, attrs.normal);
            let mut b = PointBatch::default();
            for i in 0..5 {
                let big = if l.pos_f32 { 2f64.powi(100) } else { 1e300 };
                b.pos.push([i as f64, -1.5 * i as f64, big]);
                if attrs.normal {
                    b.normal.push([0.0, 1.0, i as f32]);
                }
                if attrs.color {
                    b.color
                        .push([i, 2 * i, 3 * i, if attrs.alpha { 7 } else { u16::MAX }]);
                }
                if attrs.intensity {
                    b.intensity.push(i as f32 * 0.5);
                }
                if attrs.confidence {
                    b.confidence.push(0.25);
                }
                if attrs.source {
                    b.source.push(900 + i);
                }
            }
            let mut bytes = Vec::new();
            for i in 0..5 {
                l.encode(&b, i, &mut bytes);
            }
            assert_eq!(bytes.len(), 5 * l.stride);
            let mut d = PointBatch::default();
            l.decode(&bytes, &mut d);
            assert_eq!(d, b);
        }
    }
}
