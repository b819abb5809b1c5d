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
mod tests;
