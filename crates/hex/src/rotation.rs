//! The 24 rotations of the cube (the chiral octahedral group): the matchings of CubeCover
//! (Nieser, Reitebuch, Polthier 2011, §2.1–2.2).
//!
//! A cube rotation is a signed permutation matrix with determinant +1: it maps the parameter
//! axes `u, v, w` of one tetrahedron's chart onto ± the axes of its neighbour's. Where the
//! frame field gives frames `F_s`, `F_t` (columns the axes in space) in neighbouring tetrahedra,
//! the parameterisation's gradients satisfy `∇u_t ≈ Π_st ∇u_s` with `∇u ≈ Fᵀ`, so the matching
//! is the cube rotation closest to `F_tᵀ F_s` ([`closest`]): the one maximising
//! `tr(Πᵀ F_tᵀ F_s)`.
//!
//! Around an interior edge, the product of the matchings of its cyclic star of tetrahedra is
//! the edge's holonomy: the identity on a regular edge, a rotation by ±90° about the edge's
//! direction on a singular edge of valence 3 or 5 (the cube's quarter turns), by 180° on
//! valence 2 or 6; any other product (a rotation about another axis, 120° turns) makes the
//! edge invalid for a hexahedral mesh ([`Holonomy`]).
//!
//! Rotations are indexed `0..24`, index 0 the identity; [`Rot::compose`] and [`Rot::inverse`]
//! are table lookups.

use std::sync::OnceLock;

/// A cube rotation by its index in [`all`] (0 is the identity).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
pub struct Rot(pub u8);

/// The group's tables: matrices, products and inverses.
struct Tables {
    mats: [[[i8; 3]; 3]; 24],
    mul: [[u8; 24]; 24],
    inv: [u8; 24],
}

fn tables() -> &'static Tables {
    static T: OnceLock<Tables> = OnceLock::new();
    T.get_or_init(|| {
        let mut mats = Vec::with_capacity(24);
        // Identity first, then every signed permutation with determinant +1 in a fixed order.
        let perms = [
            [0, 1, 2],
            [0, 2, 1],
            [1, 0, 2],
            [1, 2, 0],
            [2, 0, 1],
            [2, 1, 0],
        ];
        for p in perms {
            for s in 0..8u8 {
                let sign = |k: usize| if s >> k & 1 == 1 { -1i8 } else { 1 };
                let mut m = [[0i8; 3]; 3];
                for r in 0..3 {
                    m[r][p[r]] = sign(r);
                }
                if det(&m) == 1 {
                    mats.push(m);
                }
            }
        }
        debug_assert_eq!(mats.len(), 24);
        let mats: [[[i8; 3]; 3]; 24] = mats.try_into().expect("24 cube rotations");
        let index = |m: &[[i8; 3]; 3]| mats.iter().position(|x| x == m).expect("closed") as u8;
        let mut mul = [[0u8; 24]; 24];
        let mut inv = [0u8; 24];
        for a in 0..24 {
            for b in 0..24 {
                mul[a][b] = index(&matmul(&mats[a], &mats[b]));
            }
            inv[a] = index(&transpose(&mats[a]));
        }
        Tables { mats, mul, inv }
    })
}

fn det(m: &[[i8; 3]; 3]) -> i8 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

fn matmul(a: &[[i8; 3]; 3], b: &[[i8; 3]; 3]) -> [[i8; 3]; 3] {
    let mut c = [[0i8; 3]; 3];
    for r in 0..3 {
        for k in 0..3 {
            c[r][k] = (0..3).map(|j| a[r][j] * b[j][k]).sum();
        }
    }
    c
}

fn transpose(a: &[[i8; 3]; 3]) -> [[i8; 3]; 3] {
    let mut t = [[0i8; 3]; 3];
    for r in 0..3 {
        for k in 0..3 {
            t[r][k] = a[k][r];
        }
    }
    t
}

/// Every cube rotation, identity first.
pub fn all() -> impl Iterator<Item = Rot> {
    (0..24u8).map(Rot)
}

