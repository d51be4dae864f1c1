//! A picture of a mesh, drawn as it streams: a small software rasteriser (z-buffer) with
//! three orthographic views side by side, for `--preview OUT.png` and the run report.
//!
//! The triangles are drawn as the writer receives them, so the picture costs no second read
//! of the mesh and memory independent of its size: three `S × S` views of a depth (f32) and a
//! colour (RGB) per pixel. The views look at the centre of the input's bounding box from the
//! front (along +y: x right, z up), from the side (along −x: y right, z up) and from above
//! at an angle (along (−1, 1, −1)/√3, an isometric view); each fits the box's bounding sphere
//! into its square with a margin ([`MARGIN`]), so one scale holds for every view: a unit of
//! length is `(1 − 2·MARGIN)·S / diagonal` pixels.
//!
//! **Shading.** A triangle's colour is the mean of its corners' colours (light grey where the
//! mesh has none), times `AMBIENT + (1 − AMBIENT)·|n·v|` for its unit normal `n` and the view
//! direction `v`; faces seen from behind (an open surface's inside) are tinted blue, so holes
//! show. **Coverage**: a pixel is covered when its centre lies inside the projected triangle
//! (closed edges); where triangles overlap the nearest wins, and of equal depths the first
//! drawn, so the picture depends only on the triangles' order, which the writer fixes.

use std::path::Path;

use crate::error::Result;
use crate::fs::atomic::{self, Durability};
use crate::geom::vec::{cross, dot, norm, sub};
use crate::types::Aabb;

/// Share of each view's side left empty on either edge.
pub const MARGIN: f64 = 0.04;

/// Light that reaches faces turned away from the view.
const AMBIENT: f64 = 0.25;

/// Background colour.
const BACKGROUND: [u8; 3] = [255, 255, 255];

/// Colour of a mesh without vertex colours.
const SURFACE: [f64; 3] = [205.0, 205.0, 200.0];

/// Tint of faces seen from behind.
const BACK: [f64; 3] = [90.0, 120.0, 200.0];

/// The views: (right, up, forward) unit vectors; forward points away from the viewer.
fn views() -> [[[f64; 3]; 3]; 3] {
    let s2 = std::f64::consts::FRAC_1_SQRT_2;
    let s3 = 1.0 / 3f64.sqrt();
    let s6 = 1.0 / 6f64.sqrt();
    [
        // Front: looking along +y.
        [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]],
        // Side: looking along -x.
        [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]],
        // Isometric from (+x, -y, +z): looking along (-1, 1, -1)/sqrt 3.
        [[s2, s2, 0.0], [-s6, s6, 2.0 * s6], [-s3, s3, -s3]],
    ]
}

/// The three views of a mesh being drawn.
#[derive(Debug, Clone)]
pub struct Preview {
    side: usize,
    centre: [f64; 3],
    /// Pixels per unit of length.
    scale: f64,
    /// Per view, per pixel: depth (+inf: empty).
    depth: Vec<Vec<f32>>,
    /// Per view, per pixel: colour.
    color: Vec<Vec<[u8; 3]>>,
    triangles: u64,
}

impl Preview {
    /// Empty views of `side × side` pixels each, framing `bounds`.
    pub fn new(bounds: &Aabb, side: usize) -> Preview {
        let side = side.max(8);
        let centre = [0, 1, 2].map(|a| 0.5 * (bounds.min[a] + bounds.max[a]));
        let diag = bounds.diagonal();
        let diag = if diag > 0.0 && diag.is_finite() {
            diag
        } else {
            1.0
        };
        Preview {
            side,
            centre,
            scale: (1.0 - 2.0 * MARGIN) * side as f64 / diag,
            depth: vec![vec![f32::INFINITY; side * side]; 3],
            color: vec![vec![BACKGROUND; side * side]; 3],
            triangles: 0,
        }
    }

    /// Pixels per unit of length, in every view.
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// Each view's side in pixels.
    pub fn side(&self) -> usize {
        self.side
    }

    /// Triangles drawn.
    pub fn triangles(&self) -> u64 {
        self.triangles
    }

    /// Pixels covered in view `v` (0 front, 1 side, 2 isometric).
    pub fn coverage(&self, v: usize) -> usize {
        self.depth[v].iter().filter(|d| d.is_finite()).count()
    }

