//! The data that flows between stages.
//!
//! World coordinates are `f64` in the input's units. Normals are `f32` unit vectors in the
//! same frame. Colours are 16-bit per channel (8-bit inputs are scaled by 257, so 255 maps
//! to 65535 exactly).

use serde::{Deserialize, Serialize};

/// An axis-aligned bounding box in world coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Aabb {
    /// Lower corner.
    pub min: [f64; 3],
    /// Upper corner.
    pub max: [f64; 3],
}

impl Aabb {
    /// The empty box: `min = +inf`, `max = -inf`, the identity of [`Aabb::union`].
    pub const EMPTY: Aabb = Aabb {
        min: [f64::INFINITY; 3],
        max: [f64::NEG_INFINITY; 3],
    };

    /// True when no point was added.
    pub fn is_empty(&self) -> bool {
        (0..3).any(|i| self.min[i] > self.max[i])
    }

    /// Grow to contain `p`.
    #[inline]
    pub fn add(&mut self, p: [f64; 3]) {
        for i in 0..3 {
            self.min[i] = self.min[i].min(p[i]);
            self.max[i] = self.max[i].max(p[i]);
        }
    }

    /// The smallest box holding both.
    pub fn union(&self, o: &Aabb) -> Aabb {
        let mut r = *self;
        for i in 0..3 {
            r.min[i] = r.min[i].min(o.min[i]);
            r.max[i] = r.max[i].max(o.max[i]);
        }
        r
    }

    /// The box enlarged by `h` on every side.
    pub fn grown(&self, h: f64) -> Aabb {
        Aabb {
            min: self.min.map(|v| v - h),
            max: self.max.map(|v| v + h),
        }
    }

    /// True when `p` lies in the box (faces included).
    #[inline]
    pub fn contains(&self, p: [f64; 3]) -> bool {
        (0..3).all(|i| p[i] >= self.min[i] && p[i] <= self.max[i])
    }

    /// True when the two boxes share a point.
    pub fn meets(&self, o: &Aabb) -> bool {
        (0..3).all(|i| self.min[i] <= o.max[i] && o.min[i] <= self.max[i])
    }

    /// Edge lengths.
    pub fn extent(&self) -> [f64; 3] {
        [
            self.max[0] - self.min[0],
            self.max[1] - self.min[1],
            self.max[2] - self.min[2],
        ]
    }

    /// Length of the diagonal.
    pub fn diagonal(&self) -> f64 {
        let e = self.extent();
        (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt()
    }
}

/// A cube: the root of the octree.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Cube {
    /// Lower corner.
    pub origin: [f64; 3],
    /// Edge length.
    pub size: f64,
}

impl Cube {
    /// The cube centred on `b`, with edge the largest extent of `b` enlarged by `1 + margin`.
    /// A box of zero extent gets edge 1 so that cells have a size.
    pub fn around(b: &Aabb, margin: f64) -> Cube {
        let e = b.extent();
        let mut size = e[0].max(e[1]).max(e[2]) * (1.0 + margin);
        if size.is_nan() || size <= 0.0 || !size.is_finite() {
            size = 1.0;
        }
        let mut origin = [0.0; 3];
        for i in 0..3 {
            origin[i] = 0.5 * (b.min[i] + b.max[i]) - 0.5 * size;
        }
        Cube { origin, size }
    }

    /// The box of cell `key`.
    pub fn cell_box(&self, key: CellKey) -> Aabb {
        let (l, [x, y, z]) = key.decode();
        let s = self.size / (1u64 << l) as f64;
        let min = [
            self.origin[0] + x as f64 * s,
            self.origin[1] + y as f64 * s,
            self.origin[2] + z as f64 * s,
        ];
        Aabb {
            min,
            max: [min[0] + s, min[1] + s, min[2] + s],
        }
    }

