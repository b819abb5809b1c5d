//! Eviction bookkeeping for streaming: least-recently-visible first, never a pinned item.

use std::collections::{BTreeSet, HashMap};
use std::fmt;

use crate::kind::ByteSize;

/// A resident item (a BLAS or child TLAS with its geometry), chosen by the caller.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ItemId(pub u32);

impl fmt::Display for ItemId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "item {}", self.0)
    }
}

/// Not enough unpinned bytes to free `bytes_needed`: the current pass alone does not fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error(
    "cannot free {} by eviction: {} resident, of which {} are pinned by the current pass and {} \
     evictable",
    ByteSize(*bytes_needed),
    ByteSize(*resident_bytes),
    ByteSize(*pinned_bytes),
    ByteSize(*evictable_bytes)
)]
pub struct NotEnough {
    /// Bytes asked for.
    pub bytes_needed: u64,
    /// Bytes of unpinned resident items.
    pub evictable_bytes: u64,
    /// Bytes of pinned items.
    pub pinned_bytes: u64,
    /// Bytes of all resident items.
    pub resident_bytes: u64,
}

/// Misuse of the residency table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ResidencyError {
    /// Inserted twice.
    #[error("{0} is already resident")]
    AlreadyResident(ItemId),
}

#[derive(Debug, Clone, Copy)]
struct Entry {
    bytes: u64,
    last_visible_frame: u64,
    pinned: bool,
}

/// Resident items ordered by the last frame in which they were visible.
///
/// Pinned items ("needed by the current pass") are taken out of the LRU order while pinned, so
/// victim choice walks only evictable items: O(k log n) for k victims.
/// [`unpin_all`](Self::unpin_all) at the end of a pass puts them back (O(p log n), paid once
/// per pin).
#[derive(Debug, Default)]
pub struct Residency {
    items: HashMap<ItemId, Entry>,
    /// Unpinned items: (last visible frame, id); oldest first.
    lru: BTreeSet<(u64, ItemId)>,
    pinned: Vec<ItemId>,
    resident_bytes: u64,
    pinned_bytes: u64,
}

impl Residency {
    /// An empty table.
    pub fn new() -> Self {
        Self::default()
    }

    /// Records a newly resident item of `bytes`, visible in `frame`.
    pub fn insert(&mut self, id: ItemId, bytes: u64, frame: u64) -> Result<(), ResidencyError> {
        if self.items.contains_key(&id) {
            return Err(ResidencyError::AlreadyResident(id));
        }
        self.items.insert(
            id,
            Entry {
                bytes,
                last_visible_frame: frame,
                pinned: false,
            },
        );
        self.lru.insert((frame, id));
        self.resident_bytes += bytes;
        Ok(())
    }

    /// Marks an item visible in `frame` (a frame older than the recorded one is ignored).
    /// Returns false if the item is not resident.
    pub fn mark_visible(&mut self, id: ItemId, frame: u64) -> bool {
        let Some(entry) = self.items.get_mut(&id) else {
            return false;
        };
        if frame > entry.last_visible_frame {
            if !entry.pinned {
                self.lru.remove(&(entry.last_visible_frame, id));
                self.lru.insert((frame, id));
            }
            entry.last_visible_frame = frame;
        }
        true
    }

    /// Pins an item for the current pass: it is never chosen as a victim until
    /// [`unpin_all`](Self::unpin_all). Returns false if the item is not resident.
    pub fn pin(&mut self, id: ItemId) -> bool {
        let Some(entry) = self.items.get_mut(&id) else {
            return false;
        };
        if !entry.pinned {
            entry.pinned = true;
            self.lru.remove(&(entry.last_visible_frame, id));
            self.pinned.push(id);
            self.pinned_bytes += entry.bytes;
        }
        true
    }

    /// Ends the current pass: every item becomes evictable again.
    pub fn unpin_all(&mut self) {
        for id in self.pinned.drain(..) {
            if let Some(entry) = self.items.get_mut(&id) {
                if entry.pinned {
                    entry.pinned = false;
                    self.lru.insert((entry.last_visible_frame, id));
                }
            }
        }
        self.pinned_bytes = 0;
    }

