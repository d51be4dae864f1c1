//! Decoding vertex records of a chunk: binary records from a memory-mapped window, ascii
//! lines token by token.

use super::{Field, PlyReader, Scalar};
use crate::error::{Error, Location, Result};
use crate::fs::mmap::Window;
use crate::types::PointBatch;
use crate::{ChunkSpec, ChunkStats, invalid_point_msg};

impl PlyReader {
    pub(super) fn read_binary(
        &self,
        chunk: &ChunkSpec,
        skip_invalid: bool,
        out: &mut PointBatch,
    ) -> Result<ChunkStats> {
        let win = Window::map(&self.file, &self.path, chunk.byte_start, chunk.byte_end)?;
        let be = self.big_endian();
        let l = &self.layout;
        let fields = [l.xyz, l.normal].into_iter().flatten().flatten();
        let all_f32_le = !be
            && l.rgb.is_none()
            && fields
                .chain(l.intensity)
                .chain(l.confidence)
                .all(|f| f.ty == Scalar::F32);
        // The common case (every wanted field float32, little endian) gets its own
        // monomorphised loop without a type dispatch per value.
        if all_f32_le {
            self.decode_records(&win, chunk, skip_invalid, out, |rec: &[u8], f: Field| {
                let mut a = [0u8; 4];
                a.copy_from_slice(&rec[f.at..f.at + 4]);
                f32::from_le_bytes(a) as f64
            })
        } else {
            self.decode_records(&win, chunk, skip_invalid, out, |rec: &[u8], f: Field| {
                f.ty.read(&rec[f.at..], be)
            })
        }
    }

    #[inline(always)]
    fn decode_records(
        &self,
        win: &[u8],
        chunk: &ChunkSpec,
        skip_invalid: bool,
        out: &mut PointBatch,
        get: impl Fn(&[u8], Field) -> f64,
    ) -> Result<ChunkStats> {
        let l = &self.layout;
        let [fx, fy, fz] = l.xyz.unwrap_or(
            [Field {
                at: 0,
                ty: Scalar::F32,
            }; 3],
        );
        let mut stats = ChunkStats::default();
        let n = chunk.count as usize;
        out.pos.reserve(n);
        for (i, rec) in win.chunks_exact(self.stride).take(n).enumerate() {
            let p = [get(rec, fx), get(rec, fy), get(rec, fz)];
            let normal = l
                .normal
                .filter(|_| !self.ignore_normals)
                .map(|[a, b, c]| [get(rec, a), get(rec, b), get(rec, c)]);
            if let Some(msg) = invalid_point_msg(p, normal) {
                if skip_invalid {
                    stats.skipped_invalid += 1;
                    continue;
                }
                let index = chunk.first_index + i as u64;
                return Err(Error::format(
                    &self.path,
                    Location::Element {
                        index,
                        byte: self.vertex_start + index * self.stride as u64,
                    },
                    msg,
                ));
            }
            out.pos.push(p);
            self.push_attrs(out, |f: Field| get(rec, f));
        }
        Ok(stats)
    }

    #[inline(always)]
    fn push_attrs(&self, out: &mut PointBatch, get: impl Fn(Field) -> f64) {
        let l = &self.layout;
        if let Some([a, b, c]) = l.normal {
            out.normal
                .push([get(a) as f32, get(b) as f32, get(c) as f32]);
        }
        if let Some([r, g, b]) = l.rgb {
            let conv = |f: Field| {
                let v = get(f) / f.ty.full_scale() * 65535.0;
                v.round().clamp(0.0, 65535.0) as u16
            };
            let a = l.alpha.map(conv).unwrap_or(u16::MAX);
            out.color.push([conv(r), conv(g), conv(b), a]);
        }
        if let Some(f) = l.intensity {
            out.intensity.push(get(f) as f32);
        }
        if let Some(f) = l.confidence {
            out.confidence.push(get(f) as f32);
        }
    }

    pub(super) fn read_ascii(
        &self,
        chunk: &ChunkSpec,
        skip_invalid: bool,
        out: &mut PointBatch,
    ) -> Result<ChunkStats> {
        let win = Window::map(&self.file, &self.path, chunk.byte_start, chunk.byte_end)?;
        let mut stats = ChunkStats::default();
        let mut vals = vec![0f64; self.stride];
        let [fx, fy, fz] = self.layout.xyz.unwrap_or(
            [Field {
                at: 0,
                ty: Scalar::F32,
            }; 3],
        );
        let mut rest: &[u8] = &win;
        for i in 0..chunk.count {
            let line_no = chunk.first_line + i;
            let index = chunk.first_index + i;
            let (line, tail) = match rest.iter().position(|&b| b == b'\n') {
                Some(nl) => (&rest[..nl], &rest[nl + 1..]),
                None => (rest, &rest[rest.len()..]),
            };
            rest = tail;
            let text = std::str::from_utf8(line).map_err(|_| {
                Error::format(
                    &self.path,
                    Location::Line(line_no),
                    "vertex line is not text",
                )
            })?;
            let mut n = 0usize;
            for tok in text.split_ascii_whitespace() {
                if n == self.stride {
                    n += 1;
                    break;
                }
                vals[n] = tok.parse::<f64>().map_err(|_| {
                    Error::format(
                        &self.path,
                        Location::ElementLine {
                            index,
                            line: line_no,
                        },
                        format!("value {} \"{}\" is not a number", n + 1, tok),
                    )
                })?;
                n += 1;
            }
            if n != self.stride {
                return Err(Error::format(
                    &self.path,
                    Location::ElementLine {
                        index,
                        line: line_no,
                    },
                    format!(
                        "expected {} values per vertex line as the header declares, found {}",
                        self.stride,
                        if n > self.stride {
                            "more".to_string()
                        } else {
                            n.to_string()
                        }
                    ),
                ));
            }
            let p = [vals[fx.at], vals[fy.at], vals[fz.at]];
            let normal = self
                .layout
                .normal
                .filter(|_| !self.ignore_normals)
                .map(|[a, b, c]| [vals[a.at], vals[b.at], vals[c.at]]);
            if let Some(msg) = invalid_point_msg(p, normal) {
                if skip_invalid {
                    stats.skipped_invalid += 1;
                    continue;
                }
                return Err(Error::format(
                    &self.path,
                    Location::ElementLine {
                        index,
                        line: line_no,
                    },
                    msg,
                ));
            }
            out.pos.push(p);
            self.push_attrs(out, |f: Field| vals[f.at]);
        }
        Ok(stats)
    }
}
