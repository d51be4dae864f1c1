//! `scanflow info`: describe a store (from its manifest, its cell files checked for presence and
//! size; with `--verify` every cell read and checked) or a point file (one scan of it).

use std::collections::BTreeMap;

use anyhow::Result;

use scanflow::exec::Ctx;
use scanflow::store::{Store, verify};

use super::config::InfoConfig;
use super::report;

/// Describe the store or file.
pub fn run(c: &InfoConfig, ctx: &Ctx) -> Result<()> {
    if c.path.is_dir() {
        let store = Store::open(&c.path)?;
        let verified = if c.verify {
            Some(verify::verify_cells(&store, ctx)?)
        } else {
            None
        };
        let summary = StoreSummary::new(&store);
        report::store(&c.path, &store, &summary, verified.as_ref(), c.json)
    } else {
        let fi = scanflow::store::file_info(&c.path, ctx)?;
        report::file(&fi, c.json)
    }
}

/// What `info` derives from a store's cells.
pub struct StoreSummary {
    /// Cells by number of bits of their point count: `b` holds the cells of `2^(b-1)` to
    /// `2^b - 1` points (`0`: empty cells).
    pub size_bits: BTreeMap<u32, usize>,
    /// Cells by octree level.
    pub levels: BTreeMap<u32, usize>,
    /// Bytes of all cell files.
    pub bytes: u64,
}

impl StoreSummary {
    fn new(store: &Store) -> StoreSummary {
        let cells = &store.manifest.cells;
        let mut size_bits = BTreeMap::new();
        let mut levels = BTreeMap::new();
        for c in cells {
            *size_bits.entry(64 - c.count.leading_zeros()).or_default() += 1;
            *levels.entry(c.level).or_default() += 1;
        }
        StoreSummary {
            size_bits,
            levels,
            bytes: cells.iter().map(|c| c.bytes).sum(),
        }
    }

    /// The point counts a histogram bin `b` of [`Self::size_bits`] covers.
    pub fn bin_range(b: u32) -> (u64, u64) {
        let lo = if b == 0 { 0 } else { 1u64 << (b - 1) };
        (lo, (1u64 << b) - 1)
    }
}
