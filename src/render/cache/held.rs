//! The bricks one [`Accessor`](super::Accessor) holds: the working
//! set of one tile, so that its rays go back to the shared, locked cache
//! once per brick and tile rather than once per brick and ray.
//!
//! The rays of a tile cross the same bricks in the same order. A short
//! list of the most recent bricks (the 8 of an earlier version) loses that
//! sequence to each ray whenever it is longer than the list: every ray
//! then evicts the bricks the next ray starts with, and every brick
//! change takes the shared cache's lock (1.56 million trips in a 1024^2
//! composite frame of the real CT, 1.5 per ray, a tenth of the frame's
//! time on two threads; 5,158 with [`Held`]). [`Held`] keeps up to
//! [`HELD`] bricks in an open-addressing table (one multiplicative hash,
//! linear probing, at most half full) and lets them all go when it is
//! full: a tile that crosses more bricks than that starts again from the
//! shared cache.
//! docs/BENCHMARKS.md, "Bricks held per tile".

use std::sync::Arc;

/// Slots of the table (a power of two).
const SLOTS: usize = 256;

/// Bricks held at most: half the slots, so a probe meets an empty slot
/// within a few steps.
pub const HELD: usize = SLOTS / 2;

/// An empty slot's id (brick ids are indices below the brick count).
const EMPTY: u64 = u64::MAX;

/// A slot index that holds nothing: [`Held::get`] gives `None`.
pub const NONE: usize = usize::MAX;

/// Up to [`HELD`] items by `u64` id.
pub struct Held<T> {
    ids: Vec<u64>,
    items: Vec<Option<Arc<T>>>,
    len: usize,
}

impl<T> Held<T> {
    /// An empty table.
    pub fn new() -> Held<T> {
        Held {
            ids: vec![EMPTY; SLOTS],
            items: (0..SLOTS).map(|_| None).collect(),
            len: 0,
        }
    }

    /// The slot where the probe for `id` starts (Fibonacci hashing: brick
    /// ids that differ by a row or a slab of bricks land apart).
    #[inline]
    fn home(id: u64) -> usize {
        (id.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> (64 - SLOTS.trailing_zeros())) as usize
    }

    /// The slot holding `id`, if it is held.
    #[inline]
    pub fn find(&self, id: u64) -> Option<usize> {
        let mut i = Self::home(id);
        // Terminates: at most HELD < SLOTS slots are taken.
        loop {
            match self.ids[i] {
                x if x == id => return Some(i),
                EMPTY => return None,
                _ => i = (i + 1) & (SLOTS - 1),
            }
        }
    }

    /// Holds `item` as `id` (which is not held; not [`EMPTY`]) and returns
    /// its slot. When [`HELD`] items are held, all are let go first.
    pub fn insert(&mut self, id: u64, item: Arc<T>) -> usize {
        debug_assert!(id != EMPTY && self.find(id).is_none());
        if self.len == HELD {
            self.ids.fill(EMPTY);
            self.items.fill(None);
            self.len = 0;
        }
        let mut i = Self::home(id);
        while self.ids[i] != EMPTY {
            i = (i + 1) & (SLOTS - 1);
        }
        self.ids[i] = id;
        self.items[i] = Some(item);
        self.len += 1;
        i
    }

    /// The item in `slot` ([`NONE`] or an empty slot: `None`).
    #[inline(always)]
    pub fn get(&self, slot: usize) -> Option<&T> {
        self.items.get(slot)?.as_deref()
    }

    /// [`Held::get`] as the shared handle.
    pub fn get_arc(&self, slot: usize) -> Option<&Arc<T>> {
        self.items.get(slot)?.as_ref()
    }

    /// How many items are held.
    #[cfg(test)]
    fn len(&self) -> usize {
        self.len
    }
}

impl<T> Default for Held<T> {
    fn default() -> Self {
        Held::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::collections::HashMap;

    proptest! {
        /// Against a model: a map that is cleared whenever it would grow
        /// beyond HELD. Ids are drawn from a small range (many repeats)
        /// or anywhere below EMPTY.
        #[test]
        fn held_behaves_as_a_map_cleared_when_full(
            ids in prop::collection::vec(
                prop_oneof![0u64..300, 0u64..EMPTY, Just(EMPTY - 1)], 1..2000),
        ) {
            let mut h = Held::new();
            let mut model: HashMap<u64, u64> = HashMap::new();
            for id in ids {
                match h.find(id) {
                    Some(s) => {
                        prop_assert_eq!(h.get(s).copied(), model.get(&id).copied());
                    }
                    None => {
                        prop_assert!(!model.contains_key(&id));
                        if model.len() == HELD {
                            model.clear();
                        }
                        model.insert(id, id ^ 0x5a5a);
                        let s = h.insert(id, Arc::new(id ^ 0x5a5a));
                        prop_assert_eq!(h.find(id), Some(s));
                        prop_assert_eq!(h.get(s).copied(), Some(id ^ 0x5a5a));
                    }
                }
                prop_assert_eq!(h.len(), model.len());
            }
            for (&id, &v) in &model {
                let s = h.find(id);
                prop_assert!(s.is_some());
                prop_assert_eq!(h.get(s.unwrap_or(NONE)).copied(), Some(v));
            }
        }
    }

    #[test]
    fn a_full_table_lets_all_go() {
        let mut h = Held::new();
        for id in 0..HELD as u64 {
            h.insert(id, Arc::new(id));
        }
        assert_eq!(h.len(), HELD);
        let kept = Arc::new(7u64);
        let held_before = h.get(h.find(7).unwrap_or(NONE)).copied();
        assert_eq!(held_before, Some(7));
        let s = h.insert(1000, kept.clone());
        assert_eq!(h.len(), 1);
        assert_eq!(h.find(7), None);
        assert_eq!(h.get(s).copied(), Some(7));
        assert_eq!(h.get(NONE), None);
        // The table's reference and ours: nothing else keeps it alive.
        assert_eq!(Arc::strong_count(&kept), 2);
    }
}
