//! The grids of one run: fine spacing, coarse ratio, leaf and tile sizes, coarse padding, all
//! chosen once from the depth, the cube and the memory budget.

use serde::{Deserialize, Serialize};

use super::density::DensityGrid;
use super::grid::LocalGrid;
use crate::error::{Error, Result, Setting};
use crate::types::{CellKey, Cube};

/// Peak bytes per node of a solve: the splatted normals (12) and the divergence (4).
pub const COARSE_BYTES_PER_NODE: u64 = 16;

pub use super::grid::SCREENED_BYTES_PER_NODE;

/// Coarse voxels added to the cube's width before rounding up to a 5-smooth size: 4 on each
/// side, so that the periodic coarse solve never wraps the surface.
const COARSE_PAD_VOXELS: u64 = 8;

/// The coarse ratio of every level (`r = 4`, leaves of `E = 32` fine voxels).
const COARSE_RATIO: u64 = 4;

/// Coarse voxels per axis of the largest dense coarse solve: a level whose coarse grid would
/// be finer (depths above 10) takes the level two octaves up as its coarse field.
pub const DENSE_MAX_CELLS: u64 = 256;

/// Octaves between a level and the one above it: the coarse ratio 4.
const LEVEL_STEP: u32 = 2;

/// The shallowest depth of a level over a dense solve, when there are levels above the
/// finest: its dense coarse grid then has 16 voxels an edge. Measured on a torus (150K
/// points, `--error 0`): over a dense grid of 16 or 32 voxels a level of leaves stays within
/// 7% of the two-level scheme's mean distance; over one of 8 (where a single leaf of the
/// level spans the cube) the mean grows 1.4-2.8×, the largest distance 7×.
pub const MIN_DENSE_DEPTH: u32 = 6;

/// Fine voxels of a leaf per coarse voxel: the coarse voxel is at most `E/8`, the size at
/// which the two-level blend matches one global solve.
const LEAF_COARSE_VOXELS: u64 = 8;

/// A leaf's local grids pad its cell by `E/4` beyond each face (grids of `1.5E` nodes, 48³
/// for leaves of 32 voxels), and its detail overlaps its neighbours by `E/8`. The two-level
/// detail is the fine minus the coarse local solve of the same points, so what truncating
/// the points at the box leaves in it is of the fine band only, and fades within a coarse
/// voxel or two of the box: the prototype of the scheme padded by `E/2` (the cell in a box
/// twice its size, as Kazhdan and Hoppe's leaves are), which this halves. Measured against one
/// global solve at depth 9 (2M samples, noise 5·10⁻⁴ of the diagonal; mean distance between
/// the meshes, relative to the `E/2` padding's): torus 0.93×, bumpy sphere 0.99×, two sheets
/// 0.03 apart 1.23× (1.0·10⁻⁴ against 1.3·10⁻⁴ of a cube of 2.2); the distance to the exact
/// surface equal or lower on all three, and the leaf stage 2.2–2.4× faster (`E/8` padding:
/// twice the distance to the global solve on the two sheets).
const LEAF_PAD_DIVISOR: u64 = 4;

/// A leaf's detail overlaps each neighbour by `E / LEAF_OVERLAP_DIVISOR` fine voxels, half its
/// padding: the detail stops `E/8` short of its grid's faces.
const LEAF_OVERLAP_DIVISOR: u64 = 8;

/// A leaf reads the points within `5E/32` of its cell: `3E/32` (3 voxels at `E = 32`: the
/// splat's corner and the smoothing's tail) short of its grid's faces, so that no point's
/// splat wraps around the periodic grid. A binary fraction, so that the box's faces lie on
/// the cube's lattice (`types::Cube`): the same points translated are then in or out of it
/// alike.
pub const LEAF_REACH: f64 = 5.0 / 32.0;

/// Default tile edge in fine voxels.
const DEFAULT_TILE_VOXELS: u64 = 64;

/// Depths `reconstruct` supports.
pub const DEPTHS: std::ops::RangeInclusive<u32> = 5..=13;

/// Default `--error`: 2·10⁻⁵ of the diagonal, about a fiftieth of a voxel at depth 10: below
/// the noise of real scans (which are then refined everywhere, as a global solve would be),
/// above the error of the coarse solve on smooth, clean surfaces (which are then left coarse).
pub const DEFAULT_ERROR: f64 = 2e-5;

