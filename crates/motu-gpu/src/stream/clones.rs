//! Evicted BLASes kept as clones in host memory (`--stream-host-cache clone`, opt-in: measured
//! slower than serialising on an H100, see `HostCacheMode::Auto`).
//!
//! Serialising every built BLAS for the structure cache held the H200's cold frames (island
//! 0.63 at 8 GiB: 13.3 s of a 24 s first frame storing 12.9 GB at ~1 GB/s through the host's
//! copies). A clone needs no host work: when a BLAS is evicted, the device copies it
//! (`vkCmdCopyAccelerationStructureKHR`, `CLONE`) into a structure whose buffer is in host
//! memory, outside the VRAM budget, and when it is needed again it is cloned back. A clone is
//! the structure that was built, so images cannot change. Only evicted BLASes are copied (a
//! still frame whose last pass keeps its structures copies none of those), a BLAS evicted again
//! keeps its clone, and the clones are bounded by the host cache's bytes (`--host-cache`),
//! least recently used first. The on-disk tier still takes serialised structures: those are
//! written after the frames ([`StreamingRenderer::persist_cache`]), from the resident
//! structures and the clones.
//!
//! Where host-visible memory counts against the budget (unified memory: lavapipe, integrated
//! GPUs), a clone would take the room its eviction made, so the serialised host tier of
//! `cache.rs` is used instead.

use std::collections::BTreeSet;
use std::time::Instant;

use motu_alloc::MemoryClass;
use motu_vk::{AsCopyMode, AsLevel, AsTarget};

use super::skeleton::ms_since;
use super::StreamingRenderer;
use crate::error::Result;
use crate::scene::AccelStruct;

/// How evicted structures are kept in host memory (`--stream-host-cache`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum HostCacheMode {
    /// Serialised (measured faster than clones on an H100, island 0.63: BENCHMARKS.md, session
    /// 34), but not inside the frame where no pass needs it: a BLAS is serialised when it is
    /// evicted (a later pass may restore it), and the ones resident after the last frame are
    /// written to the cache directory after the image
    /// ([`StreamingRenderer::persist_cache`](super::StreamingRenderer::persist_cache)), so a
    /// still frame's cold start does not store its structures before its pixels.
    #[default]
    Auto,
    /// Device-side clones in host memory (outside the budget only on a discrete GPU; on unified
    /// memory a clone takes the room its eviction made).
    Clone,
    /// Serialised copies (`vkCmdCopyAccelerationStructureToMemoryKHR`) of the BLASes built, in
    /// host memory and written through to the cache directory as they are built, inside the
    /// frame (every one where a directory is written; else those the store rule picks,
    /// `store_policy.rs`): the behaviour before `Auto` deferred them.
    Serialize,
}

impl HostCacheMode {
    pub fn name(self) -> &'static str {
        match self {
            HostCacheMode::Auto => "auto",
            HostCacheMode::Clone => "clone",
            HostCacheMode::Serialize => "serialize",
        }
    }
}

/// What [`StreamingRenderer::restore_cached`] (host clones, then the serialised tiers)
/// restored, and what is left to build.
pub(super) struct Restored {
    /// (BLAS id, its restored structure).
    pub built: Vec<(usize, AccelStruct)>,
    /// The BLASes no cached copy restored.
    pub rest: Vec<usize>,
}

/// The clones held (see the module docs).
#[derive(Default)]
pub(super) struct HostClones {
    /// Whether evicted BLASes are cloned (resolved from the mode when a cache is attached).
    on: bool,
    bound_bytes: u64,
    /// Per BLAS: its clone, and its last use in `order`.
    held: Vec<Option<(AccelStruct, u64)>>,
    /// (last use, BLAS) of every clone: the least recently used first.
    order: BTreeSet<(u64, usize)>,
    tick: u64,
    bytes: u64,
}

/// A clone [`HostClones::take`]n out for a moment, with its recency: the holder gives it back
/// through [`HostClones::put_back`], so the clones keep no state for what is out.
pub(super) struct TakenClone {
    accel: AccelStruct,
    last_use: u64,
}