    /// Draw triangle `p` (counter-clockwise seen from its front), its corners coloured
    /// `colors` where the mesh has colours.
    pub fn triangle(&mut self, p: [[f64; 3]; 3], colors: Option<[[u8; 3]; 3]>) {
        self.triangles += 1;
        let n = cross(sub(p[1], p[0]), sub(p[2], p[0]));
        let len = norm(n);
        if !(len > 0.0 && len.is_finite()) {
            return;
        }
        let n = n.map(|x| x / len);
        let base = match colors {
            Some(c) => [0, 1, 2].map(|k| (c[0][k] as f64 + c[1][k] as f64 + c[2][k] as f64) / 3.0),
            None => SURFACE,
        };
        for (v, [right, up, fwd]) in views().into_iter().enumerate() {
            let facing = -dot(n, fwd);
            let light = AMBIENT + (1.0 - AMBIENT) * facing.abs();
            let rgb = if facing >= 0.0 {
                base.map(|c| (c * light).round().clamp(0.0, 255.0) as u8)
            } else {
                BACK.map(|c| (c * light).round().clamp(0.0, 255.0) as u8)
            };
            let half = self.side as f64 / 2.0;
            let q = p.map(|x| {
                let d = [0, 1, 2].map(|a| x[a] - self.centre[a]);
                [
                    half + dot(d, right) * self.scale,
                    half - dot(d, up) * self.scale,
                    dot(d, fwd),
                ]
            });
            self.fill(v, q, rgb);
        }
    }