    /// Integer coordinates of the level-`level` cell holding `p`, clamped into the cube.
    #[inline]
    pub fn cell_coords(&self, p: [f64; 3], level: u32) -> [u32; 3] {
        let n = (1u64 << level) as f64;
        let inv = n / self.size;
        let max = (1u64 << level) - 1;
        let mut c = [0u32; 3];
        for i in 0..3 {
            let v = ((p[i] - self.origin[i]) * inv).floor();
            c[i] = if v <= 0.0 {
                0
            } else {
                (v as u64).min(max) as u32
            };
        }
        c
    }
}

/// An octree cell: level and Morton code, packed into one `u64` with a sentinel bit
/// (`1 << 3*level | morton`), so that keys of different levels never collide and
/// sort parent-first within a Morton run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct CellKey(pub u64);

/// The deepest octree level a [`CellKey`] can name.
pub const MAX_LEVEL: u32 = 20;

impl CellKey {
    /// The root cell.
    pub const ROOT: CellKey = CellKey(1);

    /// The key of the cell at `level` with integer coordinates `c`.
    pub fn new(level: u32, c: [u32; 3]) -> CellKey {
        debug_assert!(level <= MAX_LEVEL);
        CellKey((1u64 << (3 * level)) | morton3(c))
    }

    /// The key from a level and a Morton code.
    pub fn from_morton(level: u32, morton: u64) -> CellKey {
        CellKey((1u64 << (3 * level)) | morton)
    }

    /// The level (root = 0).
    pub fn level(self) -> u32 {
        (63 - self.0.leading_zeros()) / 3
    }

    /// The Morton code within the level.
    pub fn morton(self) -> u64 {
        self.0 & !(1u64 << (3 * self.level()))
    }

    /// Level and integer coordinates.
    pub fn decode(self) -> (u32, [u32; 3]) {
        (self.level(), demorton3(self.morton()))
    }

    /// The parent cell; the root is its own parent.
    pub fn parent(self) -> CellKey {
        if self.0 == 1 {
            self
        } else {
            CellKey(self.0 >> 3)
        }
    }

    /// Child `i` (0..8) in Morton order.
    pub fn child(self, i: u64) -> CellKey {
        CellKey((self.0 << 3) | i)
    }

    /// A short name used for cell files: the key in hexadecimal.
    pub fn file_name(self) -> String {
        format!("{:016x}", self.0)
    }
}

#[inline]
fn spread3(v: u32) -> u64 {
    let mut x = v as u64 & 0x1f_ffff;
    x = (x | x << 32) & 0x1f00000000ffff;
    x = (x | x << 16) & 0x1f0000ff0000ff;
    x = (x | x << 8) & 0x100f00f00f00f00f;
    x = (x | x << 4) & 0x10c30c30c30c30c3;
    x = (x | x << 2) & 0x1249249249249249;
    x
}

#[inline]
fn compact3(mut x: u64) -> u32 {
    x &= 0x1249249249249249;
    x = (x ^ (x >> 2)) & 0x10c30c30c30c30c3;
    x = (x ^ (x >> 4)) & 0x100f00f00f00f00f;
    x = (x ^ (x >> 8)) & 0x1f0000ff0000ff;
    x = (x ^ (x >> 16)) & 0x1f00000000ffff;
    x = (x ^ (x >> 32)) & 0x1f_ffff;
    x as u32
}

/// Interleave the bits of `c` (x lowest).
#[inline]
pub fn morton3(c: [u32; 3]) -> u64 {
    spread3(c[0]) | spread3(c[1]) << 1 | spread3(c[2]) << 2
}

/// Inverse of [`morton3`].
#[inline]
pub fn demorton3(m: u64) -> [u32; 3] {
    [compact3(m), compact3(m >> 1), compact3(m >> 2)]
}

/// Which optional attributes points carry besides their position.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Attributes {
    /// Unit normals (`nx ny nz`).
    pub normal: bool,
    /// Colour (`red green blue`).
    pub color: bool,
    /// Alpha channel with the colour.
    pub alpha: bool,
    /// Scanner intensity.
    pub intensity: bool,
    /// Per-point confidence.
    pub confidence: bool,
    /// Index of the input (scan) each point came from, kept when a scan's viewpoint is known
    /// so that normals can be oriented toward it.
    #[serde(default)]
    pub source: bool,
}

