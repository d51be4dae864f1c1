//! A split ingest's cells, assembled from its packs (ARCHITECTURE.md step 1, split).
//!
//! Each task of a split ingest scatters whole slices of the inputs' chunks into one *pack*
//! per slice ([`Scatter::packed`](crate::scatter::Scatter::packed)): the slice's
//! compressed frames, cell after cell as its buffers filled, then an index of where each
//! cell's frames lie ([`PackIndex`]). A cell of the store is then its frames from every pack,
//! in the packs' order — the inputs' order — appended as they are: a zstd stream is a
//! sequence of frames, so no frame is decompressed or compressed again, and the cell holds
//! its points in the order one process's scatter gives them. Only the frame boundaries can
//! differ from one process's cell file (as with another `--mem`). Each frame's CRC-32, taken
//! when it was compressed, is in the pack's index, and a cell's CRC-32 is combined from its
//! frames' (not taken over the bytes as they are copied), so a pack damaged on disk gives a
//! cell that fails its check when it is read.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::ops::Range;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::error::{Error, IoContext, Result};
use crate::octree::Hierarchy;
use crate::scatter::{CellOut, PackIndex};

/// A pack opened for assembly: its path and its index.
pub struct Pack {
    path: PathBuf,
    index: PackIndex,
}

impl Pack {
    /// Open the pack at `path` and read its index.
    pub fn open(path: &Path) -> Result<Pack> {
        let index = PackIndex::read(path)?;
        Ok(Pack {
            path: path.to_path_buf(),
            index,
        })
    }

    /// Bytes its index holds in memory, about.
    pub fn index_bytes(&self) -> u64 {
        self.index
            .cells
            .iter()
            .map(|c| 80 + 16 * c.frames.len() as u64)
            .sum()
    }
}

/// The cells of the leaves `leaves` of `hier`, each written to `dir` from its frames in every
/// pack, in the packs' order, the leaves in parallel on `pool`; returns them in leaf order
/// (empty ones too, with no file).
pub fn assemble(
    packs: &[Pack],
    hier: &Hierarchy,
    leaves: Range<usize>,
    dir: &Path,
    pool: &rayon::ThreadPool,
) -> Result<Vec<CellOut>> {
    let cells: Vec<Result<CellOut>> = pool.install(|| {
        leaves
            .into_par_iter()
            .map(|leaf| assemble_leaf(packs, hier, leaf, dir))
            .collect()
    });
    cells.into_iter().collect()
}

