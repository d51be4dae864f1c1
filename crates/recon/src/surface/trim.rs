//! Trimming (`--trim`): the surface is left open where no input point is near, instead of
//! closed by the coarse solution.

use crate::types::TileMesh;

/// Which voxels of a grid over the cube hold input points (for `--trim`: the finest level's
/// coarse voxels where the budget allows, `pipeline::reconstruct`).
pub struct Support {
    origin: [f64; 3],
    inv_h: f64,
    n: i64,
    bits: Vec<u64>,
}

impl Support {
    /// No voxel marked, on a grid of `n³` voxels of edge `spacing` from `origin`.
    pub fn new(origin: [f64; 3], spacing: f64, n: u64) -> Support {
        Support {
            origin,
            inv_h: 1.0 / spacing,
            n: n as i64,
            bits: vec![0u64; Support::words(n)],
        }
    }

    /// Bytes of the bits of a grid of `n³` voxels.
    pub fn bytes(n: u64) -> u64 {
        Support::words(n) as u64 * 8
    }

    /// Words of bits a grid of `n³` voxels takes.
    fn words(n: u64) -> usize {
        ((n * n * n) as usize).div_ceil(64)
    }

    fn cell(&self, p: [f64; 3]) -> [i64; 3] {
        [0, 1, 2]
            .map(|a| (((p[a] - self.origin[a]) * self.inv_h).floor() as i64).clamp(0, self.n - 1))
    }

    /// The grid without its marks: [`Support::index`] beside the support being marked.
    pub fn layout(&self) -> Support {
        Support {
            bits: Vec::new(),
            ..*self
        }
    }

    /// The index of input point `p`'s voxel, for [`Support::mark_index`].
    pub fn index(&self, p: [f64; 3]) -> usize {
        let c = self.cell(p);
        ((c[2] * self.n + c[1]) * self.n + c[0]) as usize
    }

    /// The bits, voxel `i` at bit `i % 64` of word `i / 64` (for a checkpoint).
    pub fn bits(&self) -> &[u64] {
        &self.bits
    }

    /// [`Support::new`] with the marks `bits` (a checkpoint's); `None` when they are not
    /// that grid's.
    pub fn with_bits(origin: [f64; 3], spacing: f64, n: u64, bits: Vec<u64>) -> Option<Support> {
        (bits.len() == Support::words(n)).then(|| Support {
            origin,
            inv_h: 1.0 / spacing,
            n: n as i64,
            bits,
        })
    }

    /// Mark the voxel of index `i` ([`Support::index`]).
    pub fn mark_index(&mut self, i: usize) {
        self.bits[i / 64] |= 1 << (i % 64);
    }

    /// Mark the voxel of input point `p`.
    pub fn mark(&mut self, p: [f64; 3]) {
        self.mark_index(self.index(p));
    }

    /// True when a point lies in the voxel of `p` or one of its 26 neighbours.
    pub fn near(&self, p: [f64; 3]) -> bool {
        let c = self.cell(p);
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let q = [c[0] + dx, c[1] + dy, c[2] + dz];
                    if q.iter().any(|&v| v < 0 || v >= self.n) {
                        continue;
                    }
                    let i = ((q[2] * self.n + q[1]) * self.n + q[0]) as usize;
                    if self.bits[i / 64] & (1 << (i % 64)) != 0 {
                        return true;
                    }
                }
            }
        }
        false
    }
}

/// Keep the triangles whose centroid `keep` accepts, and only the vertices they use.
pub fn trim_mesh(mesh: &mut TileMesh, keep: impl Fn([f64; 3]) -> bool) {
    retain_triangles(mesh, |m, t| {
        let p = t.map(|i| m.positions[i as usize]);
        keep([0, 1, 2].map(|a| (p[0][a] + p[1][a] + p[2][a]) / 3.0))
    });
}

/// Keep the triangles whose corners' mean sampling density (`mesh.density`: input points
/// per square unit) is at least `least`, and only the vertices they use (`--trim-density`).
/// A mesh without densities is left as it is.
pub fn trim_by_density(mesh: &mut TileMesh, least: f64) {
    if mesh.density.len() != mesh.positions.len() {
        return;
    }
    retain_triangles(mesh, |m, t| {
        let sum: f64 = t.iter().map(|&i| f64::from(m.density[i as usize])).sum();
        sum / 3.0 >= least
    });
}

/// Keep the triangles `keep` accepts, and only the vertices they use, with their attributes,
/// in their order of first use.
fn retain_triangles(mesh: &mut TileMesh, keep: impl Fn(&TileMesh, [u32; 3]) -> bool) {
    let mut used = vec![u32::MAX; mesh.positions.len()];
    let mut out = TileMesh::default();
    for &t in &mesh.triangles {
        if !keep(mesh, t) {
            continue;
        }
        let nt = t.map(|i| {
            let i = i as usize;
            if used[i] == u32::MAX {
                used[i] = out.keys.len() as u32;
                out.keys.push(mesh.keys[i]);
                out.positions.push(mesh.positions[i]);
                if let Some(c) = mesh.colors.get(i) {
                    out.colors.push(*c);
                }
                if let Some(v) = mesh.intensity.get(i) {
                    out.intensity.push(*v);
                }
                if let Some(v) = mesh.density.get(i) {
                    out.density.push(*v);
                }
            }
            used[i]
        });
        out.triangles.push(nt);
    }
    *mesh = out;
}