impl Rot {
    /// The identity.
    pub const ID: Rot = Rot(0);

    /// The signed permutation matrix (row-major: `(R x)_r = Σ_k R[r][k] x_k`).
    pub fn matrix(self) -> [[i8; 3]; 3] {
        tables().mats[self.0 as usize]
    }

    /// `self · other` (apply `other` first).
    pub fn compose(self, other: Rot) -> Rot {
        Rot(tables().mul[self.0 as usize][other.0 as usize])
    }

    /// The inverse (the transpose).
    pub fn inverse(self) -> Rot {
        Rot(tables().inv[self.0 as usize])
    }

    /// `R x` for a real vector.
    pub fn apply(self, x: [f64; 3]) -> [f64; 3] {
        let m = self.matrix();
        [0, 1, 2].map(|r| (0..3).map(|k| m[r][k] as f64 * x[k]).sum())
    }

    /// `R x` for an integer vector.
    pub fn apply_i(self, x: [i64; 3]) -> [i64; 3] {
        let m = self.matrix();
        [0, 1, 2].map(|r| (0..3).map(|k| m[r][k] as i64 * x[k]).sum())
    }

    /// The trace (3 identity, 1 quarter turn, −1 half turn, 0 third turn).
    pub fn trace(self) -> i8 {
        let m = self.matrix();
        m[0][0] + m[1][1] + m[2][2]
    }

    /// The rotation axis as a parameter axis `0..3` with the sign of the turn's direction,
    /// for quarter and half turns about a coordinate axis: `Some((axis, quarter_turns))`
    /// with `quarter_turns` in `{1, 2, 3}` counter-clockwise (right-hand rule about the
    /// positive axis); `None` for the identity and the turns about diagonals.
    pub fn axis_turn(self) -> Option<(usize, u8)> {
        let m = self.matrix();
        let axis = (0..3).find(|&a| m[a][a] == 1 && self != Rot::ID)?;
        let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
        // The image of e_b: e_c (quarter turn), −e_b (half), −e_c (three quarters).
        Some(if m[c][b] == 1 {
            (axis, 1)
        } else if m[b][b] == -1 {
            (axis, 2)
        } else {
            (axis, 3)
        })
    }
}

/// The cube rotation closest to the real 3×3 matrix `m` (row-major): the one maximising
/// `tr(Rᵀ m) = Σ R[r][k] m[r][k]`; ties go to the lower index.
pub fn closest(m: &[[f64; 3]; 3]) -> Rot {
    let mut best = (f64::NEG_INFINITY, Rot::ID);
    for r in all() {
        let a = r.matrix();
        let s: f64 = (0..3)
            .flat_map(|i| (0..3).map(move |k| (i, k)))
            .map(|(i, k)| a[i][k] as f64 * m[i][k])
            .sum();
        if s > best.0 + 1e-12 {
            best = (s, r);
        }
    }
    best.1
}

/// The matching from tetrahedron `s` to its neighbour `t` for frames `fs`, `ft` (`f[k]` the
/// k-th axis in space): the cube rotation closest to `F_tᵀ F_s`, whose entry `(r, k)` is
/// `ft[r] · fs[k]`.
pub fn matching(fs: &super::Frame, ft: &super::Frame) -> Rot {
    let mut m = [[0.0; 3]; 3];
    for r in 0..3 {
        for k in 0..3 {
            m[r][k] = (0..3).map(|x| ft[r][x] * fs[k][x]).sum();
        }
    }
    closest(&m)
}

/// What the product of the matchings around an interior edge says about it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Holonomy {
    /// The identity: a regular edge (valence 4 in the hex mesh).
    Regular,
    /// A quarter or half turn about a parameter axis (`axis`, `quarter_turns` 1–3): a singular
    /// edge, admissible when the axis is the edge's direction.
    Turn {
        /// The parameter axis of the turn.
        axis: usize,
        /// Counter-clockwise quarter turns about it.
        quarter_turns: u8,
    },
    /// A turn about a diagonal (120°, 240°) or a half turn about a face diagonal: no
    /// hexahedral mesh has such an edge.
    Invalid,
}