/// Default `--min-points`: a leaf needs this many samples in its cell to be refined. A fixed
/// count, not a share of the input (the paper's 0.5% suits 10⁵ points, not 10⁹): the detail
/// of a leaf is defined by its own samples, whatever the size of the scan.
pub const DEFAULT_MIN_POINTS: u64 = 8;

/// The smallest `m >= n` whose only prime factors are 2, 3 and 5.
pub fn smooth_size(n: u64) -> u64 {
    let mut m = n.max(1);
    loop {
        let mut k = m;
        for p in [2, 3, 5] {
            while k.is_multiple_of(p) {
                k /= p;
            }
        }
        if k == 1 {
            return m;
        }
        m += 1;
    }
}

/// What the grids of a plan hold at the two peaks of a run, or what a budget allows there.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PlanBudget {
    /// The coarse solve's scratch and the density grid, while the solve runs.
    pub coarse: u64,
    /// The coarse solution, the density grid and one leaf solve, held together through the
    /// leaf pass.
    pub leaf: u64,
}

/// The grids of one run. Serialised in the work directory's run description under the short
/// names of earlier versions, so that work directories stay resumable.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// The cube.
    pub cube: Cube,
    /// Depth.
    pub depth: u32,
    /// Fine cells per edge of the cube, `N = 2^depth`.
    #[serde(rename = "n")]
    pub fine_cells: u64,
    /// Fine spacing `h`, in input units.
    #[serde(rename = "h")]
    pub spacing: f64,
    /// Fine voxels per coarse voxel, `r`.
    #[serde(rename = "r")]
    pub coarse_ratio: u64,
    /// Leaf edge in fine voxels, `E = 8r`.
    #[serde(rename = "e")]
    pub leaf_voxels: u64,
    /// Detail overlap beyond each face of a leaf, in fine voxels (`E/8`).
    #[serde(rename = "ov")]
    pub overlap_voxels: u64,
    /// Octree level of leaves.
    pub leaf_level: u32,
    /// Coarse padding below the cube, in coarse voxels: at least 4 on each side, more where
    /// rounding the coarse grid up to a 5-smooth size adds room (4 to 56 at the supported
    /// depths; 7 at depth 10 with `r = 4`, 270 nodes for 256 coarse voxels).
    #[serde(rename = "pad")]
    pub coarse_pad: u64,
    /// Coarse nodes per axis: the smallest 5-smooth size (fast for the FFT) holding the cube
    /// and 4 coarse voxels of padding on each side.
    pub coarse_nodes: u64,
    /// Tile edge in fine voxels.
    pub tile: u64,
    /// Octree level of tiles.
    pub tile_level: u32,
    /// Smoothing width in voxels.
    pub sigma_vox: f64,
    /// Smoothing width of the coarse local solves, in coarse voxels: the width the coarse
    /// field (the level above, or the dense solve) was solved with, which the coarse local
    /// solve stands in for. Equal to `sigma_vox` but where sparse samples widen each grid's
    /// Gaussian by its own spacing ([`crate::weight::sparse_floor_voxels`]).
    #[serde(default)]
    pub coarse_sigma_vox: f64,
    /// Screening weight α (`--point-weight`; 0: the unscreened solve), see
    /// [`crate::screen`].
    #[serde(default)]
    pub point_weight: f64,
    /// The noise the vertex fit allows for, in fine voxels
    /// ([`crate::noise::NoiseStats::fit_noise_voxels`]; `None` before the coarse pass,
    /// or where nothing was measured).
    #[serde(default)]
    pub fit_noise_voxels: Option<f64>,
    /// Samples' normals are weighed by their confidence (`--confidence`).
    #[serde(default)]
    pub confidence: bool,
}