/// The cell of leaf `leaf`, written to `dir`.
fn assemble_leaf(packs: &[Pack], hier: &Hierarchy, leaf: usize, dir: &Path) -> Result<CellOut> {
    let key = hier.leaves[leaf].key;
    let path = dir.join(format!("{}.zst", key.file_name()));
    let mut cell = CellOut::new(key, path.clone());
    let parts: Vec<(&Pack, usize)> = packs
        .iter()
        .filter_map(|p| {
            p.index
                .cells
                .binary_search_by_key(&(leaf as u32), |c| c.cell)
                .ok()
                .map(|k| (p, k))
        })
        .collect();
    if !parts.is_empty() {
        let mut w = BufWriter::with_capacity(1 << 20, File::create(&path).with_path(&path)?);
        let mut buf = Vec::new();
        for (p, k) in parts {
            let c = &p.index.cells[k];
            let src = File::open(&p.path).with_path(&p.path)?;
            for f in &c.frames {
                buf.resize(f.len as usize, 0);
                src.read_exact_at(&mut buf, f.offset).with_path(&p.path)?;
                w.write_all(&buf).with_path(&path)?;
                // The CRC-32 the frame had when it was compressed: a pack damaged since
                // gives a cell that fails its check when read.
                cell.wrote(f.len as u64, f.crc32);
            }
            cell.count += c.count;
            cell.bounds = cell.bounds.union(&c.bounds);
        }
        w.flush().with_path(&path)?;
    }
    if cell.count != hier.leaves[leaf].count {
        return Err(Error::Internal(format!(
            "cell {}: the packs hold {} points, the count found {}; an input changed while ingesting?",
            key.file_name(),
            cell.count,
            hier.leaves[leaf].count
        )));
    }
    Ok(cell)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cell_file::{RecordLayout, read_cell_file};
    use crate::octree::GridMap;
    use crate::scatter::{Grouped, Scatter, group};
    use crate::types::{Attributes, CellKey, Cube, PointBatch};

    /// Points of two slices scattered into two packs, on a hierarchy of the 8 children of the
    /// unit cube's root.
    fn packs(dir: &Path) -> (Hierarchy, Vec<PathBuf>, RecordLayout, Vec<Vec<[f64; 3]>>) {
        let layout = RecordLayout::new(Attributes::default(), false);
        let cube = Cube {
            origin: [0.0; 3],
            size: 1.0,
        };
        let map = GridMap::new(&cube, CellKey::ROOT, 1);
        let slices: Vec<Vec<[f64; 3]>> = (0..2)
            .map(|s| {
                (0..40)
                    .map(|i| {
                        let t = (s * 40 + i) as f64 / 80.0;
                        [t, (3.0 * t) % 1.0, (7.0 * t) % 1.0]
                    })
                    .collect()
            })
            .collect();
        let mut counts = vec![0u64; 8];
        for p in slices.iter().flatten() {
            counts[map.index(*p) as usize] += 1;
        }
        let h = Hierarchy::build(CellKey::ROOT, 1, &counts, 1000);
        let keys: Vec<CellKey> = h.leaves.iter().map(|l| l.key).collect();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let mut paths = Vec::new();
        for (s, pts) in slices.iter().enumerate() {
            let path = dir.join(format!("{s}.pack"));
            let sc = Scatter::packed(&path, &keys, layout, 0, 1).unwrap();
            let b = PointBatch {
                pos: pts.clone(),
                ..Default::default()
            };
            let leaf: Vec<u32> = pts
                .iter()
                .map(|p| h.leaf_of(map.index(*p)).unwrap())
                .collect();
            let mut g = Grouped::default();
            group(&b, &leaf, keys.len(), &layout, &mut g);
            let mut sc = sc;
            sc.push(&pool, &g).unwrap();
            sc.finish(&pool)
                .unwrap()
                .pack
                .unwrap()
                .append_to(&path)
                .unwrap();
            paths.push(path);
        }
        // Each leaf's points in input order: the first slice's, then the second's.
        let want = (0..keys.len())
            .map(|l| {
                slices
                    .iter()
                    .flatten()
                    .filter(|p| h.leaf_of(map.index(**p)) == Some(l as u32))
                    .copied()
                    .collect()
            })
            .collect();
        (h, paths, layout, want)
    }

    #[test]
    fn cells_hold_every_packs_points_in_input_order_and_a_damaged_pack_is_caught() {
        let d = tempfile::tempdir().unwrap();
        let (h, paths, layout, want) = packs(d.path());
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let open = || {
            paths
                .iter()
                .map(|p| Pack::open(p).unwrap())
                .collect::<Vec<_>>()
        };
        let out = d.path().join("cells");
        std::fs::create_dir(&out).unwrap();
        let cells = assemble(&open(), &h, 0..h.leaves.len(), &out, &pool).unwrap();
        assert_eq!(cells.len(), h.leaves.len());
        for (c, w) in cells.iter().zip(&want) {
            let b = read_cell_file(&c.file, layout, c.count, c.crc32()).unwrap();
            assert_eq!(&b.pos, w, "cell {}", c.key.file_name());
        }
        // A frame's byte changed in a pack after it was written: the cell assembled from it
        // fails its check (its CRC-32 comes from the frames as compressed).
        let mut bytes = std::fs::read(&paths[1]).unwrap();
        bytes[3] ^= 0x40;
        std::fs::write(&paths[1], &bytes).unwrap();
        let cells = assemble(&open(), &h, 0..h.leaves.len(), &out, &pool).unwrap();
        let bad = cells
            .iter()
            .filter(|c| read_cell_file(&c.file, layout, c.count, c.crc32()).is_err())
            .count();
        assert_eq!(bad, 1);
    }
}
