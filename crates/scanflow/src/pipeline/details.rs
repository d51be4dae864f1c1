//! Leaf details read back from the work directory for the tiles, through one byte-bounded
//! cache: tiles in Morton order reuse the leaves of their neighbours.
//!
//! The cache holds at most its byte cap (its slice of the budget); a wave of tiles holds the
//! details its tiles touch itself, whether the cache keeps them or not, and charges them to its
//! own permit (`tiles::run`).

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use rayon::prelude::*;

use crate::error::Result;
use crate::exec::cache::Lru;
use crate::recon::checkpoint::leaf_detail;
use crate::types::{CellKey, Detail};

/// Bytes of one detail value: 16-bit fixed point (`quantise_detail`).
const DETAIL_VALUE_BYTES: u64 = 2;

/// Leaf details read back from the work directory, cached up to a byte cap. Every detail has
/// the same size, so the cache holds a number of entries: at least one, at most what the byte
/// cap allows, and as [`DetailCache::fit`] asks in between.
pub struct DetailCache {
    dir: PathBuf,
    m: usize,
    cache: Lru<CellKey, Arc<Detail>>,
    /// Bytes of one detail.
    per: u64,
    cap_entries: usize,
    max_entries: usize,
}

impl DetailCache {
    /// Details of `m³` nodes from checkpoint directory `dir`, up to `cap_bytes` (at least one
    /// detail).
    pub fn new(dir: &Path, m: usize, cap_bytes: u64) -> DetailCache {
        let per = ((m * m * m) as u64 * DETAIL_VALUE_BYTES).max(1);
        let max_entries = ((cap_bytes / per) as usize).max(1);
        DetailCache {
            dir: dir.to_path_buf(),
            m,
            cache: Lru::new(max_entries as u64 * per),
            per,
            cap_entries: max_entries,
            max_entries,
        }
    }

    /// Bytes of one detail.
    pub fn detail_bytes(&self) -> u64 {
        self.per
    }

    /// Keep at most `want` entries (at least one, at most the byte cap allows).
    pub fn fit(&mut self, want: usize) {
        self.cap_entries = want.clamp(1, self.max_entries);
        self.cache.set_capacity(self.cap_entries as u64 * self.per);
    }

    /// The details of `keys`: those cached become the most recently used, the others are read
    /// in parallel on `pool` and cached (evicting the least recently used beyond the cap). The
    /// caller holds them all, cached or not, as long as it keeps the map.
    pub fn load(
        &mut self,
        keys: &[CellKey],
        pool: &rayon::ThreadPool,
    ) -> Result<HashMap<CellKey, Arc<Detail>>> {
        let mut out = HashMap::new();
        let mut missing = Vec::new();
        for &k in keys {
            if out.contains_key(&k) || missing.contains(&k) {
                continue;
            }
            match self.cache.get(&k) {
                Some(d) => {
                    out.insert(k, Arc::clone(d));
                }
                None => missing.push(k),
            }
        }
        let (dir, m) = (&self.dir, self.m);
        let loaded: Vec<Result<Detail>> = pool.install(|| {
            missing
                .par_iter()
                .map(|&k| leaf_detail(dir, k, m))
                .collect()
        });
        for (k, d) in missing.into_iter().zip(loaded) {
            let d = Arc::new(d?);
            self.cache.insert(k, Arc::clone(&d), self.per);
            out.insert(k, d);
        }
        Ok(out)
    }
}
