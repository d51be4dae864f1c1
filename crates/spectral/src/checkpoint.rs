//! A cell's patches as bytes: pass 1's checkpoint, read back by pass 2 and by a resumed run.
//!
//! Layout (little-endian): the magic `SFPATCH1`, the patch count (u32), then per patch its
//! frame (origin, axes, core rectangle, box, height range, admission cosine: 23 f64), grid
//! (`nu`, `nv` u32; `lo` 2 f64; `step` f64), counts (`members`, `admitted` u32), measures
//! (aperture, SDA RMS, Parseval RMS, noise RMS, rate: 5 f32), then `nu·nv` heights and as
//! many weights (f32); the file ends with the CRC-32 of everything before it.

use super::patch::{Frame, Patch};

/// First bytes of a patch file.
pub const MAGIC: &[u8; 8] = b"SFPATCH1";

/// Encode patches.
pub fn encode(patches: &[Patch]) -> Vec<u8> {
    let nodes: usize = patches.iter().map(|p| p.h.len()).sum();
    let mut b = Vec::with_capacity(12 + patches.len() * 240 + nodes * 8 + 4);
    b.extend_from_slice(MAGIC);
    b.extend_from_slice(&(patches.len() as u32).to_le_bytes());
    for p in patches {
        let f = &p.frame;
        let mut d: Vec<f64> = Vec::with_capacity(26);
        d.extend(f.origin);
        for a in &f.axes {
            d.extend(a);
        }
        d.extend(f.core);
        d.extend(f.bx);
        d.extend(f.hrange);
        d.push(f.cos_admit);
        d.extend(p.lo);
        d.push(p.step);
        for x in d {
            b.extend_from_slice(&x.to_le_bytes());
        }
        for x in [p.nu, p.nv, p.members, p.admitted] {
            b.extend_from_slice(&x.to_le_bytes());
        }
        for x in [p.aperture, p.sda_rms, p.parseval_rms, p.noise_rms, p.rate] {
            b.extend_from_slice(&x.to_le_bytes());
        }
        for x in p.h.iter().chain(&p.w) {
            b.extend_from_slice(&x.to_le_bytes());
        }
    }
    let crc = crc32fast::hash(&b);
    b.extend_from_slice(&crc.to_le_bytes());
    b
}

/// Decode patches; `Err` names what is wrong (the caller adds the file).
pub fn decode(b: &[u8]) -> Result<Vec<Patch>, String> {
    if b.len() < 16 || &b[..8] != MAGIC {
        return Err("not a scanflow patch file (no SFPATCH1 header)".into());
    }
    let (body, tail) = b.split_at(b.len() - 4);
    let crc = u32::from_le_bytes([tail[0], tail[1], tail[2], tail[3]]);
    if crc32fast::hash(body) != crc {
        return Err("checksum mismatch: the file is damaged".into());
    }
    let mut r = Reader { b: body, at: 8 };
    let n = r.u32()? as usize;
    let mut out = Vec::with_capacity(n.min(1 << 20));
    for _ in 0..n {
        let mut d = [0f64; 26];
        for x in &mut d {
            *x = r.f64()?;
        }
        let frame = Frame {
            origin: [d[0], d[1], d[2]],
            axes: [[d[3], d[4], d[5]], [d[6], d[7], d[8]], [d[9], d[10], d[11]]],
            core: [d[12], d[13], d[14], d[15]],
            bx: [d[16], d[17], d[18], d[19]],
            hrange: [d[20], d[21]],
            cos_admit: d[22],
        };
        let (nu, nv, members, admitted) = (r.u32()?, r.u32()?, r.u32()?, r.u32()?);
        let mut m = [0f32; 5];
        for x in &mut m {
            *x = r.f32()?;
        }
        let nodes = nu as usize * nv as usize;
        if nu < 2 || nv < 2 || nodes * 8 > r.b.len() - r.at {
            return Err(format!("patch grid {nu}×{nv} does not fit the file"));
        }
        let h = (0..nodes)
            .map(|_| r.f32())
            .collect::<Result<Vec<f32>, String>>()?;
        let w = (0..nodes)
            .map(|_| r.f32())
            .collect::<Result<Vec<f32>, String>>()?;
        out.push(Patch {
            frame,
            nu,
            nv,
            lo: [d[23], d[24]],
            step: d[25],
            h,
            w,
            members,
            admitted,
            aperture: m[0],
            sda_rms: m[1],
            parseval_rms: m[2],
            noise_rms: m[3],
            rate: m[4],
        });
    }
    if r.at != r.b.len() {
        return Err(format!("{} bytes after the last patch", r.b.len() - r.at));
    }
    Ok(out)
}

struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N], String> {
        let s = self
            .b
            .get(self.at..self.at + N)
            .ok_or_else(|| format!("truncated at byte {}", self.at))?;
        self.at += N;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        Ok(a)
    }
    fn u32(&mut self) -> Result<u32, String> {
        self.take::<4>().map(u32::from_le_bytes)
    }
    fn f32(&mut self) -> Result<f32, String> {
        self.take::<4>().map(f32::from_le_bytes)
    }
    fn f64(&mut self) -> Result<f64, String> {
        self.take::<8>().map(f64::from_le_bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::patch::Frame;

    fn patch(k: u32) -> Patch {
        let nodes = (k as usize + 2) * 3;
        Patch {
            frame: Frame {
                origin: [1.0, 2.0, 3.0 + k as f64],
                axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                core: [-1.0, -2.0, 1.0, 2.0],
                bx: [-1.2, -2.4, 1.2, 2.4],
                hrange: [-0.3, 0.4],
                cos_admit: 0.5,
            },
            nu: k + 2,
            nv: 3,
            lo: [-1.2, -2.4],
            step: 0.125,
            h: (0..nodes).map(|i| i as f32 * 0.5).collect(),
            w: (0..nodes).map(|i| 1.0 / (i + 1) as f32).collect(),
            members: 40 + k,
            admitted: 50 + k,
            aperture: 0.25,
            sda_rms: 1e-3,
            parseval_rms: 2e-3,
            noise_rms: 3e-3,
            rate: 17.0,
        }
    }

    #[test]
    fn patches_round_trip_and_damage_is_refused() {
        let ps: Vec<Patch> = (0..3).map(patch).collect();
        let b = encode(&ps);
        assert_eq!(decode(&b).unwrap(), ps);
        assert_eq!(decode(&encode(&[])).unwrap(), Vec::<Patch>::new());
        let mut bad = b.clone();
        bad[40] ^= 1;
        assert!(decode(&bad).unwrap_err().contains("checksum"));
        assert!(decode(&b[..b.len() - 9]).is_err());
        assert!(
            decode(b"SFLEAF03xxxxxxxxxxx")
                .unwrap_err()
                .contains("SFPATCH1")
        );
    }
}
