//! The Wavefront OBJ encoder: `v` lines (with colour in [0, 1]), `vn` lines with normals,
//! then 1-based `f` lines, as documented in [`super`].

use std::io::Write;

use super::MeshWriter;
use super::text::num;
use crate::error::{IoContext, Result};

impl MeshWriter {
    pub(super) fn write_obj(&mut self, w: &mut impl Write) -> Result<()> {
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
}
