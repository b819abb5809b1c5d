//! Serialising built BLASes into the structure cache: as built (`--stream-host-cache
//! serialize`), when evicted (the default where host memory lies apart from the budget), and
//! what is resident or a host clone after the frames ([`StreamingRenderer::persist_cache`]).

use std::time::Instant;

use motu_ascache::{Blob, CacheKey, Tier};
use motu_vk::{SizeQueries, SERIALIZED_ALIGNMENT};
use rayon::prelude::*;

use super::super::clones::{HostCacheMode, TakenClone};
use super::super::skeleton::ms_since;
use super::super::store_policy::HostStorePolicy;
use super::super::transfer::{staged_runs, Transfer, TRANSFER_CAP_BYTES};
use super::super::StreamingRenderer;
use crate::error::Result;
use crate::scene::AccelStruct;

/// A built BLAS to serialise into the cache under `key`.
struct ToStore<'s> {
    /// Its id (`debug` logs name it).
    blas: usize,
    accel: &'s AccelStruct,
    key: CacheKey,
    /// Written through to the cache directory too (else kept in host memory only).
    to_disk: bool,
}

/// A BLAS to store: its id, key, and whether to the directory too ([`ToStore::to_disk`]).
type Keyed = (usize, CacheKey, bool);

/// A BLAS taken out of the renderer to serialise (at eviction, or by
/// [`StreamingRenderer::persist_cache`]), and where it goes back.
struct TakenOut {
    blas: usize,
    key: CacheKey,
    to_disk: bool,
    from: Home,
}

/// Where a taken-out BLAS lives: resident, or a host clone with its recency.
enum Home {
    Resident(AccelStruct),
    Clone(TakenClone),
}

impl Home {
    fn accel(&self) -> &AccelStruct {
        match self {
            Home::Resident(a) => a,
            Home::Clone(c) => c.accel(),
        }
    }
}

