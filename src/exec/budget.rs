//! The memory budget: one counter of admitted bytes, shared by every stage.
//!
//! A stage computes the scratch a task needs, asks [`Budget::acquire`] for it, and gets a
//! [`Permit`] that gives the bytes back when dropped. A request that does not fit now waits on
//! a condition variable until permits are returned; it never polls. A request larger than the
//! whole budget can never fit and is an error that names both sizes.

use std::sync::{Arc, Condvar, Mutex};

use crate::error::{Error, Result};
use crate::exec::human_bytes;

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
                "{what} needs {} but the memory budget (--mem) is {}; raise --mem",
                human_bytes(bytes),
                human_bytes(self.total)
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
        assert!(e.contains("the count grid") && e.contains("--mem"), "{e}");
    }
}
