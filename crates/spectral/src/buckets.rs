//! A uniform grid of buckets over points or boxes, for the box queries of admission and
//! blending: build by counting sort, query by the range of buckets a box meets.

/// Items (points, or boxes) bucketed on a uniform grid.
#[derive(Debug, Clone, Default)]
pub struct Buckets {
    lo: [f64; 3],
    s: f64,
    dims: [usize; 3],
    /// Start of each bucket's items in `idx` (buckets + 1 entries).
    start: Vec<u32>,
    /// Item indices, by bucket, ascending within a bucket.
    idx: Vec<u32>,
}

/// Most buckets per axis.
const MAX_DIM: usize = 1024;

impl Buckets {
    /// Boxes `(lo, hi)` bucketed so that about `per_bucket` items share a bucket along a
    /// surface: each box is listed in every bucket it meets.
    pub fn of_boxes(boxes: &[([f64; 3], [f64; 3])], per_bucket: f64) -> Buckets {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for (a, b) in boxes {
            for k in 0..3 {
                lo[k] = lo[k].min(a[k]);
                hi[k] = hi[k].max(b[k]);
            }
        }
        if boxes.is_empty() {
            return Buckets::default();
        }
        let extent = (0..3)
            .map(|k| hi[k] - lo[k])
            .fold(0f64, f64::max)
            .max(1e-300);
        // On a surface, occupied buckets grow as the square of the resolution.
        let s = extent * (per_bucket / boxes.len() as f64).sqrt().min(1.0);
        let mut g = Buckets::empty(lo, hi, s, boxes.len());
        let ranges: Vec<[usize; 6]> = boxes.iter().map(|(a, b)| g.range(*a, *b)).collect();
        g.fill(&ranges);
        g
    }

    /// Points bucketed so that about `per_bucket` share a bucket along a surface.
    pub fn of_points(pos: &[[f64; 3]], per_bucket: f64) -> Buckets {
        let boxes: Vec<([f64; 3], [f64; 3])> = pos.iter().map(|p| (*p, *p)).collect();
        Buckets::of_boxes(&boxes, per_bucket)
    }

    fn empty(lo: [f64; 3], hi: [f64; 3], s: f64, n: usize) -> Buckets {
        let mut s = s.max((0..3).map(|k| hi[k] - lo[k]).fold(0f64, f64::max) / MAX_DIM as f64);
        if s.is_nan() || s <= 0.0 {
            s = 1.0;
        }
        let mut dims = [0usize; 3];
        for k in 0..3 {
            dims[k] = (((hi[k] - lo[k]) / s).floor() as usize + 1).clamp(1, MAX_DIM);
        }
        // Keep the bucket count within a few times the items.
        while dims[0] * dims[1] * dims[2] > 8 * n + 64 {
            s *= 1.5;
            for k in 0..3 {
                dims[k] = (((hi[k] - lo[k]) / s).floor() as usize + 1).clamp(1, MAX_DIM);
            }
        }
        Buckets {
            lo,
            s,
            dims,
            start: Vec::new(),
            idx: Vec::new(),
        }
    }

    #[inline]
    fn coord(&self, x: f64, k: usize) -> usize {
        // `as` truncates toward zero and saturates negatives to 0: the floor, clamped.
        (((x - self.lo[k]) / self.s) as usize).min(self.dims[k] - 1)
    }

    /// Bucket ranges `[x0, y0, z0, x1, y1, z1]` (inclusive) a box meets.
    #[inline]
    fn range(&self, a: [f64; 3], b: [f64; 3]) -> [usize; 6] {
        [
            self.coord(a[0], 0),
            self.coord(a[1], 1),
            self.coord(a[2], 2),
            self.coord(b[0], 0),
            self.coord(b[1], 1),
            self.coord(b[2], 2),
        ]
    }

