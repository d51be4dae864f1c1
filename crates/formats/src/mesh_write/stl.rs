//! The binary STL encoder: an 80-byte header, the triangle count, then per triangle its unit
//! normal, its corners looked up in the mapped staged vertices, and a zero attribute.

use std::io::Write;

use super::MeshWriter;
use super::staging::{STAGE_BYTES, Staged};
use crate::error::{Error, IoContext, Result};
use crate::geom::vec::{cross, norm, sub};

/// Bytes of a binary STL's header, and of one of its triangles.
pub(super) const STL_HEADER: usize = 80;
pub(super) const STL_TRIANGLE: u64 = 50;

/// The unit normal of triangle `p` (counter-clockwise seen from its front), zero where it has
/// no area.
pub(super) fn unit_normal(p: [[f32; 3]; 3]) -> [f32; 3] {
    let p = p.map(|c| c.map(f64::from));
    let c = cross(sub(p[1], p[0]), sub(p[2], p[0]));
    let len = norm(c);
    if len > 0.0 && len.is_finite() {
        c.map(|x| (x / len) as f32)
    } else {
        [0.0; 3]
    }
}

impl MeshWriter {
    pub(super) fn write_stl(&mut self, w: &mut impl Write) -> Result<()> {
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
