//! Leaf details read back from the work directory for the tiles, through one byte-bounded
//! cache: tiles in Morton order reuse the leaves of their neighbours.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use rayon::prelude::*;

use crate::error::Result;
use crate::exec::cache::Lru;
use crate::recon::checkpoint::leaf_detail;
use crate::types::{CellKey, Detail};

/// Bytes of one detail value: 16-bit fixed point (`quantise_detail`).
const DETAIL_VALUE_BYTES: u64 = 2;

/// The fewest details the cache holds, whatever its byte cap: a tile needs all the leaves that
/// reach it at once (at most 27 for a tile of one leaf, more for larger tiles).
const MIN_DETAILS: usize = 64;

/// Leaf details read back from the work directory, cached up to a byte cap. Every detail has
/// the same size, so the cache holds a number of entries: at least [`MIN_DETAILS`], at most
/// what the byte cap allows, and as [`DetailCache::fit`] asks in between.
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
    /// Details of `m³` nodes from checkpoint directory `dir`, up to `cap_bytes`.
    pub fn new(dir: &Path, m: usize, cap_bytes: u64) -> DetailCache {
        let per = ((m * m * m) as u64 * DETAIL_VALUE_BYTES).max(1);
        let max_entries = ((cap_bytes / per) as usize).max(MIN_DETAILS);
        DetailCache {
            dir: dir.to_path_buf(),
            m,
            cache: Lru::new(max_entries as u64 * per),
            per,
            cap_entries: max_entries,
            max_entries,
        }
    }

    /// Keep at most `want` entries (at least [`MIN_DETAILS`], at most the byte cap allows).
    pub fn fit(&mut self, want: usize) {
        self.cap_entries = want.clamp(MIN_DETAILS, self.max_entries);
        self.cache.set_capacity(self.cap_entries as u64 * self.per);
    }

    /// Drop the least recently used entries until at most `keep` remain.
    fn evict_to(&mut self, keep: usize) {
        while self.cache.len() > keep {
            self.cache.pop_oldest();
        }
    }

    /// Make the details of `keys` resident: those cached become the most recently used, the
    /// others are read in parallel on `pool` (as many as the cache holds), after evicting the
    /// least recently used to make room. Only speed depends on this.
    pub fn prefetch(&mut self, keys: &[CellKey], pool: &rayon::ThreadPool) -> Result<()> {
        let mut seen = HashSet::new();
        let mut missing = Vec::new();
        for &k in keys {
            if !seen.insert(k) {
                continue;
            }
            if !self.cache.touch(&k) && missing.len() < self.cap_entries {
                missing.push(k);
            }
        }
        self.evict_to(self.cap_entries - missing.len());
        let (dir, m) = (&self.dir, self.m);
        let loaded: Vec<Result<Detail>> = pool.install(|| {
            missing
                .par_iter()
                .map(|&k| leaf_detail(dir, k, m))
                .collect()
        });
        for (k, d) in missing.into_iter().zip(loaded) {
            self.cache.insert(k, Arc::new(d?), self.per);
        }
        Ok(())
    }

    /// Leaf `k`'s detail in fixed point.
    pub fn get(&mut self, k: CellKey) -> Result<Arc<Detail>> {
        if let Some(d) = self.cache.peek(&k) {
            return Ok(Arc::clone(d));
        }
        let d = Arc::new(leaf_detail(&self.dir, k, self.m)?);
        self.cache.insert(k, Arc::clone(&d), self.per);
        Ok(d)
    }
}