impl Plan {
    /// The grids of one level at `depth` with coarse ratio `r` (a power of two, at least 4;
    /// the leaf edge `E = 8r` is clamped to the cube).
    pub fn with_ratio(
        cube: Cube,
        depth: u32,
        sigma_vox: f64,
        point_weight: f64,
        tile: Option<u64>,
        r: u64,
    ) -> Plan {
        let n = 1u64 << depth;
        let e = (LEAF_COARSE_VOXELS * r).min(n);
        let r = (e / LEAF_COARSE_VOXELS).max(1);
        let coarse_nodes = smooth_size(n / r + COARSE_PAD_VOXELS);
        let tile = tile.unwrap_or(DEFAULT_TILE_VOXELS).clamp(e, n);
        let tile = tile.next_power_of_two().min(n);
        Plan {
            cube,
            depth,
            fine_cells: n,
            spacing: cube.size / n as f64,
            coarse_ratio: r,
            leaf_voxels: e,
            overlap_voxels: e / LEAF_OVERLAP_DIVISOR,
            leaf_level: depth - e.trailing_zeros(),
            coarse_pad: (coarse_nodes - n / r) / 2,
            coarse_nodes,
            tile,
            tile_level: depth - tile.trailing_zeros(),
            sigma_vox,
            coarse_sigma_vox: sigma_vox,
            point_weight,
            fit_noise_voxels: None,
            confidence: false,
        }
    }

    /// What coarse ratio `r` holds at depth `depth`: the coarse solve's scratch, then the
    /// coarse solution (f32 a node) with one leaf's fine solve (its `(1.5E)³` grid, `E = 8r`);
    /// the sampling-density grid ([`crate::density`]) beside both.
    pub fn needs(depth: u32, r: u64, screened: bool) -> PlanBudget {
        let n = 1u64 << depth;
        let e = (LEAF_COARSE_VOXELS * r).min(n);
        let r = (e / LEAF_COARSE_VOXELS).max(1);
        let nc = smooth_size(n / r + COARSE_PAD_VOXELS);
        let grid = |n: u64| LocalGrid {
            n: n as usize,
            h: 1.0,
            origin: [0.0; 3],
            unit: 1.0,
        };
        let density = DensityGrid::bytes(n / r);
        PlanBudget {
            coarse: grid(nc).solve_bytes(screened) + density,
            leaf: nc * nc * nc * 4 + density + grid(leaf_grid_nodes(e)).solve_bytes(screened),
        }
    }

    /// The smallest `--mem` a run at `depth` can be planned in: the needs of the smallest
    /// dense level [`levels`] can stop at, scaled by `to_total` into the whole budget they
    /// take.
    pub fn least_budget(depth: u32, screened: bool, to_total: impl Fn(PlanBudget) -> u64) -> u64 {
        let mut d = depth;
        while d >= MIN_DENSE_DEPTH + LEVEL_STEP {
            d -= LEVEL_STEP;
        }
        to_total(Plan::needs(d, COARSE_RATIO, screened))
    }

    /// Coarse nodes per axis (periodic FFT size).
    pub fn coarse_n(&self) -> usize {
        self.coarse_nodes as usize
    }

    /// Coarse spacing, `r·h`.
    pub fn coarse_spacing(&self) -> f64 {
        self.spacing * self.coarse_ratio as f64
    }

    /// Coarse voxels per edge of the cube, `N/r`.
    pub fn coarse_cells(&self) -> u64 {
        self.fine_cells / self.coarse_ratio
    }

    /// The coarse global grid.
    pub fn coarse_grid(&self) -> LocalGrid {
        let hc = self.coarse_spacing();
        let o = self.coarse_pad as f64 * hc;
        LocalGrid {
            n: self.coarse_n(),
            h: hc,
            origin: [
                self.cube.origin[0] - o,
                self.cube.origin[1] - o,
                self.cube.origin[2] - o,
            ],
            unit: self.cube.size,
        }
    }

    /// Global fine node of the lower corner of leaf cell `key`.
    pub fn leaf_node(&self, key: CellKey) -> [i64; 3] {
        let (_, c) = key.decode();
        c.map(|v| v as i64 * self.leaf_voxels as i64)
    }

    /// The fine local grid of a leaf: the cell padded by [`Plan::leaf_pad`] beyond each face.
    pub fn leaf_fine_grid(&self, key: CellKey) -> LocalGrid {
        LocalGrid {
            n: self.leaf_grid_n(),
            h: self.spacing,
            origin: self.node_pos(self.leaf_lattice(key)),
            unit: self.cube.size,
        }
    }

    /// The fine node of a leaf's local grids' node 0 ([`Plan::leaf_fine_grid`]).
    pub fn leaf_lattice(&self, key: CellKey) -> [i64; 3] {
        let pad = self.leaf_pad() as i64;
        self.leaf_node(key).map(|g| g - pad)
    }

    /// Scratch bytes of one leaf's fine solve.
    pub fn leaf_scratch_bytes(&self) -> u64 {
        LocalGrid {
            n: self.leaf_grid_n(),
            h: self.spacing,
            origin: [0.0; 3],
            unit: self.cube.size,
        }
        .solve_bytes(self.point_weight > 0.0)
    }