impl Attributes {
    /// Attributes present in both.
    pub fn intersect(self, o: Attributes) -> Attributes {
        Attributes {
            normal: self.normal && o.normal,
            color: self.color && o.color,
            alpha: self.alpha && o.alpha,
            intensity: self.intensity && o.intensity,
            confidence: self.confidence && o.confidence,
            source: self.source && o.source,
        }
    }

    /// Names of the attributes present, for messages and `info`.
    pub fn names(self) -> Vec<&'static str> {
        let mut v = vec!["x", "y", "z"];
        if self.normal {
            v.extend(["nx", "ny", "nz"]);
        }
        if self.color {
            v.extend(["red", "green", "blue"]);
        }
        if self.alpha {
            v.push("alpha");
        }
        if self.intensity {
            v.push("intensity");
        }
        if self.confidence {
            v.push("confidence");
        }
        if self.source {
            v.push("scan");
        }
        v
    }
}

/// Points in struct-of-arrays form. An attribute's vector is empty when the batch does not
/// carry it, else as long as `pos`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointBatch {
    /// Positions, world frame.
    pub pos: Vec<[f64; 3]>,
    /// Unit normals.
    pub normal: Vec<[f32; 3]>,
    /// RGBA colour, 16 bits per channel (alpha 65535 when the input has none).
    pub color: Vec<[u16; 4]>,
    /// Intensity.
    pub intensity: Vec<f32>,
    /// Confidence.
    pub confidence: Vec<f32>,
    /// Index of the input each point came from.
    pub source: Vec<u16>,
}

impl PointBatch {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.pos.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.pos.is_empty()
    }

    /// Empty every vector, keeping capacity.
    pub fn clear(&mut self) {
        self.pos.clear();
        self.normal.clear();
        self.color.clear();
        self.intensity.clear();
        self.confidence.clear();
        self.source.clear();
    }

    /// Bytes held by the vectors' contents.
    pub fn heap_bytes(&self) -> usize {
        self.pos.capacity() * 24
            + self.normal.capacity() * 12
            + self.color.capacity() * 8
            + (self.intensity.capacity() + self.confidence.capacity()) * 4
            + self.source.capacity() * 2
    }

    /// Apply a rigid transform to positions and normals.
    pub fn transform(&mut self, t: &Rigid) {
        for p in &mut self.pos {
            *p = t.apply(*p);
        }
        for n in &mut self.normal {
            let r = t.rotate([n[0] as f64, n[1] as f64, n[2] as f64]);
            *n = [r[0] as f32, r[1] as f32, r[2] as f32];
        }
    }
}

/// Where a scan was seen from, in the common frame: normals are oriented toward it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Viewpoint {
    /// A scanner position (terrestrial scanners, `--viewpoint x,y,z`).
    Point([f64; 3]),
    /// A direction toward the scanner, for orthographic or far-away sensors (the
    /// Cyberware range images of a `.conf` scan: their local `+z`).
    Direction([f64; 3]),
}

impl Viewpoint {
    /// Unit vector from `p` toward the viewpoint (zero when `p` is the viewpoint).
    #[inline]
    pub fn toward(&self, p: [f64; 3]) -> [f64; 3] {
        let d = match *self {
            Viewpoint::Point(v) => [v[0] - p[0], v[1] - p[1], v[2] - p[2]],
            Viewpoint::Direction(d) => d,
        };
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if l > 0.0 {
            [d[0] / l, d[1] / l, d[2] / l]
        } else {
            [0.0; 3]
        }
    }
}

/// A rigid transform `p -> R p + t`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Rigid {
    /// Row-major rotation matrix.
    pub rotation: [[f64; 3]; 3],
    /// Translation.
    pub translation: [f64; 3],
}