    /// Forgets an item (after the caller freed its memory). Returns its bytes.
    pub fn remove(&mut self, id: ItemId) -> Option<u64> {
        let entry = self.items.remove(&id)?;
        if entry.pinned {
            // Its stale id in `pinned` is skipped by `unpin_all`.
            self.pinned_bytes -= entry.bytes;
        } else {
            self.lru.remove(&(entry.last_visible_frame, id));
        }
        self.resident_bytes -= entry.bytes;
        Some(entry.bytes)
    }

    /// Least-recently-visible unpinned items whose bytes sum to at least `bytes_needed`
    /// (oldest first; ties by id). Chooses nothing if `bytes_needed` is 0. Never chooses a
    /// pinned item; fails without choosing anything if unpinned items cannot cover the need.
    pub fn choose_victims(&self, bytes_needed: u64) -> Result<Vec<ItemId>, NotEnough> {
        let evictable_bytes = self.resident_bytes - self.pinned_bytes;
        if evictable_bytes < bytes_needed {
            return Err(NotEnough {
                bytes_needed,
                evictable_bytes,
                pinned_bytes: self.pinned_bytes,
                resident_bytes: self.resident_bytes,
            });
        }
        let mut victims = Vec::new();
        let mut freed = 0u64;
        for &(_, id) in &self.lru {
            if freed >= bytes_needed {
                break;
            }
            freed += self.items.get(&id).map_or(0, |e| e.bytes);
            victims.push(id);
        }
        Ok(victims)
    }

    /// Like [`choose_victims`](Self::choose_victims), but also treats items for which
    /// `also_pinned` is true as pinned (a caller-held set of what the current pass needs).
    /// O(k log n) plus the skipped items.
    pub fn choose_victims_excluding(
        &self,
        bytes_needed: u64,
        also_pinned: impl Fn(ItemId) -> bool,
    ) -> Result<Vec<ItemId>, NotEnough> {
        let mut victims = Vec::new();
        let mut freed = 0u64;
        let mut skipped_bytes = 0u64;
        for &(_, id) in &self.lru {
            if freed >= bytes_needed {
                return Ok(victims);
            }
            let bytes = self.items.get(&id).map_or(0, |e| e.bytes);
            if also_pinned(id) {
                skipped_bytes += bytes;
            } else {
                freed += bytes;
                victims.push(id);
            }
        }
        if freed >= bytes_needed {
            return Ok(victims);
        }
        Err(NotEnough {
            bytes_needed,
            evictable_bytes: freed,
            pinned_bytes: self.pinned_bytes + skipped_bytes,
            resident_bytes: self.resident_bytes,
        })
    }

    /// [`choose_victims`](Self::choose_victims) and removes them; returns (id, bytes) pairs.
    pub fn evict(&mut self, bytes_needed: u64) -> Result<Vec<(ItemId, u64)>, NotEnough> {
        let victims = self.choose_victims(bytes_needed)?;
        Ok(victims
            .into_iter()
            .filter_map(|id| self.remove(id).map(|bytes| (id, bytes)))
            .collect())
    }

    /// Whether the item is resident.
    pub fn contains(&self, id: ItemId) -> bool {
        self.items.contains_key(&id)
    }

    /// Whether the item is pinned for the current pass.
    pub fn is_pinned(&self, id: ItemId) -> bool {
        self.items.get(&id).is_some_and(|e| e.pinned)
    }

    /// Last frame an item was visible in.
    pub fn last_visible_frame(&self, id: ItemId) -> Option<u64> {
        self.items.get(&id).map(|e| e.last_visible_frame)
    }

    /// Resident items.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// Whether nothing is resident.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    /// Bytes of all resident items.
    pub fn resident_bytes(&self) -> u64 {
        self.resident_bytes
    }

