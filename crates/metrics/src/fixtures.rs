//! Test meshes shared by the metrics tests.

use std::path::Path;

use super::double_area;
use crate::geom::vec::{cross, dot, norm, sub};
use crate::io::mesh_read::Mesh;

pub(crate) fn mesh(vertices: &[[f64; 3]], triangles: &[[u32; 3]]) -> Mesh {
    Mesh {
        vertices: vertices.to_vec(),
        triangles: triangles.to_vec(),
    }
}

/// The octahedron with corners ±e_i, faces wound outward.
pub(crate) fn octahedron() -> Mesh {
    Mesh::octahedron()
}

pub(crate) fn signed_volume(m: &Mesh) -> f64 {
    m.triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| m.vertices[i as usize]);
            dot(a, cross(b, c)) / 6.0
        })
        .sum()
}
/// A UV sphere of radius 1 with `rings` latitude bands and `segments` longitudes, outward.
pub(crate) fn uv_sphere(rings: u32, segments: u32) -> Mesh {
    let mut v = vec![[0.0, 0.0, 1.0]];
    for i in 1..rings {
        let th = std::f64::consts::PI * i as f64 / rings as f64;
        for j in 0..segments {
            let ph = std::f64::consts::TAU * j as f64 / segments as f64;
            v.push([th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()]);
        }
    }
    v.push([0.0, 0.0, -1.0]);
    let south = v.len() as u32 - 1;
    let at = |i: u32, j: u32| 1 + (i - 1) * segments + j % segments;
    let mut t = Vec::new();
    for j in 0..segments {
        t.push([0, at(1, j), at(1, j + 1)]);
        for i in 1..rings - 1 {
            t.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            t.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
        t.push([south, at(rings - 1, j + 1), at(rings - 1, j)]);
    }
    mesh(&v, &t)
}

/// A square grid of `n × n` cells in the plane `z = z0`, side `side`.
pub(crate) fn grid(n: u32, side: f64, z0: f64) -> Mesh {
    let mut m = Mesh::default();
    for i in 0..=n {
        for j in 0..=n {
            m.vertices
                .push([side * i as f64 / n as f64, side * j as f64 / n as f64, z0]);
        }
    }
    let at = |i: u32, j: u32| i * (n + 1) + j;
    for i in 0..n {
        for j in 0..n {
            m.triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            m.triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    m
}

pub(crate) fn write_ascii_mesh(path: &Path, m: &Mesh) {
    let mut s = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty double x\nproperty double y\nproperty double z\nelement face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        m.vertices.len(),
        m.triangles.len()
    );
    for p in &m.vertices {
        s += &format!("{} {} {}\n", p[0], p[1], p[2]);
    }
    for t in &m.triangles {
        s += &format!("3 {} {} {}\n", t[0], t[1], t[2]);
    }
    std::fs::write(path, s).unwrap();
}

/// Largest gap between an inscribed triangle and the unit sphere: `1 - sqrt(1 - R²)`, `R`
/// the triangle's circumradius (its plane's distance to the centre is `sqrt(1 - R²)`).
pub(crate) fn chord_error(m: &Mesh) -> f64 {
    m.triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| m.vertices[i as usize]);
            let r = norm(sub(a, b)) * norm(sub(b, c)) * norm(sub(c, a))
                / (2.0 * double_area(&[a, b, c]));
            1.0 - (1.0 - r * r).sqrt()
        })
        .fold(0.0, f64::max)
}