    /// Bytes of the coarse solution (f32 a node).
    pub fn coarse_field_bytes(&self) -> u64 {
        self.coarse_nodes.pow(3) * 4
    }

    /// Bytes of the sampling-density grid ([`crate::density`]), at the coarse spacing.
    pub fn density_bytes(&self) -> u64 {
        DensityGrid::bytes(self.coarse_cells())
    }

    /// Scratch bytes of the coarse global solve.
    pub fn coarse_scratch_bytes(&self) -> u64 {
        self.coarse_grid().solve_bytes(self.point_weight > 0.0)
    }

    /// World position of fine node `g`.
    pub fn node_pos(&self, g: [i64; 3]) -> [f64; 3] {
        [
            self.cube.origin[0] + g[0] as f64 * self.spacing,
            self.cube.origin[1] + g[1] as f64 * self.spacing,
            self.cube.origin[2] + g[2] as f64 * self.spacing,
        ]
    }

    /// Padding of a leaf's local grids beyond each face of its cell, in fine voxels (`E/4`,
    /// a multiple of `r`: the coarse local grid's nodes lie on the global coarse lattice).
    pub fn leaf_pad(&self) -> u64 {
        self.leaf_voxels / LEAF_PAD_DIVISOR
    }

    /// Nodes per axis of a leaf's local fine grid (`1.5E`).
    pub fn leaf_grid_n(&self) -> usize {
        leaf_grid_nodes(self.leaf_voxels) as usize
    }

    /// Nodes per axis of a leaf's detail grid.
    pub fn detail_n(&self) -> usize {
        (self.leaf_voxels + 2 * self.overlap_voxels + 1) as usize
    }
}

/// Nodes per axis of the local fine grid of a leaf of `e` voxels: the cell and its padding.
fn leaf_grid_nodes(e: u64) -> u64 {
    e + 2 * (e / LEAF_PAD_DIVISOR)
}

