//! One least-recently-used cache bounded in bytes, for every stage that keeps decoded data
//! (store cells, neighbour cells, leaf details, the GPU's resident leaf grids).
//!
//! Entries live in a slab linked in recency order, so a hit, an insert and an eviction are
//! O(1); a hash map finds an entry's slot. Each entry carries the bytes it holds, given by the
//! caller. After an insert the cache evicts least recently used entries until its bytes fit the
//! capacity, but never the entry just inserted, so one entry larger than the capacity is still
//! held (callers admit their cache's capacity through the budget, and an entry that large is
//! already admitted by its own permit while it is built). Evicted entries are returned, so that
//! a caller that owns a resource per entry (a slot of a device buffer) can reuse it.
//!
//! Only speed may depend on what a cache holds, never an output's bytes: every caller reads
//! a missing entry back from its source.

use std::collections::HashMap;
use std::hash::Hash;

const NIL: usize = usize::MAX;

struct Slot<K, V> {
    entry: Option<(K, V)>,
    bytes: u64,
    /// Towards the most recently used end.
    newer: usize,
    /// Towards the least recently used end.
    older: usize,
}

/// A byte-bounded LRU cache; see the [module docs](self).
pub struct Lru<K, V> {
    index: HashMap<K, usize>,
    slots: Vec<Slot<K, V>>,
    free: Vec<usize>,
    /// Most recently used.
    newest: usize,
    /// Least recently used.
    oldest: usize,
    bytes: u64,
    capacity: u64,
}

impl<K: Hash + Eq + Clone, V> Lru<K, V> {
    /// An empty cache holding at most `capacity_bytes` (but always the newest entry).
    pub fn new(capacity_bytes: u64) -> Lru<K, V> {
        Lru {
            index: HashMap::new(),
            slots: Vec::new(),
            free: Vec::new(),
            newest: NIL,
            oldest: NIL,
            bytes: 0,
            capacity: capacity_bytes,
        }
    }

    /// Entries held.
    pub fn len(&self) -> usize {
        self.index.len()
    }

    /// Whether nothing is held.
    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    /// Bytes held: the sum of the entries' declared bytes.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// The capacity in bytes.
    pub fn capacity(&self) -> u64 {
        self.capacity
    }

    /// Whether `key` is held (its recency is left alone).
    pub fn contains(&self, key: &K) -> bool {
        self.index.contains_key(key)
    }

    /// The value of `key`, made the most recently used.
    pub fn get(&mut self, key: &K) -> Option<&V> {
        let i = *self.index.get(key)?;
        self.unlink(i);
        self.push_newest(i);
        self.slots[i].entry.as_ref().map(|(_, v)| v)
    }

    /// The value of `key`, its recency left alone.
    pub fn peek(&self, key: &K) -> Option<&V> {
        let i = *self.index.get(key)?;
        self.slots[i].entry.as_ref().map(|(_, v)| v)
    }

    /// Make `key` the most recently used; false if it is not held.
    pub fn touch(&mut self, key: &K) -> bool {
        self.get(key).is_some()
    }

    /// Hold `value` under `key` as the most recently used entry, replacing any value it had,
    /// then evict least recently used entries (never this one) until the bytes fit. Returns
    /// the evicted entries, oldest first, and the replaced value's entry if there was one.
    pub fn insert(&mut self, key: K, value: V, bytes: u64) -> Vec<(K, V)> {
        let mut out = Vec::new();
        if let Some(old) = self.remove(&key) {
            out.push((key.clone(), old));
        }
        let slot = Slot {
            entry: Some((key.clone(), value)),
            bytes,
            newer: NIL,
            older: NIL,
        };
        let i = match self.free.pop() {
            Some(i) => {
                self.slots[i] = slot;
                i
            }
            None => {
                self.slots.push(slot);
                self.slots.len() - 1
            }
        };
        self.index.insert(key, i);
        self.bytes += bytes;
        self.push_newest(i);
        self.evict_over(&mut out);
        out
    }

    /// Change the capacity and evict least recently used entries (never the newest) until the
    /// bytes fit; returns them, oldest first.
    pub fn set_capacity(&mut self, capacity_bytes: u64) -> Vec<(K, V)> {
        self.capacity = capacity_bytes;
        let mut out = Vec::new();
        self.evict_over(&mut out);
        out
    }

    /// Remove and return the least recently used entry.
    pub fn pop_oldest(&mut self) -> Option<(K, V)> {
        if self.oldest == NIL {
            return None;
        }
        Some(self.take(self.oldest))
    }

    /// Remove `key`; its value if it was held.
    pub fn remove(&mut self, key: &K) -> Option<V> {
        let i = *self.index.get(key)?;
        Some(self.take(i).1)
    }

