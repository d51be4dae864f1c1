//! A split ingest's cells, assembled from its packs (ARCHITECTURE.md step 1, split).
//!
//! Each task of a split ingest scatters whole slices of the inputs' chunks into one *pack*
//! per slice ([`Scatter::packed`](crate::store::scatter::Scatter::packed)): the slice's
//! compressed frames, cell after cell as its buffers filled, then an index of where each
//! cell's frames lie ([`PackIndex`]). A cell of the store is then its frames from every pack,
//! in the packs' order — the inputs' order — appended as they are: a zstd stream is a
//! sequence of frames, so no frame is decompressed or compressed again, and the cell holds
//! its points in the order one process's scatter gives them. Only the frame boundaries can
//! differ from one process's cell file (as with another `--mem`).

use std::fs::File;
use std::io::Write;
use std::ops::Range;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::error::{Error, IoContext, Result};
use crate::store::octree::Hierarchy;
use crate::store::scatter::{CellOut, PackIndex};

/// A pack opened for assembly: its file and its index.
pub struct Pack {
    path: PathBuf,
    file: File,
    index: PackIndex,
}

impl Pack {
    /// Open the pack at `path` and read its index.
    pub fn open(path: &Path) -> Result<Pack> {
        let index = PackIndex::read(path)?;
        let file = File::open(path).with_path(path)?;
        Ok(Pack {
            path: path.to_path_buf(),
            file,
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
        let file = File::create(&path).with_path(&path)?;
        let mut w = std::io::BufWriter::with_capacity(1 << 20, file);
        let mut buf = Vec::new();
        for (p, k) in parts {
            let c = &p.index.cells[k];
            for &(off, len) in &c.frames {
                buf.resize(len as usize, 0);
                p.file.read_exact_at(&mut buf, off).with_path(&p.path)?;
                cell.wrote(&buf);
                w.write_all(&buf).with_path(&path)?;
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