    /// Fill the pixels of view `v` whose centres lie in the screen triangle `q` (x, y,
    /// depth), where it is nearer than what is there.
    fn fill(&mut self, v: usize, q: [[f64; 3]; 3], rgb: [u8; 3]) {
        let side = self.side as f64;
        let lo = |a: usize| q.iter().map(|x| x[a]).fold(f64::INFINITY, f64::min);
        let hi = |a: usize| q.iter().map(|x| x[a]).fold(f64::NEG_INFINITY, f64::max);
        let x0 = (lo(0) - 0.5).ceil().max(0.0);
        let x1 = (hi(0) - 0.5).floor().min(side - 1.0);
        let y0 = (lo(1) - 0.5).ceil().max(0.0);
        let y1 = (hi(1) - 0.5).floor().min(side - 1.0);
        if !(x0 <= x1 && y0 <= y1) {
            return;
        }
        let area =
            (q[1][0] - q[0][0]) * (q[2][1] - q[0][1]) - (q[2][0] - q[0][0]) * (q[1][1] - q[0][1]);
        if area == 0.0 || !area.is_finite() {
            return;
        }
        let edge = |a: [f64; 3], b: [f64; 3], x: f64, y: f64| {
            (b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0])
        };
        let side = self.side;
        for y in y0 as usize..=y1 as usize {
            let cy = y as f64 + 0.5;
            for x in x0 as usize..=x1 as usize {
                let cx = x as f64 + 0.5;
                // Barycentric weights, positive inside for either winding.
                let w0 = edge(q[1], q[2], cx, cy) / area;
                let w1 = edge(q[2], q[0], cx, cy) / area;
                let w2 = edge(q[0], q[1], cx, cy) / area;
                if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                    continue;
                }
                let z = (w0 * q[0][2] + w1 * q[1][2] + w2 * q[2][2]) as f32;
                let i = y * side + x;
                if z < self.depth[v][i] {
                    self.depth[v][i] = z;
                    self.color[v][i] = rgb;
                }
            }
        }
    }

    /// The picture: the three views side by side (`3·side × side` RGB pixels, row-major).
    pub fn pixels(&self) -> (usize, usize, Vec<u8>) {
        let (s, w) = (self.side, 3 * self.side);
        let mut px = Vec::with_capacity(w * s * 3);
        for y in 0..s {
            for v in 0..3 {
                for x in 0..s {
                    px.extend_from_slice(&self.color[v][y * s + x]);
                }
            }
        }
        (w, s, px)
    }

    /// The picture as PNG bytes.
    pub fn png(&self) -> Vec<u8> {
        let (w, h, px) = self.pixels();
        let mut out = Vec::new();
        {
            let mut e = png::Encoder::new(&mut out, w as u32, h as u32);
            e.set_color(png::ColorType::Rgb);
            e.set_depth(png::BitDepth::Eight);
            e.add_text_chunk("Software".into(), "scanflow".into()).ok();
            e.add_text_chunk(
                "Comment".into(),
                format!(
                    "front, side and isometric views; {} pixels per unit",
                    self.scale
                ),
            )
            .ok();
            if let Ok(mut wr) = e.write_header() {
                let _ = wr.write_image_data(&px);
            }
        }
        out
    }

    /// Write the picture to `path` as PNG (atomically).
    pub fn write_png(&self, path: &Path) -> Result<()> {
        atomic::write(path, &self.png(), Durability::Synced)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The octahedron with corners ±e_i, as outward triangles.
    fn octahedron() -> Vec<[[f64; 3]; 3]> {
        let m = crate::mesh::Mesh::octahedron();
        m.triangles
            .iter()
            .map(|t| t.map(|i| m.vertices[i as usize]))
            .collect()
    }

    #[test]
    fn every_view_is_an_orthonormal_right_handed_frame() {
        for (v, [r, u, f]) in views().into_iter().enumerate() {
            for (a, b) in [(r, u), (u, f), (f, r)] {
                assert!(dot(a, b).abs() < 1e-12, "view {v}");
            }
            for a in [r, u, f] {
                assert!((dot(a, a) - 1.0).abs() < 1e-12, "view {v}");
            }
            // right × up points at the viewer (against forward).
            let c = cross(r, u);
            assert!((dot(c, f) + 1.0).abs() < 1e-12, "view {v}");
            // Up has no downward part: z never points down the picture.
            assert!(u[2] > 0.0, "view {v}");
        }
    }

    #[test]
    fn silhouettes_have_the_projected_area() {
        let b = Aabb {
            min: [-1.0; 3],
            max: [1.0; 3],
        };
        let mut p = Preview::new(&b, 400);
        for t in octahedron() {
            p.triangle(t, None);
        }
        // Front and side: a square of diagonal 2 (area 2).
        let px = p.scale() * p.scale();
        for v in 0..2 {
            let want = 2.0 * px;
            let got = p.coverage(v) as f64;
            assert!((got / want - 1.0).abs() < 0.02, "view {v}: {got} vs {want}");
        }
        // Along (1,1,1)/sqrt 3 the octahedron projects to a regular hexagon of
        // circumradius sqrt(2/3): area (3 sqrt 3 / 2) · 2/3 = sqrt 3.
        let want = 3f64.sqrt() * px;
        let got = p.coverage(2) as f64;
        assert!(
            (got / want - 1.0).abs() < 0.02,
            "isometric: {got} vs {want}"
        );
        // Outward faces only: no back tint in the picture.
        let (w, h, px) = p.pixels();
        assert_eq!((w, h), (1200, 400));
        assert!(
            px.chunks(3)
                .all(|c| c != [BACK[0] as u8, BACK[1] as u8, BACK[2] as u8])
        );
        let png = p.png();
        assert_eq!(&png[1..4], b"PNG");
    }

    #[test]
    fn nearer_faces_hide_farther_ones_in_any_order_of_equal_depth_ties() {
        let b = Aabb {
            min: [-1.0; 3],
            max: [1.0; 3],
        };
        // Two parallel squares facing the front view (normal -y), the nearer red.
        let quad = |y: f64| {
            [
                [[-0.5, y, -0.5], [0.5, y, -0.5], [0.5, y, 0.5]],
                [[-0.5, y, -0.5], [0.5, y, 0.5], [-0.5, y, 0.5]],
            ]
        };
        let red = Some([[255, 0, 0]; 3]);
        let green = Some([[0, 255, 0]; 3]);
        let mut a = Preview::new(&b, 64);
        let mut c = Preview::new(&b, 64);
        for t in quad(-0.5) {
            a.triangle(t, red);
        }
        for t in quad(0.5) {
            a.triangle(t, green);
            c.triangle(t, green);
        }
        for t in quad(-0.5) {
            c.triangle(t, red);
        }
        assert_eq!(a.pixels(), c.pixels());
        let (w, _, px) = a.pixels();
        let mid = (32 * w + 32) * 3;
        assert!(px[mid] > 0 && px[mid + 1] == 0, "{:?}", &px[mid..mid + 3]);
    }
}
