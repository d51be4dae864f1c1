//! Island removal: the connected pieces of a triangle mesh whose area is a small fraction of
//! the whole, dropped as the mesh is written (PoissonRecon's SurfaceTrimmer `--aRatio`).
//!
//! Trimming by sampling density (or by support) cuts a reconstruction where the samples are
//! thin, and leaves small floating pieces where a few samples were dense enough: noise, a
//! passer-by, a reflection. SurfaceTrimmer (Kazhdan's PoissonRecon distribution) removes
//! every connected component whose area is below `aRatio` times the mesh's total area
//! (default 0.001); [`IslandFilter`] does the same over a mesh already staged on disk, so it
//! needs the whole mesh, which tiles never see alone.
//!
//! **Components** are those of the graph whose nodes are vertices and whose edges are the
//! triangles' sides: a union–find over vertex indices (union by smaller index, path
//! halving), one pass over the triangles. A component's area is the sum of its triangles'
//! areas `|(b − a) × (c − a)| / 2` in float64, summed in triangle order; so the choice is the
//! same bytes for any thread count, tile size or shard count, as the staged mesh is. A vertex
//! no triangle uses has area 0 and goes too.
//!
//! **Memory**: [`BYTES_PER_VERTEX`]: the parents (`u32`), the component areas (`f64`), and
//! the new vertex numbers (`u32`); positions are looked up in the mapped staged vertices (page
//! cache), triangles streamed.

/// Bytes per vertex the filter holds while it is built (module docs).
pub const BYTES_PER_VERTEX: u64 = 16;

/// The new vertex numbers of a mesh with its islands removed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IslandFilter {
    /// Per old vertex: its new number, or [`IslandFilter::DROPPED`].
    new: Vec<u32>,
    /// Vertices kept.
    pub vertices: u64,
    /// Triangles kept.
    pub triangles: u64,
    /// Components found, and those dropped.
    pub components: u64,
    /// Components dropped.
    pub dropped: u64,
}

impl IslandFilter {
    /// The number of a dropped vertex.
    pub const DROPPED: u32 = u32::MAX;