/// The levels of the recursive scheme for `depth`, finest first. Every level has coarse ratio
/// 4 (leaves of 32 fine voxels, their solves on 48³ grids); level `k + 1` is two octaves
/// above level `k` (its fine spacing is level `k`'s coarse spacing) and is level `k`'s
/// coarse field. The last level's coarse field is one dense global solve: the first, from
/// the finest, whose coarse grid has at most [`DENSE_MAX_CELLS`] voxels per axis, is at
/// most `coarse_depth` octaves deep (when given), and whose needs ([`Plan::needs`]) fit
/// `budget` (or the shallowest possible, where none does; the caller refuses such budgets
/// first, [`Plan::least_budget`]). A run at depth 10 or less
/// with room for its coarse solve has one level: the two-level scheme of earlier versions,
/// bit for bit.
pub fn levels(
    cube: Cube,
    depth: u32,
    sigma_vox: f64,
    point_weight: f64,
    tile: Option<u64>,
    coarse_depth: Option<u32>,
    budget: PlanBudget,
) -> Result<Vec<Plan>> {
    if !DEPTHS.contains(&depth) {
        return Err(Error::Usage(format!(
            "{} {depth} is out of range: supported depths are {}..={}",
            Setting::Depth,
            DEPTHS.start(),
            DEPTHS.end()
        )));
    }
    let screened = point_weight > 0.0;
    let mut out = Vec::new();
    let mut d = depth;
    loop {
        let p = Plan::with_ratio(cube, d, sigma_vox, point_weight, tile, COARSE_RATIO);
        let need = Plan::needs(d, COARSE_RATIO, screened);
        let fits = need.coarse <= budget.coarse && need.leaf <= budget.leaf;
        out.push(p);
        let shallow = coarse_depth.is_none_or(|c| d <= c + LEVEL_STEP);
        if (p.coarse_cells() <= DENSE_MAX_CELLS && fits && shallow)
            || d < MIN_DENSE_DEPTH + LEVEL_STEP
        {
            return Ok(out);
        }
        d -= LEVEL_STEP;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CUBE: Cube = Cube {
        origin: [0.0; 3],
        size: 1.0,
    };

    fn budget(total: u64) -> PlanBudget {
        PlanBudget {
            coarse: total * 2 / 3,
            leaf: total * 3 / 4,
        }
    }

    /// A leaf's grid, at every depth and ratio: `1.5E` nodes, its padding on the coarse
    /// lattice (so the coarse local grid is the global one's), its detail `E/8` short of the
    /// grid's faces, and its points' splats (a voxel) and smoothing (two) short of them too.
    #[test]
    fn a_leaf_grid_holds_its_detail_and_its_points_within_its_faces() {
        for depth in DEPTHS {
            for r in [4, 8] {
                let p = Plan::with_ratio(CUBE, depth, 1.0, 4.0, None, r);
                let (e, pad, r) = (p.leaf_voxels, p.leaf_pad(), p.coarse_ratio);
                assert_eq!(p.leaf_grid_n() as u64, e + 2 * pad, "{p:?}");
                assert_eq!(2 * p.leaf_grid_n() as u64, 3 * e, "{p:?}");
                assert_eq!(pad % r, 0, "{p:?}");
                assert_eq!(pad - p.overlap_voxels, e / 8, "{p:?}");
                assert_eq!(p.detail_n() as u64, e + 2 * p.overlap_voxels + 1);
                let reach = LEAF_REACH * e as f64;
                assert_eq!(pad as f64 - reach, 3.0 * e as f64 / 32.0, "{p:?}");
                assert!(reach >= p.overlap_voxels as f64, "{p:?}");
            }
        }
    }

    /// With room, depths up to 10 keep one level (the two-level scheme) and deeper ones stack
    /// levels two octaves apart over a dense solve of at most 256 cells an edge.
    #[test]
    fn levels_stack_two_octaves_apart_over_a_bounded_dense_solve() {
        let big = budget(64 << 30);
        for depth in 5..=13 {
            let l = levels(CUBE, depth, 1.0, 4.0, None, None, big).unwrap();
            let depths: Vec<u32> = l.iter().map(|p| p.depth).collect();
            assert_eq!(depths[0], depth);
            let top = l.last().unwrap();
            assert!(top.coarse_cells() <= DENSE_MAX_CELLS, "{depths:?}");
            for w in l.windows(2) {
                assert_eq!(w[1].depth + 2, w[0].depth);
                assert_eq!(w[1].spacing, w[0].coarse_spacing());
                assert_eq!(w[0].coarse_ratio, 4);
                assert_eq!(w[0].leaf_voxels, 32);
            }
            if depth <= 10 {
                assert_eq!(depths, [depth]);
                assert_eq!(l[0], Plan::with_ratio(CUBE, depth, 1.0, 4.0, None, 4));
            } else {
                // The shallowest stack: the level above the top would fit too.
                assert!(top.depth >= 9, "{depths:?}");
            }
        }
    }

    /// A tight budget or `--coarse-depth` adds levels; every level's leaf solve is the same
    /// size, so the least budget does not grow with the depth.
    #[test]
    fn a_tight_budget_or_a_shallow_coarse_depth_adds_levels() {
        let l = levels(CUBE, 10, 1.0, 4.0, None, None, budget(64 << 20)).unwrap();
        let depths: Vec<u32> = l.iter().map(|p| p.depth).collect();
        assert_eq!(depths, [10, 8]);
        let l = levels(CUBE, 13, 1.0, 4.0, None, None, budget(64 << 20)).unwrap();
        let depths: Vec<u32> = l.iter().map(|p| p.depth).collect();
        assert_eq!(depths, [13, 11, 9, 7]);
        assert_eq!(l[3].coarse_cells(), 32);
        let l = levels(CUBE, 10, 1.0, 4.0, None, Some(4), budget(64 << 30)).unwrap();
        let depths: Vec<u32> = l.iter().map(|p| p.depth).collect();
        assert_eq!(depths, [10, 8, 6]);
        // Never over a dense grid of fewer than 16 voxels an edge.
        let l = levels(CUBE, 9, 1.0, 4.0, None, Some(3), budget(64 << 30)).unwrap();
        let depths: Vec<u32> = l.iter().map(|p| p.depth).collect();
        assert_eq!(depths, [9, 7]);
        let least: Vec<u64> = (7..=13)
            .map(|d| Plan::least_budget(d, true, |n| n.coarse.max(n.leaf)))
            .collect();
        assert!(
            least.iter().all(|&b| b == least[0] || b == least[1]),
            "{least:?}"
        );
        assert!(least[0] < 16 << 20, "{least:?}");
    }
}