impl TakenClone {
    pub(super) fn accel(&self) -> &AccelStruct {
        &self.accel
    }
}

impl HostClones {
    /// Clones on, for `blases` BLASes, holding at most `bound_bytes`.
    pub(super) fn enable(&mut self, blases: usize, bound_bytes: u64) {
        self.on = bound_bytes > 0;
        self.bound_bytes = bound_bytes;
        self.held.resize_with(blases, || None);
    }

    pub(super) fn on(&self) -> bool {
        self.on
    }

    pub(super) fn holds(&self, b: usize) -> bool {
        self.held.get(b).is_some_and(Option::is_some)
    }

    pub(super) fn bytes(&self) -> u64 {
        self.bytes
    }

    /// BLAS `b`'s clone, made the most recently used.
    fn touch(&mut self, b: usize) -> Option<&AccelStruct> {
        self.tick += 1;
        let tick = self.tick;
        let (a, last) = self.held.get_mut(b)?.as_mut()?;
        self.order.remove(&(*last, b));
        *last = tick;
        self.order.insert((tick, b));
        Some(a)
    }

    fn insert(&mut self, b: usize, a: AccelStruct) {
        self.tick += 1;
        self.bytes += a.size_bytes;
        self.order.insert((self.tick, b));
        self.held[b] = Some((a, self.tick));
    }

    /// Takes out least recently used clones until `size_bytes` more fit under the bound.
    fn make_room(&mut self, size_bytes: u64) -> Vec<AccelStruct> {
        let mut out = Vec::new();
        while self.bytes + size_bytes > self.bound_bytes {
            let Some((_, b)) = self.order.pop_first() else {
                break;
            };
            if let Some((a, _)) = self.held[b].take() {
                self.bytes -= a.size_bytes;
                out.push(a);
            }
        }
        out
    }

    /// Takes BLAS `b`'s clone out for a moment ([`Self::put_back`] returns it unchanged in
    /// recency and bytes).
    pub(super) fn take(&mut self, b: usize) -> Option<TakenClone> {
        let (accel, last_use) = self.held.get_mut(b)?.take()?;
        self.order.remove(&(last_use, b));
        self.bytes -= accel.size_bytes;
        Some(TakenClone { accel, last_use })
    }

    /// Puts BLAS `b`'s clone back where [`Self::take`] took it from.
    pub(super) fn put_back(&mut self, b: usize, taken: TakenClone) {
        let TakenClone { accel, last_use } = taken;
        self.bytes += accel.size_bytes;
        self.order.insert((last_use, b));
        self.held[b] = Some((accel, last_use));
    }

    pub(super) fn get(&self, b: usize) -> Option<&AccelStruct> {
        self.held.get(b)?.as_ref().map(|(a, _)| a)
    }
}