    /// The keys from least to most recently used.
    pub fn keys_oldest_first(&self) -> Vec<K> {
        let mut out = Vec::with_capacity(self.len());
        let mut i = self.oldest;
        while i != NIL {
            if let Some((k, _)) = &self.slots[i].entry {
                out.push(k.clone());
            }
            i = self.slots[i].newer;
        }
        out
    }

    fn evict_over(&mut self, out: &mut Vec<(K, V)>) {
        while self.bytes > self.capacity && self.oldest != self.newest {
            out.push(self.take(self.oldest));
        }
    }

    fn take(&mut self, i: usize) -> (K, V) {
        self.unlink(i);
        let slot = &mut self.slots[i];
        self.bytes -= slot.bytes;
        slot.bytes = 0;
        let (k, v) = slot
            .entry
            .take()
            .unwrap_or_else(|| unreachable!("a linked slot holds an entry"));
        self.index.remove(&k);
        self.free.push(i);
        (k, v)
    }

    fn unlink(&mut self, i: usize) {
        let (newer, older) = (self.slots[i].newer, self.slots[i].older);
        if newer == NIL {
            self.newest = older;
        } else {
            self.slots[newer].older = older;
        }
        if older == NIL {
            self.oldest = newer;
        } else {
            self.slots[older].newer = newer;
        }
        self.slots[i].newer = NIL;
        self.slots[i].older = NIL;
    }

    fn push_newest(&mut self, i: usize) {
        self.slots[i].older = self.newest;
        self.slots[i].newer = NIL;
        if self.newest != NIL {
            self.slots[self.newest].newer = i;
        }
        self.newest = i;
        if self.oldest == NIL {
            self.oldest = i;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn evicts_the_least_recently_used_first() {
        let mut c = Lru::new(30);
        assert!(c.insert(1, "a", 10).is_empty());
        assert!(c.insert(2, "b", 10).is_empty());
        assert!(c.insert(3, "c", 10).is_empty());
        assert_eq!(c.get(&1), Some(&"a"));
        let out = c.insert(4, "d", 10);
        assert_eq!(out, vec![(2, "b")]);
        assert_eq!(c.keys_oldest_first(), vec![3, 1, 4]);
        assert_eq!(c.bytes(), 30);
        assert_eq!(c.peek(&3), Some(&"c"));
        assert_eq!(c.keys_oldest_first(), vec![3, 1, 4], "peek keeps recency");
    }

    #[test]
    fn keeps_the_newest_even_when_it_alone_is_over() {
        let mut c = Lru::new(10);
        c.insert(1, 1, 5);
        let out = c.insert(2, 2, 50);
        assert_eq!(out, vec![(1, 1)]);
        assert_eq!(c.len(), 1);
        assert_eq!(c.bytes(), 50);
        assert_eq!(c.insert(3, 3, 1), vec![(2, 2)]);
    }

    #[test]
    fn replacing_and_shrinking_return_what_left() {
        let mut c = Lru::new(100);
        c.insert("x", 1, 40);
        c.insert("y", 2, 40);
        assert_eq!(c.insert("x", 3, 50), vec![("x", 1)]);
        assert_eq!(c.bytes(), 90);
        assert_eq!(c.set_capacity(60), vec![("y", 2)]);
        assert_eq!(c.pop_oldest(), Some(("x", 3)));
        assert!(c.is_empty() && c.bytes() == 0 && c.pop_oldest().is_none());
    }

    #[test]
    fn matches_a_naive_model_over_random_operations() {
        // A VecDeque model of the same policy, driven by a fixed-seed LCG.
        let mut model: std::collections::VecDeque<(u32, u64)> = Default::default();
        let mut c: Lru<u32, u64> = Lru::new(1000);
        let mut s = 12345u64;
        for _ in 0..20_000 {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let k = ((s >> 33) % 64) as u32;
            let b = (s >> 20) % 200 + 1;
            if (s >> 60) < 6 {
                let hit = c.get(&k).copied();
                let pos = model.iter().position(|e| e.0 == k);
                assert_eq!(hit, pos.map(|p| model[p].1));
                if let Some(p) = pos {
                    let e = model.remove(p).unwrap();
                    model.push_back(e);
                }
            } else {
                c.insert(k, b, b);
                if let Some(p) = model.iter().position(|e| e.0 == k) {
                    model.remove(p);
                }
                model.push_back((k, b));
                while model.iter().map(|e| e.1).sum::<u64>() > 1000 && model.len() > 1 {
                    model.pop_front();
                }
            }
            let keys: Vec<u32> = model.iter().map(|e| e.0).collect();
            assert_eq!(c.keys_oldest_first(), keys);
            assert_eq!(c.bytes(), model.iter().map(|e| e.1).sum::<u64>());
        }
    }
}
