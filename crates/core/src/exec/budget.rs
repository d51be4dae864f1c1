//! The memory budget: one counter of admitted bytes, shared by every stage.
//!
//! A stage computes the scratch a task needs, asks [`Budget::acquire`] for it, and gets a
//! [`Permit`] that gives the bytes back when dropped. A request that does not fit now waits on
//! a condition variable until permits are returned; it never polls. A request larger than the
//! whole budget can never fit and is an error that names both sizes.
//!
//! How the budget is shared is written once, in [`Share`]: every long-lived consumer (a cache,
//! a counting grid, a wave of buffers) takes its slice through [`Budget::share`], so the
//! slices of one stage can be read and summed in one place.

use std::sync::{Arc, Condvar, Mutex};

use crate::error::{Error, Result, Setting};
use crate::exec::human_bytes;

/// The slices of the budget that long-lived consumers size themselves by, as fractions of the
/// whole. Slices of one stage may be live at once, so within a stage they add up to at most
/// the whole; what remains is admitted per task (a solve, a tile, a chunk) through permits.
/// Reconstruct's coarse scratch is live alone (before the caches), and the plan picks the
/// coarse ratio so that its solution, the point cache and one leaf solve then fit too.
///
/// | stage | consumer | slice |
/// | --- | --- | --- |
/// | ingest | point chunks of a read wave | 1/2 |
/// | ingest | the counting grid (two copies while merging) | 1/4 |
/// | ingest | scatter buffers before a flush | 1/8 |
/// | normals | the cache of decoded neighbour cells | 1/4 |
/// | normals | the cells of one estimation wave | 1/3 |
/// | reconstruct | the coarse solve's scratch, while it runs (with the leaf pass, picks the coarse ratio) | 2/3 |
/// | reconstruct | the cache of sorted store cells (at most 128 MiB) | 1/4 |
/// | reconstruct | the cache of leaf details read back for tiles | 1/6 |
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Share {
    /// Ingest: the point chunks decoded in one wave of reads.
    IngestChunks,
    /// Ingest: the per-cell counting grid.
    CountingGrid,
    /// Ingest: the scatter stage's record buffers.
    ScatterBuffers,
    /// Normals: the cache of decoded neighbour cells.
    NormalsCellCache,
    /// Normals: the cells estimated in one wave.
    NormalsWave,
    /// Reconstruct: the coarse global grid.
    CoarseGrid,
    /// Reconstruct: the cache of sorted store cells.
    PointCache,
    /// Reconstruct: the cache of leaf details.
    DetailCache,
}

impl Share {
    /// The slice as a fraction of the whole budget: numerator, denominator.
    pub const fn fraction(self) -> (u64, u64) {
        match self {
            Share::IngestChunks => (1, 2),
            Share::CountingGrid => (1, 4),
            Share::ScatterBuffers => (1, 8),
            Share::NormalsCellCache => (1, 4),
            Share::NormalsWave => (1, 3),
            Share::CoarseGrid => (2, 3),
            Share::PointCache => (1, 4),
            Share::DetailCache => (1, 6),
        }
    }

    /// The slice of a budget of `total` bytes.
    pub const fn of(self, total: u64) -> u64 {
        let (num, den) = self.fraction();
        (total as u128 * num as u128 / den as u128) as u64
    }
}

/// A memory budget in bytes.
#[derive(Debug)]
pub struct Budget {
    total: u64,
    used: Mutex<(u64, u64)>,
    freed: Condvar,
}

impl Budget {
    /// A budget of `total` bytes.
    pub fn new(total: u64) -> Arc<Budget> {
        Arc::new(Budget {
            total,
            used: Mutex::new((0, 0)),
            freed: Condvar::new(),
        })
    }

    /// The whole budget.
    pub fn total(&self) -> u64 {
        self.total
    }

    /// The bytes of slice `share` of this budget ([`Share`]).
    pub fn share(&self, share: Share) -> u64 {
        share.of(self.total)
    }

    /// Bytes admitted now.
    pub fn used(&self) -> u64 {
        self.lock().0
    }

    /// Most bytes ever admitted at once.
    pub fn peak(&self) -> u64 {
        self.lock().1
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, (u64, u64)> {
        // A poisoned lock only means a holder panicked; the counter itself stays consistent.
        self.used.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Admit `bytes`, waiting until they fit. `what` names the request in the error raised
    /// when it exceeds the whole budget.
    pub fn acquire(self: &Arc<Self>, bytes: u64, what: &str) -> Result<Permit> {
        if bytes > self.total {
            return Err(Error::Usage(format!(
                "{what} needs {} but the memory budget ({mem}) is {}; raise {mem}",
                human_bytes(bytes),
                human_bytes(self.total),
                mem = Setting::Mem
            )));
        }
        let mut g = self.lock();
        while g.0 + bytes > self.total {
            g = self.freed.wait(g).unwrap_or_else(|p| p.into_inner());
        }
        g.0 += bytes;
        g.1 = g.1.max(g.0);
        Ok(Permit {
            budget: Arc::clone(self),
            bytes,
        })
    }

    /// Admit `bytes` now or fail: for a caller whose thread holds the permits that would have
    /// to be freed first, where waiting would wait forever. The error names `what`, its size
    /// and what is free.
    pub fn acquire_now(self: &Arc<Self>, bytes: u64, what: &str) -> Result<Permit> {
        if let Some(p) = self.try_acquire(bytes) {
            return Ok(p);
        }
        if bytes > self.total {
            return self.acquire(bytes, what);
        }
        Err(Error::Usage(format!(
            "{what} needs {} but only {} of the memory budget ({mem} {}) is free at that point; raise {mem}",
            human_bytes(bytes),
            human_bytes(self.total.saturating_sub(self.used())),
            human_bytes(self.total),
            mem = Setting::Mem
        )))
    }

    /// Admit `bytes` if they fit now.
    pub fn try_acquire(self: &Arc<Self>, bytes: u64) -> Option<Permit> {
        let mut g = self.lock();
        if g.0 + bytes > self.total {
            return None;
        }
        g.0 += bytes;
        g.1 = g.1.max(g.0);
        Some(Permit {
            budget: Arc::clone(self),
            bytes,
        })
    }

    fn release(&self, bytes: u64) {
        let mut g = self.lock();
        g.0 -= bytes;
        drop(g);
        self.freed.notify_all();
    }
}

/// Admitted bytes, returned to the budget on drop.
#[derive(Debug)]
pub struct Permit {
    budget: Arc<Budget>,
    bytes: u64,
}

impl Permit {
    /// Bytes held.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }
}

impl Drop for Permit {
    fn drop(&mut self) {
        self.budget.release(self.bytes);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn waits_until_released() {
        let b = Budget::new(100);
        let p = b.acquire(80, "a").unwrap();
        assert!(b.try_acquire(30).is_none());
        let b2 = Arc::clone(&b);
        let h = std::thread::spawn(move || b2.acquire(30, "b").map(|p| p.bytes()));
        std::thread::sleep(Duration::from_millis(50));
        assert_eq!(b.used(), 80);
        drop(p);
        assert_eq!(h.join().unwrap().unwrap(), 30);
        assert_eq!(b.used(), 0);
        assert_eq!(b.peak(), 80);
    }

    #[test]
    fn too_big_is_an_error() {
        let b = Budget::new(100);
        let e = b.acquire(101, "the count grid").unwrap_err().to_string();
        assert!(e.contains("the count grid") && e.contains("`mem`"), "{e}");
    }
}