    /// Components of the mesh of `vertices` vertices (positions by `pos`) whose triangles
    /// `each_triangle` gives (calling its argument once per triangle, in order); those with
    /// less than `ratio` of the total area are dropped.
    pub fn new<E>(
        vertices: u32,
        pos: impl Fn(u32) -> [f64; 3],
        mut each_triangle: impl FnMut(&mut dyn FnMut([u32; 3])) -> Result<(), E>,
        ratio: f64,
    ) -> Result<IslandFilter, E> {
        let n = vertices as usize;
        let mut parent: Vec<u32> = (0..vertices).collect();
        each_triangle(&mut |t| {
            union(&mut parent, t[0], t[1]);
            union(&mut parent, t[0], t[2]);
        })?;
        // Every vertex points at its root (roots are the least index of their component, so
        // one ascending pass settles them).
        for v in 0..n {
            let p = parent[v] as usize;
            parent[v] = parent[p];
        }
        let mut area = vec![0f64; n];
        let mut total = 0.0;
        let mut triangles = 0u64;
        each_triangle(&mut |t| {
            let [a, b, c] = t.map(&pos);
            let e = [0, 1, 2].map(|k| b[k] - a[k]);
            let f = [0, 1, 2].map(|k| c[k] - a[k]);
            let x = [
                e[1] * f[2] - e[2] * f[1],
                e[2] * f[0] - e[0] * f[2],
                e[0] * f[1] - e[1] * f[0],
            ];
            let s = 0.5 * (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
            area[parent[t[0] as usize] as usize] += s;
            total += s;
            triangles += 1;
        })?;
        let least = ratio * total;
        let (mut components, mut dropped) = (0u64, 0u64);
        for v in 0..n {
            if parent[v] as usize == v {
                components += 1;
                dropped += u64::from(area[v] < least || area[v] == 0.0);
            }
        }
        let mut new = vec![Self::DROPPED; n];
        let mut kept = 0u32;
        for v in 0..n {
            let a = area[parent[v] as usize];
            if a >= least && a > 0.0 {
                new[v] = kept;
                kept += 1;
            }
        }
        drop(area);
        let mut f = IslandFilter {
            new,
            vertices: u64::from(kept),
            triangles: 0,
            components,
            dropped,
        };
        // Triangles kept: those whose corners are (a component is kept whole).
        let mut kept_triangles = 0u64;
        each_triangle(&mut |t| kept_triangles += u64::from(f.keeps(t[0])))?;
        f.triangles = kept_triangles;
        debug_assert!(kept_triangles <= triangles);
        Ok(f)
    }

    /// Whether vertex `v` is kept.
    pub fn keeps(&self, v: u32) -> bool {
        self.new[v as usize] != Self::DROPPED
    }

    /// The new number of vertex `v` (kept).
    pub fn renumber(&self, v: u32) -> u32 {
        self.new[v as usize]
    }
}

fn root(parent: &mut [u32], mut v: u32) -> u32 {
    while parent[v as usize] != v {
        let g = parent[parent[v as usize] as usize];
        parent[v as usize] = g;
        v = g;
    }
    v
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (root(parent, a), root(parent, b));
    let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
    parent[hi as usize] = lo;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two unit squares (area 1 each) and a small triangle (area 0.005), plus an unused vertex.
    fn mesh() -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        let mut v = Vec::new();
        let mut t = Vec::new();
        // The small triangle first, so its vertices are not the least indices.
        v.extend([[5.0, 0.0, 0.0], [5.1, 0.0, 0.0], [5.0, 0.1, 0.0]]);
        t.push([0, 1, 2]);
        for x0 in [0.0, 2.0] {
            let b = v.len() as u32;
            v.extend([
                [x0, 0.0, 0.0],
                [x0 + 1.0, 0.0, 0.0],
                [x0 + 1.0, 1.0, 0.0],
                [x0, 1.0, 0.0],
            ]);
            // Given corner-last, so the union must follow the chain.
            t.push([b + 2, b + 3, b]);
            t.push([b + 1, b + 2, b]);
        }
        v.push([9.0, 9.0, 9.0]);
        (v, t)
    }

    fn filter(ratio: f64) -> IslandFilter {
        let (v, t) = mesh();
        IslandFilter::new(
            v.len() as u32,
            |i| v[i as usize],
            |f: &mut dyn FnMut([u32; 3])| -> Result<(), ()> {
                t.iter().for_each(|x| f(*x));
                Ok(())
            },
            ratio,
        )
        .unwrap()
    }

    #[test]
    fn a_small_piece_goes_and_the_large_ones_stay_renumbered_in_order() {
        // The triangle is 0.25% of the area: it stays at 0.1%; the unused vertex goes.
        let f = filter(0.001);
        assert_eq!((f.components, f.dropped), (4, 1));
        assert_eq!((f.vertices, f.triangles), (11, 5));
        let f = filter(0.01);
        assert_eq!((f.components, f.dropped), (4, 2));
        assert_eq!((f.vertices, f.triangles), (8, 4));
        assert!(!f.keeps(0) && !f.keeps(1) && !f.keeps(2) && !f.keeps(11));
        assert_eq!(
            (3..11).map(|v| f.renumber(v)).collect::<Vec<_>>(),
            (0..8).collect::<Vec<_>>()
        );
        // Over half the area: both squares are islands of a mesh with nothing larger.
        let f = filter(0.6);
        assert_eq!((f.vertices, f.triangles, f.dropped), (0, 0, 4));
    }

    #[test]
    fn ratio_zero_drops_only_what_has_no_area() {
        let f = filter(0.0);
        assert_eq!((f.vertices, f.triangles, f.dropped), (11, 5, 1));
    }
}
