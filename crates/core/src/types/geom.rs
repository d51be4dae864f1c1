//! Boxes, the octree's root cube and rigid transforms, in world coordinates (`f64`, input
//! units).

use serde::{Deserialize, Serialize};

use super::CellKey;

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

    /// The squared distance from `p` to the box (0 inside): per axis the gap to the box,
    /// squared, summed over the axes in order. Each term is at most the like term of any
    /// point of the box, and rounding is monotone, so in floats too it is at most
    /// `Σ_a (x_a − p_a)²` (summed in that order) for every `x` in the box.
    #[inline]
    pub fn dist2(&self, p: [f64; 3]) -> f64 {
        let gap = |a: usize| (self.min[a] - p[a]).max(p[a] - self.max[a]).max(0.0);
        gap(0).powi(2) + gap(1).powi(2) + gap(2).powi(2)
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
///
/// **Translation invariance.** [`Cube::around`] puts the cube on a lattice tied to its size,
/// so that the same points translated by a vector `t` of lattice steps get the cube translated
/// by exactly `t` (any `t` of whole multiples of `q`): the edge is rounded up to 16
/// significant bits, `m·q` with `q` a power of two and `2^15 ≤ m ≤ 2^16`, and the lower corner
/// down to a multiple of `q`. Every grid node and cell corner `origin + k·size/2^d` is then
/// exact in `f64` wherever `|origin| / size < 2^(37 − d)` (`2^24` at the deepest supported
/// depth, 13), so a point's offset from any of them is exact too, and
/// everything downstream of the cube (plan, leaf grids, splats, tile fields, the iso-value)
/// sees the same numbers for `P` and `P + t`. The edge grows by less than `2^-15` and the
/// corner moves by less than `size/2^15`: the grids stay where they were to within a
/// thousandth of a voxel (coarser rounding, 8 bits, moved them enough to flip marginal
/// topology, two sheets 1.7 voxels apart).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Cube {
    /// Lower corner.
    pub origin: [f64; 3],
    /// Edge length.
    pub size: f64,
}

impl Cube {
    /// The cube around `b`, with edge the largest extent of `b` enlarged by `1 + margin`,
    /// rounded up and placed on its lattice (see [`Cube`]); centred on `b` to within
    /// `size/2^15`. A box of zero extent gets edge 1 so that cells have a size.
    pub fn around(b: &Aabb, margin: f64) -> Cube {
        let e = b.extent();
        let mut size = e[0].max(e[1]).max(e[2]) * (1.0 + margin);
        if size.is_nan() || size <= 0.0 || !size.is_finite() {
            size = 1.0;
        }
        let q = lattice_quantum(size);
        if q > 0.0 && (size / q).is_finite() {
            size = (size / q).ceil() * q;
        }
        let step = q;
        let mut origin = [0.0; 3];
        for i in 0..3 {
            let o = 0.5 * (b.min[i] + b.max[i]) - 0.5 * size;
            let snapped = (o / step).floor() * step;
            origin[i] = if snapped.is_finite() { snapped } else { o };
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
            let v = floor((p[i] - self.origin[i]) * inv);
            c[i] = if v <= 0.0 {
                0
            } else {
                (v as u64).min(max) as u32
            };
        }
        c
    }
}

/// Significant bits of the cube's edge: `2^15 ≤ size/q < 2^16`.
const LATTICE_LOW: f64 = (1u64 << 15) as f64;

/// The power of two `q` with `2^15·q ≤ size < 2^16·q` (0 where `size` is too small for one).
fn lattice_quantum(size: f64) -> f64 {
    let e = size.log2().floor() as i32 - 15;
    let q = 2f64.powi(e);
    // log2 may round across a power of two; correct by one step either way.
    if LATTICE_LOW * q > size {
        q / 2.0
    } else if 2.0 * LATTICE_LOW * q <= size {
        q * 2.0
    } else {
        q
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

/// `x.floor()` for finite `x` with `|x| < 2^63`, without the libm call that x86-64's baseline
/// (no SSE4.1) makes of `floor`: a call per coordinate was a visible share of the per-sample
/// loops (splats, screening, density). Exact: truncation is exact and off by one only below zero.
#[inline(always)]
pub fn floor(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x { t - 1.0 } else { t }
}

/// `i.rem_euclid(n)` for `n > 0`, without the integer division where `i` already lies in
/// `0..n`: the samples of a local grid wrap only at its edges, and a division per axis was a
/// visible share of the per-sample loops (splat, screening, evaluation).
#[inline(always)]
pub fn wrap(i: i64, n: i64) -> i64 {
    if (0..n).contains(&i) {
        i
    } else {
        i.rem_euclid(n)
    }
}

/// `x.round()` as an index, for `0 <= x < 2^53`, without a libm call (see [`floor`]).
#[inline(always)]
pub fn round_index(x: f64) -> usize {
    let f = x as usize;
    if x - f as f64 >= 0.5 { f + 1 } else { f }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_round_and_wrap_agree_with_libm() {
        let half = 0.5f64.next_down();
        for x in [
            0.0,
            -0.0,
            half,
            -half,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.5,
            -2.5,
            1e15 + 0.5,
            -1e15 - 0.5,
            9.1e18,
            -9.1e18,
            1e-300,
            -1e-300,
        ] {
            assert_eq!(floor(x), x.floor(), "{x}");
            let i = x as i64;
            for n in [1, 7, 64] {
                assert_eq!(wrap(i, n), i.rem_euclid(n), "{i} {n}");
            }
            if (0.0..9e15).contains(&x) {
                assert_eq!(round_index(x), x.round() as usize, "{x}");
            }
        }
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
    fn cube_is_on_its_lattice_and_translates_exactly() {
        let b = Aabb {
            min: [0.123456789, -3.75, 2.0],
            max: [40.9876543, 11.5, 9.25],
        };
        let c = Cube::around(&b, 0.1);
        let q = lattice_quantum(c.size);
        let want = 1.1 * (40.9876543 - 0.123456789);
        assert!(c.size >= want && c.size <= want * (1.0 + 1.0 / LATTICE_LOW));
        assert_eq!((c.size / q).fract(), 0.0);
        for i in 0..3 {
            assert!(c.origin[i] <= b.min[i] && c.origin[i] + c.size >= b.max[i]);
            assert_eq!((c.origin[i] / q).fract(), 0.0);
        }
        let t = [5.0e6, 5.0e6, 100.0];
        let bt = Aabb {
            min: [0, 1, 2].map(|i| b.min[i] + t[i]),
            max: [0, 1, 2].map(|i| b.max[i] + t[i]),
        };
        let ct = Cube::around(&bt, 0.1);
        assert_eq!(ct.size, c.size);
        assert_eq!(ct.origin, [0, 1, 2].map(|i| c.origin[i] + t[i]));
        for size in [1e-30, 0.75, 1.0, 255.9, 256.0, 1e30] {
            let q = lattice_quantum(size);
            assert!(
                LATTICE_LOW * q <= size && size < 2.0 * LATTICE_LOW * q,
                "{size} {q}"
            );
        }
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
