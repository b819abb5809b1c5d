//! A least-recently-used map bounded by the sum of its entries' weights (bytes): the order
//! both tiers evict in.
//!
//! Written here rather than taken from the `lru` crate because the bound is bytes, not
//! entries, and the disk tier seeds the order from file times: a `HashMap` plus a `BTreeMap`
//! from a recency tick to the key gives O(log n) for every operation in ~100 lines.

use std::collections::{BTreeMap, HashMap};
use std::hash::Hash;

struct Slot<V> {
    value: V,
    weight: u64,
    tick: u64,
}

/// An entry that left the map to make room (its value dropped).
pub(crate) struct Evicted<K> {
    pub key: K,
    pub weight: u64,
}

/// Invariant: `bytes == Σ weight <= capacity`; `order` holds exactly one tick per key, and a
/// larger tick is more recent.
pub(crate) struct ByteLru<K, V> {
    map: HashMap<K, Slot<V>>,
    order: BTreeMap<u64, K>,
    next_tick: u64,
    bytes: u64,
    capacity: u64,
}

impl<K: Hash + Eq + Clone, V> ByteLru<K, V> {
    pub fn new(capacity: u64) -> Self {
        Self {
            map: HashMap::new(),
            order: BTreeMap::new(),
            next_tick: 0,
            bytes: 0,
            capacity,
        }
    }

    pub fn len(&self) -> usize {
        self.map.len()
    }

    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    pub fn capacity(&self) -> u64 {
        self.capacity
    }

    pub fn contains(&self, key: &K) -> bool {
        self.map.contains_key(key)
    }

    fn tick(&mut self) -> u64 {
        self.next_tick += 1;
        self.next_tick
    }

    /// Stores `value` as the most recent entry, evicting the least recent ones until it fits.
    /// A value heavier than the capacity is refused (`Err` gives it back) and nothing changes.
    /// A key already present is replaced (its old value is not reported as evicted).
    pub fn insert(&mut self, key: K, value: V, weight: u64) -> Result<Vec<Evicted<K>>, V> {
        if weight > self.capacity {
            return Err(value);
        }
        self.remove(&key);
        let mut evicted = Vec::new();
        while self.bytes + weight > self.capacity {
            // bytes > 0 here, so an entry exists.
            match self.pop_lru() {
                Some(e) => evicted.push(e),
                None => break,
            }
        }
        let tick = self.tick();
        self.order.insert(tick, key.clone());
        self.map.insert(
            key,
            Slot {
                value,
                weight,
                tick,
            },
        );
        self.bytes += weight;
        Ok(evicted)
    }

    /// The value, made the most recent.
    pub fn get(&mut self, key: &K) -> Option<&V> {
        let tick = self.tick();
        let slot = self.map.get_mut(key)?;
        self.order.remove(&slot.tick);
        slot.tick = tick;
        self.order.insert(tick, key.clone());
        Some(&slot.value)
    }

    /// The value, recency unchanged.
    pub fn peek(&self, key: &K) -> Option<&V> {
        self.map.get(key).map(|s| &s.value)
    }

    /// The entry's weight, recency unchanged.
    pub fn weight(&self, key: &K) -> Option<u64> {
        self.map.get(key).map(|s| s.weight)
    }

    pub fn remove(&mut self, key: &K) -> Option<(V, u64)> {
        let slot = self.map.remove(key)?;
        self.order.remove(&slot.tick);
        self.bytes -= slot.weight;
        Some((slot.value, slot.weight))
    }

    pub fn pop_lru(&mut self) -> Option<Evicted<K>> {
        let (_, key) = self.order.pop_first()?;
        let slot = self
            .map
            .remove(&key)
            .expect("ByteLru: order and map hold the same keys");
        self.bytes -= slot.weight;
        Some(Evicted {
            key,
            weight: slot.weight,
        })
    }

    /// Sets the bound, evicting the least recent entries until the map fits it.
    pub fn set_capacity(&mut self, capacity: u64) -> Vec<Evicted<K>> {
        self.capacity = capacity;
        let mut evicted = Vec::new();
        while self.bytes > self.capacity {
            match self.pop_lru() {
                Some(e) => evicted.push(e),
                None => break,
            }
        }
        evicted
    }

    /// Keys from the least to the most recently used.
    #[cfg(test)]
    pub fn keys_lru_first(&self) -> Vec<K> {
        self.order.values().cloned().collect()
    }
}

#[cfg(test)]
mod tests;
