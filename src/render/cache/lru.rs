//! The shared cache's entries in recency order under a byte budget.

/// Least-recently-used map under a byte budget, for keys below a bound
/// known up front (a brick id times 2, plus 1 for a stand-in): O(1) per
/// lookup, insertion and eviction, and no hashing. Keys index a table of
/// slots; the slots form a doubly linked list in recency order. A lookup
/// runs under the shared cache's lock on every brick an accessor's own
/// few do not hold (docs/BENCHMARKS.md, "Brick cache lookups: an O(1)
/// LRU": the recency-ordered B-tree this replaces took 15 % of a cold
/// frame).
pub(super) struct Lru<V> {
    /// key -> slot in `slots`, or [`NIL`].
    index: Vec<u32>,
    slots: Vec<Slot<V>>,
    /// Slots of evicted entries, for reuse.
    free: Vec<u32>,
    /// Most and least recently used slots ([`NIL`] when empty).
    newest: u32,
    oldest: u32,
    bytes: usize,
    pub(super) peak: usize,
    /// Keys ever inserted, one bit each.
    seen: Vec<u64>,
}

/// No slot.
const NIL: u32 = u32::MAX;

struct Slot<V> {
    key: u64,
    value: Option<V>,
    bytes: usize,
    /// Towards the newest and the oldest entry.
    newer: u32,
    older: u32,
}

impl<V: Clone> Lru<V> {
    /// An empty map for keys `0..keys`.
    pub(super) fn new(keys: u64) -> Lru<V> {
        Lru {
            index: vec![NIL; keys as usize],
            slots: Vec::new(),
            free: Vec::new(),
            newest: NIL,
            oldest: NIL,
            bytes: 0,
            peak: 0,
            seen: vec![0; (keys as usize).div_ceil(64)],
        }
    }

    /// Takes slot `i` out of the recency list.
    fn unlink(&mut self, i: u32) {
        let (newer, older) = (self.slots[i as usize].newer, self.slots[i as usize].older);
        match newer {
            NIL => self.newest = older,
            n => self.slots[n as usize].older = older,
        }
        match older {
            NIL => self.oldest = newer,
            o => self.slots[o as usize].newer = newer,
        }
    }

    /// Puts slot `i` at the newest end of the recency list.
    fn push_newest(&mut self, i: u32) {
        let s = &mut self.slots[i as usize];
        s.newer = NIL;
        s.older = self.newest;
        match self.newest {
            NIL => self.oldest = i,
            n => self.slots[n as usize].newer = i,
        }
        self.newest = i;
    }

    /// The value of `key`, now the most recently used.
    pub(super) fn get(&mut self, key: u64) -> Option<V> {
        let i = *self.index.get(key as usize)?;
        if i == NIL {
            return None;
        }
        if self.newest != i {
            self.unlink(i);
            self.push_newest(i);
        }
        self.slots[i as usize].value.clone()
    }

    /// Inserts `key` (absent, below the bound) holding `bytes`, first
    /// evicting least recently used entries until it fits in `budget`; a
    /// value larger than the whole budget is not kept.
    pub(super) fn insert(&mut self, key: u64, v: V, bytes: usize, budget: usize) {
        let k = key as usize;
        if k >= self.index.len() || self.index[k] != NIL {
            return;
        }
        self.seen[k / 64] |= 1 << (k % 64);
        if bytes > budget {
            return;
        }
        while self.bytes + bytes > budget && self.oldest != NIL {
            let o = self.oldest;
            self.unlink(o);
            let s = &mut self.slots[o as usize];
            self.index[s.key as usize] = NIL;
            s.value = None;
            self.bytes -= s.bytes;
            self.free.push(o);
        }
        let slot = Slot {
            key,
            value: Some(v),
            bytes,
            newer: NIL,
            older: NIL,
        };
        let i = match self.free.pop() {
            Some(i) => {
                self.slots[i as usize] = slot;
                i
            }
            None => {
                self.slots.push(slot);
                (self.slots.len() - 1) as u32
            }
        };
        self.push_newest(i);
        self.index[k] = i;
        self.bytes += bytes;
        self.peak = self.peak.max(self.bytes);
    }

    /// Keys ever inserted that satisfy `f`.
    pub(super) fn count_seen(&self, f: impl Fn(u64) -> bool) -> u64 {
        let mut n = 0;
        for (w, &bits) in self.seen.iter().enumerate() {
            let mut b = bits;
            while b != 0 {
                let k = w as u64 * 64 + b.trailing_zeros() as u64;
                n += u64::from(f(k));
                b &= b - 1;
            }
        }
        n
    }

    /// The keys held, oldest first.
    #[cfg(test)]
    fn by_age(&self) -> Vec<u64> {
        let mut v = Vec::new();
        let mut i = self.oldest;
        while i != NIL {
            v.push(self.slots[i as usize].key);
            i = self.slots[i as usize].newer;
        }
        v
    }
}
#[cfg(test)]
mod tests {
    use super::Lru;
    use proptest::prelude::*;

    proptest! {
        /// Against a model that keeps (key, bytes) in recency order and
        /// evicts from the front: same contents after every operation,
        /// never above the budget.
        #[test]
        fn lru_matches_a_recency_list(
            budget in 1usize..64,
            ops in proptest::collection::vec((any::<bool>(), 0u64..12, 1usize..20), 1..200),
        ) {
            let mut lru: Lru<u64> = Lru::new(12);
            let mut model: Vec<(u64, usize)> = Vec::new();
            for (is_get, key, bytes) in ops {
                let pos = model.iter().position(|e| e.0 == key);
                if is_get || pos.is_some() {
                    let got = lru.get(key);
                    prop_assert_eq!(got, pos.map(|_| key * 10));
                    if let Some(p) = pos {
                        let e = model.remove(p);
                        model.push(e);
                    }
                } else {
                    lru.insert(key, key * 10, bytes, budget);
                    if bytes <= budget {
                        while model.iter().map(|e| e.1).sum::<usize>() + bytes > budget {
                            model.remove(0);
                        }
                        model.push((key, bytes));
                    }
                }
                let model_age: Vec<u64> = model.iter().map(|e| e.0).collect();
                prop_assert_eq!(lru.by_age(), model_age);
                let held = (0..12).filter(|&k| lru.index[k as usize] != super::NIL).count();
                prop_assert_eq!(held, model.len());
                prop_assert_eq!(lru.bytes, model.iter().map(|e| e.1).sum::<usize>());
                prop_assert!(lru.bytes <= budget && lru.peak <= budget);
            }
        }
    }
}