/// Classifies an edge's holonomy.
pub fn holonomy(r: Rot) -> Holonomy {
    if r == Rot::ID {
        return Holonomy::Regular;
    }
    match r.axis_turn() {
        Some((axis, quarter_turns)) => Holonomy::Turn {
            axis,
            quarter_turns,
        },
        None => Holonomy::Invalid,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_group_is_closed_with_inverses() {
        let mut seen = std::collections::BTreeSet::new();
        for a in all() {
            assert!(seen.insert(a.matrix()));
            assert_eq!(a.compose(a.inverse()), Rot::ID);
            assert_eq!(a.inverse().compose(a), Rot::ID);
            for b in all() {
                let x = [0.3, -1.7, 2.9];
                let ab = a.compose(b).apply(x);
                let a_b = a.apply(b.apply(x));
                assert_eq!(ab, a_b);
            }
        }
        assert_eq!(seen.len(), 24);
        assert_eq!(Rot::ID.matrix(), [[1, 0, 0], [0, 1, 0], [0, 0, 1]]);
        // Conjugacy classes by trace: 1 identity, 6 quarter turns, 3 + 6 half turns, 8 thirds.
        let count = |t: i8| all().filter(|r| r.trace() == t).count();
        assert_eq!((count(3), count(1), count(-1), count(0)), (1, 6, 9, 8));
        let axis_turns = all().filter(|r| r.axis_turn().is_some()).count();
        assert_eq!(axis_turns, 9);
    }

    #[test]
    fn closest_recovers_a_perturbed_rotation_and_quarter_turns_have_their_sense() {
        for r in all() {
            let m = r.matrix();
            let mut p = [[0.0; 3]; 3];
            for i in 0..3 {
                for k in 0..3 {
                    p[i][k] = m[i][k] as f64 + 0.2 * ((i * 3 + k) as f64).sin();
                }
            }
            assert_eq!(closest(&p), r);
        }
        // A quarter turn about w maps u to v.
        let q = all()
            .find(|r| {
                r.apply([1.0, 0.0, 0.0]) == [0.0, 1.0, 0.0]
                    && r.apply([0.0, 0.0, 1.0]) == [0.0, 0.0, 1.0]
            })
            .unwrap();
        assert_eq!(q.axis_turn(), Some((2, 1)));
        assert_eq!(q.compose(q).axis_turn(), Some((2, 2)));
        assert_eq!(q.compose(q).compose(q).axis_turn(), Some((2, 3)));
        assert_eq!(
            holonomy(q.compose(q).compose(q).compose(q)),
            Holonomy::Regular
        );
        // A third turn about the diagonal is invalid.
        let third = all()
            .find(|r| {
                r.apply([1.0, 0.0, 0.0]) == [0.0, 1.0, 0.0]
                    && r.apply([0.0, 1.0, 0.0]) == [0.0, 0.0, 1.0]
            })
            .unwrap();
        assert_eq!(holonomy(third), Holonomy::Invalid);
    }

    #[test]
    fn matching_of_frames_related_by_a_cube_rotation_is_that_rotation() {
        // A generic frame and the same frame with its axes permuted by each rotation.
        let (a, b) = (0.4f64, 1.1f64);
        let (ca, sa, cb, sb) = (a.cos(), a.sin(), b.cos(), b.sin());
        let fs: crate::Frame = [
            [ca * cb, sa * cb, -sb],
            [-sa, ca, 0.0],
            [ca * sb, sa * sb, cb],
        ];
        for r in all() {
            // ∇u_t = Π ∇u_s: the axes of t are the rows of Π Fᵀ_s.
            let m = r.matrix();
            let mut ft = [[0.0; 3]; 3];
            for k in 0..3 {
                for x in 0..3 {
                    ft[k][x] = (0..3).map(|j| m[k][j] as f64 * fs[j][x]).sum();
                }
            }
            assert_eq!(matching(&fs, &ft), r);
        }
    }
}