impl StreamingRenderer<'_> {
    /// Before BLASes `victims` are evicted: keeps them for their return. With clones, clones
    /// into host memory those resident without a clone yet, in one submission (a clone that
    /// does not fit, host memory refused or larger than the bound, is skipped, counted: the
    /// BLAS is rebuilt when it returns); else serialises them into the structure cache where
    /// stores wait for eviction (`cache.rs`, `store_evicted`).
    pub(super) fn keep_evicted(&mut self, victims: &[usize]) -> Result<()> {
        if !self.clones.on() {
            return self.store_evicted(victims);
        }
        let t = Instant::now();
        let todo: Vec<usize> = victims
            .iter()
            .copied()
            .filter(|&b| self.res.has_blas(b))
            .filter(|&b| !self.clones.holds(b))
            .collect();
        if todo.is_empty() {
            return Ok(());
        }
        let ctx = self.ctx.clone();
        let mut made: Vec<(usize, AccelStruct)> = Vec::with_capacity(todo.len());
        for b in todo {
            let size = self.res.blas(b).map_or(0, |a| a.size_bytes);
            if size > self.clones.bound_bytes {
                self.frame.stats_mut().clone_skipped += 1;
                continue;
            }
            for old in self.clones.make_room(size) {
                old.release(&mut self.heap);
            }
            match AccelStruct::new_in(
                &ctx,
                &mut self.heap,
                &format!("blas {b} (host clone)"),
                size,
                AsLevel::Bottom,
                MemoryClass::HostVisible,
            ) {
                Ok(a) => made.push((b, a)),
                Err(e) => {
                    tracing::debug!(blas = b, %e, "host clone refused; rebuilt when needed");
                    self.frame.stats_mut().clone_skipped += 1;
                }
            }
        }
        if made.is_empty() {
            return Ok(());
        }
        let made = self.clone_copies("clone evicted blases to host", made, |s, b| {
            s.res.blas(b).expect("resident").target()
        })?;
        for (b, a) in made {
            self.frame.stats_mut().cloned_blases += 1;
            self.frame.stats_mut().cloned_bytes += a.size_bytes;
            self.clones.insert(b, a);
        }
        self.frame.stats_mut().clone_ms += ms_since(t);
        Ok(())
    }

    /// Clones back into device memory what the host holds of BLASes `ids`: returns the
    /// restored structures and the ids left (to the serialised tiers, then to building). No
    /// room for a copy leaves that BLAS to be built, counted; only a device error fails.
    pub(super) fn restore_clones(&mut self, ids: &[usize], evict: bool) -> Result<Restored> {
        if !self.clones.on() || ids.iter().all(|&b| !self.clones.holds(b)) {
            return Ok(Restored {
                built: Vec::new(),
                rest: ids.to_vec(),
            });
        }
        let t = Instant::now();
        let ctx = self.ctx.clone();
        let mut rest = Vec::new();
        let mut made: Vec<(usize, AccelStruct)> = Vec::new();
        for &b in ids {
            let Some(size) = self.clones.get(b).map(|a| a.size_bytes) else {
                rest.push(b);
                continue;
            };
            let label = format!("blas {b} (from host clone)");
            let alloc = self.maybe_evicting(evict, |s| {
                AccelStruct::new(&ctx, &mut s.heap, &label, size, AsLevel::Bottom)
                    .map_err(Into::into)
            });
            match alloc {
                Ok(a) => made.push((b, a)),
                Err(crate::error::GpuError::Budget(why)) => {
                    tracing::debug!(blas = b, %why, "no room to restore a host clone; building");
                    self.frame.stats_mut().restore_skipped += 1;
                    rest.push(b);
                }
                Err(e) => {
                    for (_, a) in made {
                        a.release(&mut self.heap);
                    }
                    return Err(e);
                }
            }
        }
        if made.is_empty() {
            return Ok(Restored { built: made, rest });
        }
        let made = self.clone_copies("clone blases back from host", made, |s, b| {
            s.clones.touch(b).expect("held").target()
        })?;
        self.frame.stats_mut().restored_from_clone += made.len() as u32;
        self.frame.stats_mut().restored_from_host += made.len() as u32;
        self.frame.stats_mut().restore_ms += ms_since(t);
        rest.sort_unstable();
        Ok(Restored { built: made, rest })
    }

    /// Copies into each new structure of `made` (BLAS id, destination) its source
    /// `source(self, id)`, in one submission (`label`); on failure the new structures are
    /// released and nothing is kept.
    fn clone_copies(
        &mut self,
        label: &str,
        made: Vec<(usize, AccelStruct)>,
        mut source: impl FnMut(&mut Self, usize) -> AsTarget,
    ) -> Result<Vec<(usize, AccelStruct)>> {
        let ctx = self.ctx.clone();
        let copied = (|| -> Result<()> {
            let mut rec = ctx.record(label)?;
            rec.barrier();
            for (b, dst) in &made {
                let src = source(self, *b);
                rec.copy_acceleration_structure(src, dst.target(), AsCopyMode::Clone)?;
            }
            rec.barrier();
            rec.submit_and_wait()?;
            Ok(())
        })();
        if let Err(e) = copied {
            for (_, a) in made {
                a.release(&mut self.heap);
            }
            return Err(e);
        }
        Ok(made)
    }
}