    /// Bytes of pinned items.
    pub fn pinned_bytes(&self) -> u64 {
        self.pinned_bytes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(items: &[(u32, u64, u64)]) -> Residency {
        let mut residency = Residency::new();
        for &(id, bytes, frame) in items {
            residency.insert(ItemId(id), bytes, frame).unwrap();
        }
        residency
    }

    #[test]
    fn victims_are_least_recently_visible() {
        let mut residency = table(&[(1, 100, 5), (2, 100, 1), (3, 100, 3), (4, 100, 0)]);
        assert_eq!(
            residency.choose_victims(150).unwrap(),
            vec![ItemId(4), ItemId(2)]
        );
        assert_eq!(residency.choose_victims(100).unwrap(), vec![ItemId(4)]);
        assert_eq!(residency.choose_victims(0).unwrap(), vec![]);
        // item 4 seen again: now 2 is the oldest.
        assert!(residency.mark_visible(ItemId(4), 6));
        assert_eq!(residency.choose_victims(1).unwrap(), vec![ItemId(2)]);
        // an older frame does not make it older again.
        assert!(residency.mark_visible(ItemId(4), 2));
        assert_eq!(residency.last_visible_frame(ItemId(4)), Some(6));
        assert!(!residency.mark_visible(ItemId(9), 7));
    }

    #[test]
    fn pinned_items_are_never_victims() {
        let mut residency = table(&[(1, 100, 0), (2, 50, 1), (3, 70, 2)]);
        assert!(residency.pin(ItemId(1)));
        assert!(residency.pin(ItemId(1)));
        assert_eq!(residency.pinned_bytes(), 100);
        assert_eq!(
            residency.choose_victims(60).unwrap(),
            vec![ItemId(2), ItemId(3)]
        );
        let err = residency.choose_victims(121).unwrap_err();
        assert_eq!(
            err,
            NotEnough {
                bytes_needed: 121,
                evictable_bytes: 120,
                pinned_bytes: 100,
                resident_bytes: 220
            }
        );
        let message = err.to_string();
        for number in ["121 bytes", "220 bytes", "100 bytes", "120 bytes"] {
            assert!(message.contains(number), "{message}");
        }
        // visible while pinned: the new frame counts once unpinned.
        assert!(residency.mark_visible(ItemId(1), 9));
        residency.unpin_all();
        assert_eq!(residency.pinned_bytes(), 0);
        assert_eq!(
            residency.choose_victims(220).unwrap(),
            vec![ItemId(2), ItemId(3), ItemId(1)]
        );
    }

    #[test]
    fn caller_pinned_set_is_respected() {
        let mut residency = table(&[(1, 100, 0), (2, 50, 1), (3, 70, 2), (4, 10, 3)]);
        residency.pin(ItemId(4));
        let needed_now = |id: ItemId| id == ItemId(2);
        assert_eq!(
            residency.choose_victims_excluding(150, needed_now).unwrap(),
            vec![ItemId(1), ItemId(3)]
        );
        assert_eq!(
            residency.choose_victims_excluding(171, needed_now),
            Err(NotEnough {
                bytes_needed: 171,
                evictable_bytes: 170,
                pinned_bytes: 60,
                resident_bytes: 230
            })
        );
        assert_eq!(
            residency.choose_victims_excluding(0, needed_now).unwrap(),
            vec![]
        );
    }

    #[test]
    fn evict_removes_and_accounts() {
        let mut residency = table(&[(1, 10, 0), (2, 20, 1), (3, 30, 2)]);
        residency.pin(ItemId(3));
        assert_eq!(residency.remove(ItemId(3)), Some(30));
        assert_eq!(residency.pinned_bytes(), 0);
        residency.unpin_all();
        assert_eq!(
            residency.evict(15).unwrap(),
            vec![(ItemId(1), 10), (ItemId(2), 20)]
        );
        assert!(residency.is_empty());
        assert_eq!(residency.resident_bytes(), 0);
        assert_eq!(
            residency
                .insert(ItemId(5), 1, 0)
                .and(residency.insert(ItemId(5), 1, 0)),
            Err(ResidencyError::AlreadyResident(ItemId(5)))
        );
        // re-inserting a removed-while-pinned item works and is not pinned.
        residency.insert(ItemId(3), 30, 4).unwrap();
        assert!(!residency.is_pinned(ItemId(3)));
    }
}