impl StreamingRenderer<'_> {
    /// Whether stores wait for eviction and the end of the frames (`HostCacheMode::Auto`): a
    /// BLAS is serialised when it is evicted (a later pass or frame may restore it), and the
    /// ones still resident after the last frame by [`Self::persist_cache`], after the image.
    /// `Serialize` stores as it builds, inside the frame (the behaviour before). Where
    /// host-visible memory counts against the budget (unified memory: lavapipe, integrated
    /// GPUs) the readback would need the room the eviction is making (a still frame at a
    /// quarter of the test island's peak skipped 7 of 9 such stores, against 3 skipped as
    /// built): stores stay at build time there, as clones stay off (`clones.rs`).
    fn stores_deferred(&self) -> bool {
        self.opts.host_cache_mode == HostCacheMode::Auto
            && !self.clones.on()
            && !self.heap.host_visible_counts_against_budget()
    }

    /// Serialises the newly built BLASes of `built` into the cache (those it does not hold
    /// yet, and, where only the host tier would keep them, those the store rule says pay:
    /// `store_policy.rs`), with `--stream-host-cache serialize`; by default stores wait for
    /// eviction ([`Self::store_evicted`]). A cache that cannot take them (no room for the
    /// readback) is skipped, counted.
    pub(in crate::stream) fn store_built(&mut self, built: &[(usize, AccelStruct)]) -> Result<()> {
        // With host clones the directory is written after the frames (`persist_cache`).
        if self.reuse.cache.is_none()
            || built.is_empty()
            || self.clones.on()
            || self.stores_deferred()
        {
            return Ok(());
        }
        let t = Instant::now();
        let mut todo: Vec<ToStore<'_>> = Vec::new();
        for (b, accel) in built {
            let Some((key, to_disk)) = self.store_key(*b, accel.size_bytes) else {
                continue;
            };
            todo.push(ToStore {
                blas: *b,
                accel,
                key,
                to_disk,
            });
        }
        if todo.is_empty() {
            return Ok(());
        }
        self.store_some(&todo)?;
        let bytes = todo.iter().map(|t| t.accel.size_bytes).sum();
        self.note_stored(todo.len() as u64, bytes, t);
        Ok(())
    }

    /// `count` structures of `bytes` stored in the frame since `t`: a sample of the store
    /// rule's store cost (`store_policy.rs`), and the frame's `cache_store_ms`.
    fn note_stored(&mut self, count: u64, bytes: u64, t: Instant) {
        self.reuse.estimates.store.add(count, bytes, ms_since(t));
        self.frame.stats_mut().cache_store_ms += ms_since(t);
    }

    /// BLAS `b`'s key where it is to be stored, and whether to the cache directory too: there
    /// when the directory lacks it and the restore rule says the next process would restore
    /// it (`restore_rule.rs`; every one with `--stream-host-cache-policy always`), else in host
    /// memory alone where the host tier's rule says its returns pay (`store_policy.rs`). Each
    /// skip is counted in the frame.
    fn store_key(&mut self, b: usize, size_bytes: u64) -> Option<(CacheKey, bool)> {
        let key = self.blas_key(b)?;
        let held = self.reuse.cache.as_ref().expect("attached");
        let host_room = held.cache.cache.host().capacity_bytes() > 0;
        let on_disk = match held.cache.cache.contains(&key) {
            Some(Tier::Host) => return None,
            Some(Tier::Disk) => true,
            None => false,
        };
        let always = self.reuse.policy == HostStorePolicy::Always;
        if !on_disk && self.cache_dir_writable() {
            let est = &self.reuse.estimates;
            if always || self.reuse.rule.write_pays(est, size_bytes) {
                return Some((key, true));
            }
            let st = self.frame.stats_mut();
            st.disk_store_skipped += 1;
            st.disk_store_skipped_bytes += size_bytes;
        }
        if !host_room || (on_disk && always) {
            return None;
        }
        let est = &self.reuse.estimates;
        if !always && !est.should_store(size_bytes, est.returned_before(b)) {
            let st = self.frame.stats_mut();
            st.host_cache_skipped_stores += 1;
            st.host_cache_skipped_store_bytes += size_bytes;
            return None;
        }
        Some((key, false))
    }

    /// Before BLASes `victims` are evicted (their structures still resident): serialises into
    /// the cache those it lacks, by the rules [`Self::store_built`] applies at build time,
    /// where stores are deferred ([`Self::stores_deferred`]). Counted in the frame as stores
    /// (`cache_store_ms`).
    pub(in crate::stream) fn store_evicted(&mut self, victims: &[usize]) -> Result<()> {
        if self.reuse.cache.is_none() || !self.stores_deferred() {
            return Ok(());
        }
        let t = Instant::now();
        let mut ids = Vec::with_capacity(victims.len());
        for &b in victims {
            let Some(size_bytes) = self.res.blas(b).map(|a| a.size_bytes) else {
                continue;
            };
            if let Some((key, to_disk)) = self.store_key(b, size_bytes) {
                ids.push((b, key, to_disk, size_bytes));
            }
        }
        if ids.is_empty() {
            return Ok(());
        }
        let bytes = ids.iter().map(|i| i.3).sum();
        let n = ids.len() as u64;
        let keyed: Vec<Keyed> = ids.into_iter().map(|(b, k, d, _)| (b, k, d)).collect();
        self.store_held(keyed)?;
        self.note_stored(n, bytes, t);
        Ok(())
    }

    fn cache_dir_writable(&self) -> bool {
        self.reuse
            .cache
            .as_ref()
            .is_some_and(|a| a.cache.cache.disk().is_some_and(|d| d.writable()))
    }

    /// Writes to the cache directory, serialised, every BLAS this renderer holds (resident or
    /// as a host clone) that the cache lacks. Stores wait for eviction by default and nothing
    /// is serialised while frames render with host clones, so a caller that wants the next
    /// process warm calls this after its last frame and after its image is out (the viewer
    /// at exit), or takes the cache ([`Self::take_cache`] calls this once: `motu render` after
    /// writing the image). Counted in [`StreamTotals`](super::StreamTotals) (`persisted_*`).
    /// With `--stream-host-cache serialize` the blobs were stored as they were built and this
    /// finds nothing to do.
    pub fn persist_cache(&mut self) -> Result<()> {
        if !self.cache_dir_writable() {
            return Ok(());
        }
        let t = Instant::now();
        let keyed = self.persist_list();
        // Counted into the totals below, not into a frame: none is rendering.
        let aside = self.frame.set_stats_aside();
        let stored = self.store_held(keyed);
        let counted = self.frame.put_stats_back(aside);
        let tot = &mut self.totals;
        let count = u64::from(counted.cache_stored);
        let bytes = counted.cache_stored_bytes;
        tot.persisted_blases += count;
        tot.persisted_bytes += bytes;
        tot.cache_stored += count;
        tot.cache_stored_bytes += bytes;
        if counted.cache_skipped > 0 {
            tracing::warn!(
                skipped = counted.cache_skipped,
                "structure cache: no room to serialise some structures after the frames; not cached"
            );
        }
        tot.store_serialize_ms += counted.store_serialize_ms;
        tot.store_copy_ms += counted.store_copy_ms;
        tot.store_put_ms += counted.store_put_ms;
        tot.transfer_batches += counted.transfer_batches;
        tot.transfer_allocations += counted.transfer_allocations;
        tot.transfer_staged_runs += counted.transfer_staged_runs;
        tot.persist_ms += ms_since(t);
        if let Ok(from_clones) = stored {
            tot.persisted_from_clone += from_clones;
        }
        // The next process starts from this one's rates (`restore_rule.rs`).
        self.reuse.save_rates();
        stored.map(|_| ())
    }

    /// What [`Self::persist_cache`] writes: the BLASes held (resident or as host clones) that
    /// the directory lacks and the restore rule says the next process would restore (the rest
    /// counted in the totals as `disk_store_skipped`).
    fn persist_list(&mut self) -> Vec<Keyed> {
        let always = self.reuse.policy == HostStorePolicy::Always;
        let mut keyed = Vec::new();
        for b in 0..self.view.blases.len() {
            if !self.topo.buildable(b) {
                continue;
            }
            let size_bytes = match (self.res.blas(b), self.clones.get(b)) {
                (Some(a), _) | (None, Some(a)) => a.size_bytes,
                (None, None) => continue,
            };
            let Some(key) = self.blas_key(b) else {
                continue;
            };
            let held = self.reuse.cache.as_ref().expect("attached");
            if held.cache.cache.contains(&key).is_some() {
                continue;
            }
            if always
                || self
                    .reuse
                    .rule
                    .write_pays(&self.reuse.estimates, size_bytes)
            {
                keyed.push((b, key, true));
            } else {
                self.totals.disk_store_skipped += 1;
                self.totals.disk_store_skipped_bytes += size_bytes;
            }
        }
        keyed
    }

    /// Serialises BLASes `keyed` (id, key) that this renderer holds, resident or as a host
    /// clone (others are passed over): each is taken out for the serialise copies and put
    /// back after, whatever happens. Returns how many came from clones.
    fn store_held(&mut self, keyed: Vec<Keyed>) -> Result<u64> {
        let mut taken: Vec<TakenOut> = Vec::with_capacity(keyed.len());
        for (b, key, to_disk) in keyed {
            let from = if let Some(a) = self.res.take_blas(b) {
                Home::Resident(a)
            } else if let Some(c) = self.clones.take(b) {
                Home::Clone(c)
            } else {
                continue;
            };
            taken.push(TakenOut {
                blas: b,
                key,
                to_disk,
                from,
            });
        }
        let from_clones = taken
            .iter()
            .filter(|t| matches!(t.from, Home::Clone(_)))
            .count() as u64;
        let todo: Vec<ToStore<'_>> = taken
            .iter()
            .map(|t| ToStore {
                blas: t.blas,
                accel: t.from.accel(),
                key: t.key,
                to_disk: t.to_disk,
            })
            .collect();
        let stored = if todo.is_empty() {
            Ok(())
        } else {
            self.store_some(&todo)
        };
        drop(todo);
        for TakenOut { blas, from, .. } in taken {
            match from {
                Home::Resident(a) => self.res.put_back_blas(blas, a),
                Home::Clone(c) => self.clones.put_back(blas, c),
            }
        }
        stored.map(|()| from_clones)
    }

    /// Serialises `todo`: their sizes in one query, then in batches of at most
    /// [`TRANSFER_CAP_BYTES`] (see `transfer.rs`).
    fn store_some(&mut self, todo: &[ToStore<'_>]) -> Result<()> {
        let ctx = self.ctx.clone();
        let t = Instant::now();
        let queries = SizeQueries::serialization(&ctx, todo.len() as u32)?;
        let targets: Vec<_> = todo.iter().map(|t| t.accel.target()).collect();
        let mut rec = ctx.record("serialised sizes")?;
        rec.barrier();
        rec.write_serialization_sizes(&targets, &queries)?;
        rec.submit_and_wait()?;
        let sizes = queries.read(todo.len() as u32)?;
        self.frame.stats_mut().store_serialize_ms += ms_since(t);
        self.store_sized(todo, &sizes)
    }

    /// Serialises `todo` (serialised sizes `sizes`) in one readback; above the transfer cap,
    /// or where the budget has no room for it, in halves (a single structure that does not fit
    /// is skipped, counted).
    fn store_sized(&mut self, todo: &[ToStore<'_>], sizes: &[u64]) -> Result<()> {
        let ctx = self.ctx.clone();
        let t = Instant::now();
        let align = |v: u64| v.div_ceil(SERIALIZED_ALIGNMENT) * SERIALIZED_ALIGNMENT;
        let total: u64 = sizes.iter().map(|&s| align(s)).sum();
        let halves = |s: &mut Self| -> Result<()> {
            let k = todo.len() / 2;
            s.store_sized(&todo[..k], &sizes[..k])?;
            s.store_sized(&todo[k..], &sizes[k..])
        };
        if total > TRANSFER_CAP_BYTES && todo.len() > 1 {
            return halves(self);
        }
        let readback = match self.transfer_buffer(Transfer::Readback, total) {
            Ok(buf) => buf,
            Err(motu_vk::VkError::Budget(why)) if todo.len() > 1 => {
                tracing::debug!(%why, n = todo.len(), "structure cache: serialising in halves");
                return halves(self);
            }
            Err(motu_vk::VkError::Budget(why)) => {
                // The cache is an optimisation: no room to read back is a skip, not a failure.
                let blas = todo.first().map(|t| t.blas);
                tracing::debug!(%why, ?blas, "structure cache: no room to serialise; not cached");
                self.frame.stats_mut().cache_skipped += 1;
                return Ok(());
            }
            Err(e) => return Err(e.into()),
        };
        let staging = self.transfer_staging();
        // The blobs' memory is paged in on the pool's threads while the device serialises
        // (what is not ready in time is allocated fresh by the copy, as before).
        let pool = self
            .reuse
            .cache
            .as_ref()
            .expect("attached")
            .cache
            .cache
            .pool()
            .clone();
        let lens: Vec<usize> = sizes.iter().map(|&s| s as usize).collect();
        pool.prefault(&lens);
        let result = (|| -> Result<Vec<Blob>> {
            let base = readback.device_address()?;
            let mut offsets = Vec::with_capacity(todo.len());
            let mut at = 0u64;
            for &size in sizes {
                offsets.push(at);
                at += align(size);
            }
            let mut rec = ctx.record("serialise blases")?;
            match &staging {
                None => {
                    for (t, &off) in todo.iter().zip(&offsets) {
                        rec.serialize_acceleration_structure(t.accel.target(), base.offset(off))?;
                    }
                }
                Some(st) => {
                    // Serialised into device memory, then one bus copy a run (transfer.rs).
                    let st_base = st.device_address()?;
                    for run in staged_runs(&offsets, sizes, st.size_bytes()) {
                        for i in run.blobs.clone() {
                            let dst = run.address(offsets[i], st_base, base);
                            rec.serialize_acceleration_structure(todo[i].accel.target(), dst)?;
                        }
                        if run.staged {
                            rec.barrier();
                            rec.copy_buffer(st, 0, &readback, run.start_bytes, run.len_bytes)?;
                            rec.barrier();
                            self.frame.stats_mut().transfer_staged_runs += 1;
                        }
                    }
                }
            }
            rec.barrier();
            rec.submit_and_wait()?;
            self.frame.stats_mut().store_serialize_ms += ms_since(t);
            let copy = Instant::now();
            // Each blob copied once, straight into the buffer the cache keeps (no zero fill;
            // paged in already where the pool had one), on all cores: one thread's reads of
            // pinned memory held storing to about 1 GB/s.
            let blobs = readback.with_mapped_mut(0, at as usize, |bytes| {
                let bytes: &[u8] = bytes;
                offsets
                    .par_iter()
                    .zip(sizes)
                    .map(|(&off, &size)| pool.copy(&bytes[off as usize..][..size as usize]))
                    .collect::<Vec<_>>()
            })?;
            self.frame.stats_mut().store_copy_ms += ms_since(copy);
            Ok(blobs)
        })();
        self.put_back_transfer(Transfer::Readback, readback);
        if let Some(st) = staging {
            self.put_back_transfer(Transfer::Staging, st);
        }
        let blobs = result?;
        let put = Instant::now();
        let a = self.reuse.cache.as_mut().expect("attached");
        let st = self.frame.stats_mut();
        for (t, blob) in todo.iter().zip(blobs) {
            st.cache_stored_bytes += blob.len() as u64;
            st.cache_stored += 1;
            if t.to_disk {
                a.cache.cache.put(t.key, blob);
            } else {
                a.cache.cache.put_host(t.key, blob);
            }
        }
        // The burst is over: page in memory for the next one while the device works.
        a.cache.cache.pool().refill();
        self.frame.stats_mut().store_put_ms += ms_since(put);
        Ok(())
    }
}