    fn fill(&mut self, ranges: &[[usize; 6]]) {
        let [dx, dy, dz] = self.dims;
        let mut count = vec![0u32; dx * dy * dz + 1];
        let each = |r: &[usize; 6], f: &mut dyn FnMut(usize)| {
            for z in r[2]..=r[5] {
                for y in r[1]..=r[4] {
                    for x in r[0]..=r[3] {
                        f((z * dy + y) * dx + x);
                    }
                }
            }
        };
        for r in ranges {
            each(r, &mut |b| count[b + 1] += 1);
        }
        for b in 1..count.len() {
            count[b] += count[b - 1];
        }
        let mut next = count.clone();
        let mut idx = vec![0u32; count[count.len() - 1] as usize];
        for (i, r) in ranges.iter().enumerate() {
            each(r, &mut |b| {
                idx[next[b] as usize] = i as u32;
                next[b] += 1;
            });
        }
        self.start = count;
        self.idx = idx;
    }

    /// Every item listed in a bucket that the box `(a, b)` meets, in bucket order (an item
    /// can come more than once when it spans buckets: see [`Buckets::at`] for points).
    pub fn in_box(&self, a: [f64; 3], b: [f64; 3], mut f: impl FnMut(u32)) {
        if self.idx.is_empty() {
            return;
        }
        let r = self.range(a, b);
        let [dx, dy, _] = self.dims;
        for z in r[2]..=r[5] {
            for y in r[1]..=r[4] {
                let row = (z * dy + y) * dx;
                let (s, e) = (self.start[row + r[0]], self.start[row + r[3] + 1]);
                for &i in &self.idx[s as usize..e as usize] {
                    f(i);
                }
            }
        }
    }

    /// The items listed in the bucket holding point `p`, ascending.
    #[inline]
    pub fn at(&self, p: [f64; 3]) -> &[u32] {
        if self.idx.is_empty() {
            return &[];
        }
        let [dx, dy, _] = self.dims;
        let b = (self.coord(p[2], 2) * dy + self.coord(p[1], 1)) * dx + self.coord(p[0], 0);
        &self.idx[self.start[b] as usize..self.start[b + 1] as usize]
    }

    /// Bytes held.
    pub fn heap_bytes(&self) -> usize {
        (self.start.capacity() + self.idx.capacity()) * 4
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_queries_find_every_point_inside() {
        let mut s = 7u64;
        let mut r = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let pts: Vec<[f64; 3]> = (0..3000).map(|_| [r(), r(), 0.1 * r()]).collect();
        let g = Buckets::of_points(&pts, 8.0);
        for _ in 0..50 {
            let a = [r(), r(), 0.0];
            let b = [a[0] + 0.2 * r(), a[1] + 0.2 * r(), 0.05];
            let mut got = Vec::new();
            g.in_box(a, b, |i| {
                let p = pts[i as usize];
                if (0..3).all(|k| p[k] >= a[k] && p[k] <= b[k]) {
                    got.push(i);
                }
            });
            got.sort();
            let want: Vec<u32> = (0..pts.len() as u32)
                .filter(|&i| {
                    (0..3).all(|k| pts[i as usize][k] >= a[k] && pts[i as usize][k] <= b[k])
                })
                .collect();
            assert_eq!(got, want);
        }
    }

    #[test]
    fn a_point_finds_every_box_holding_it() {
        let boxes: Vec<([f64; 3], [f64; 3])> = (0..200)
            .map(|i| {
                let x = (i % 20) as f64 * 0.05;
                let y = (i / 20) as f64 * 0.1;
                ([x, y, 0.0], [x + 0.12, y + 0.15, 0.01])
            })
            .collect();
        let g = Buckets::of_boxes(&boxes, 4.0);
        for p in [[0.5, 0.5, 0.005], [0.01, 0.99, 0.0], [1.0, 0.2, 0.01]] {
            let got: Vec<u32> = g
                .at(p)
                .iter()
                .copied()
                .filter(|&i| {
                    let (a, b) = boxes[i as usize];
                    (0..3).all(|k| p[k] >= a[k] && p[k] <= b[k])
                })
                .collect();
            let want: Vec<u32> = (0..boxes.len() as u32)
                .filter(|&i| {
                    let (a, b) = boxes[i as usize];
                    (0..3).all(|k| p[k] >= a[k] && p[k] <= b[k])
                })
                .collect();
            assert_eq!(got, want);
        }
    }
}