impl Rigid {
    /// The identity.
    pub const IDENTITY: Rigid = Rigid {
        rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        translation: [0.0; 3],
    };

    /// From a translation and a unit quaternion `(x, y, z, w)` (normalised here).
    pub fn from_quaternion(t: [f64; 3], q: [f64; 4]) -> Rigid {
        let uq = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            q[3], q[0], q[1], q[2],
        ));
        let m = uq.to_rotation_matrix();
        let mut rotation = [[0.0; 3]; 3];
        for (r, row) in rotation.iter_mut().enumerate() {
            for (c, v) in row.iter_mut().enumerate() {
                *v = m[(r, c)];
            }
        }
        Rigid {
            rotation,
            translation: t,
        }
    }

    /// Rotate a vector.
    #[inline]
    pub fn rotate(&self, p: [f64; 3]) -> [f64; 3] {
        let r = &self.rotation;
        [
            r[0][0] * p[0] + r[0][1] * p[1] + r[0][2] * p[2],
            r[1][0] * p[0] + r[1][1] * p[1] + r[1][2] * p[2],
            r[2][0] * p[0] + r[2][1] * p[1] + r[2][2] * p[2],
        ]
    }

    /// Transform a point.
    #[inline]
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let r = self.rotate(p);
        [
            r[0] + self.translation[0],
            r[1] + self.translation[1],
            r[2] + self.translation[2],
        ]
    }

    /// True for the identity (exactly).
    pub fn is_identity(&self) -> bool {
        *self == Rigid::IDENTITY
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_round_trip() {
        for c in [
            [0, 0, 0],
            [1, 2, 3],
            [0x1f_ffff, 0, 7],
            [12345, 54321, 99999],
        ] {
            assert_eq!(demorton3(morton3(c)), c);
        }
        assert_eq!(morton3([1, 0, 0]), 1);
        assert_eq!(morton3([0, 1, 0]), 2);
        assert_eq!(morton3([0, 0, 1]), 4);
    }

    #[test]
    fn cell_key_levels() {
        let k = CellKey::new(3, [5, 2, 7]);
        assert_eq!(k.level(), 3);
        assert_eq!(k.decode(), (3, [5, 2, 7]));
        assert_eq!(k.parent().decode(), (2, [2, 1, 3]));
        assert_eq!(CellKey::ROOT.level(), 0);
        assert_eq!(k.parent().child(k.0 & 7), k);
        let deep = CellKey::new(MAX_LEVEL, [(1 << MAX_LEVEL) - 1; 3]);
        assert_eq!(deep.level(), MAX_LEVEL);
    }

    #[test]
    fn cube_cells() {
        let b = Aabb {
            min: [0.0, 0.0, 0.0],
            max: [2.0, 1.0, 1.0],
        };
        let c = Cube::around(&b, 0.0);
        assert_eq!(c.size, 2.0);
        assert_eq!(c.cell_coords([1.99, 0.2, 0.2], 1), [1, 0, 0]);
        assert_eq!(c.cell_coords([2.0, 1.5, -0.5], 1), [1, 1, 0]);
        let bx = c.cell_box(CellKey::new(1, [1, 0, 0]));
        assert_eq!(bx.min, [1.0, -0.5, -0.5]);
    }

    #[test]
    fn quaternion_identity_and_turn() {
        let t = Rigid::from_quaternion([0.0; 3], [0.0, 0.0, 0.0, 1.0]);
        assert!((t.apply([1.0, 2.0, 3.0])[2] - 3.0).abs() < 1e-12);
        let s = std::f64::consts::FRAC_1_SQRT_2;
        // 90 degrees about z maps x to y.
        let t = Rigid::from_quaternion([1.0, 0.0, 0.0], [0.0, 0.0, s, s]);
        let p = t.apply([1.0, 0.0, 0.0]);
        assert!((p[0] - 1.0).abs() < 1e-12 && (p[1] - 1.0).abs() < 1e-12);
    }
}
