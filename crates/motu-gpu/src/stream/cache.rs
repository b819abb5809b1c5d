//! Built BLASes that survive eviction and the process (`--host-cache`, `--as-cache`).
//!
//! A triangle BLAS the streamer builds is serialised (Vulkan's `SERIALIZE` copy of the
//! compacted structure) into a [`motu_ascache::AsCache`]: a byte-bounded LRU in host memory,
//! written through to a cache directory; by default when it is evicted, or after the frames
//! and their image for those still resident, not inside the frame (`cache/store.rs`). It is
//! written to the directory where restoring it in the next process would beat building it, by
//! this device's measured rates (`restore_rule.rs`; unknown rates: every BLAS, as before);
//! otherwise the host tier alone may keep it, and only the BLASes whose expected restores save
//! more than their store costs are serialised for it (`--stream-host-cache-policy measured`,
//! the rule and its self-measured rates in `store_policy.rs`). When the BLAS is needed again,
//! after an eviction or in a later process, it is deserialised by copy instead of rebuilt from
//! its meshes where the restore rule says that is faster (its directory reads run beside the
//! group's mesh uploads, `cache/reads.rs`; the meshes are streamed as before: hits still
//! shade from them). Keys name the scene's content (the
//! package's checksums), the BLAS and its records, the build flags and the driver; the driver
//! judges each entry's compatibility data before it is used, so a cache of another device or
//! driver is a miss with a warning (`motu-ascache`), never a wrong structure. A deserialised
//! structure is the one that was built, so images cannot change.
//!
//! The state lives in one owned part, [`Reuse`]: which BLASes were ever built (so rebuilds are
//! counted whether or not a cache is attached) and the cache with its keys.
//!
//! Invariants ([`Reuse`], fields private to this file): a BLAS once built (or restored) stays
//! counted as built ([`Reuse::mark_built`] never unmarks); a key is made once per BLAS and
//! names its records, the scene's content and the driver, so an entry is only ever used for
//! the structure it was made from; at most one transfer buffer is kept per direction
//! ([`Reuse::keep_transfer`] hands back the one it replaces, to free).

use std::collections::HashSet;
use std::time::Instant;

use motu_abi::blob::{BlobReader, BlobWriter};
use motu_ascache::{
    AsCache, Blob, CacheKey, CacheKeyBuilder, CacheStats, Tier, SERIALIZED_HEADER_BYTES,
};
use motu_vk::{AsLevel, HeapBuffer, SerializedHeader, SERIALIZED_ALIGNMENT};
use rayon::prelude::*;

use super::clones::{HostCacheMode, Restored};
use super::proxy_boxes::{self, Box6};
use super::restore_rule::RestoreRule;
use super::skeleton::ms_since;
use super::store_policy::{self, HostStorePolicy, StoreEstimator, StorePolicyStats};
use super::transfer::{staged_runs, Transfer, TransferBuffers, TRANSFER_CAP_BYTES};
use super::StreamingRenderer;
use crate::error::{GpuError, Result};
use crate::scene::AccelStruct;

/// A structure cache for a [`StreamingRenderer`] ([`StreamingRenderer::attach_cache`]): the
/// cache tiers and the identity of the scene content its keys are made from.
pub struct StructureCache {
    cache: AsCache,
    scene_identity: Vec<u8>,
    /// The host tier's bound as given: a renderer keeping clones takes it for them and sets
    /// the serialised tier's to 0 (`clones.rs`); the next renderer starts from it again.
    host_bytes: u64,
}

impl StructureCache {
    /// `scene_identity`: bytes that change whenever any mesh or record of the scene does (a
    /// package's chunk and section checksums).
    pub fn new(cache: AsCache, scene_identity: &[u8]) -> StructureCache {
        StructureCache {
            host_bytes: cache.host().capacity_bytes(),
            cache,
            scene_identity: scene_identity.to_vec(),
        }
    }

    pub fn stats(&self) -> CacheStats {
        self.cache.stats()
    }

    pub(super) fn scene_identity(&self) -> &[u8] {
        &self.scene_identity
    }

    pub(super) fn cache_mut(&mut self) -> &mut AsCache {
        &mut self.cache
    }
}

/// What the streamer keeps to reuse built structures: see the module docs.
pub(super) struct Reuse {
    /// Which BLASes were built (or restored) before, how often they return, and the rates
    /// the host tier's store rule decides from (`store_policy.rs`).
    estimates: StoreEstimator,
    /// Which cached BLASes are restored and which built ones written to the directory, by
    /// this device's rates (`restore_rule.rs`).
    rule: RestoreRule,
    policy: HostStorePolicy,
    cache: Option<Attached>,
    /// Host-visible buffers kept between store and restore batches (`transfer.rs`).
    transfer: TransferBuffers,
}

struct Attached {
    cache: StructureCache,
    /// Per BLAS, its key once made.
    keys: Vec<Option<CacheKey>>,
    driver: String,
}

/// A cache entry found for BLAS `blas`: its serialised structure and that blob's header.
struct Hit {
    blas: usize,
    blob: Blob,
    header: SerializedHeader,
}

/// A BLAS looked up in the cache, its key, and its entry with the tier that held it (`None`:
/// neither tier).
type Found = (usize, CacheKey, Option<(Blob, Tier)>);

/// Keys' format: bump when what a key covers changes.
const KEY_DOMAIN: &str = "motu-blas-v1";

impl Reuse {
    /// `fixed`: decide from these rates alone (`--stream-rates`, `restore_rule.rs`).
    pub(super) fn new(
        blases: usize,
        policy: HostStorePolicy,
        fixed: Option<motu_ascache::DeviceRates>,
    ) -> Reuse {
        let mut estimates = StoreEstimator::new(blases, store_policy::PRIOR);
        let rule = match fixed {
            Some(rates) => {
                let rule = RestoreRule::fixed(rates);
                estimates.fix_prior(rule.prior());
                rule
            }
            None => RestoreRule::default(),
        };
        Reuse {
            estimates,
            rule,
            policy,
            cache: None,
            transfer: TransferBuffers::default(),
        }
    }

    pub(super) fn stats(&self) -> Option<CacheStats> {
        self.cache.as_ref().map(|a| a.cache.stats())
    }

    /// BLAS `b` was just built (or restored): whether it had been before (a rebuild, or a
    /// return the store rule counts).
    pub(super) fn mark_built(&mut self, b: usize) -> bool {
        self.estimates.note_made(b)
    }

    /// A batch of `blases` BLAS builds (with compaction), `bytes` of structures together,
    /// took `ms`: a sample of the store rule's build cost.
    pub(super) fn note_builds(&mut self, blases: usize, bytes: u64, ms: f64) {
        self.estimates.build.add(blases as u64, bytes, ms);
    }

    /// The store rule and its estimates now (`stream.totals.store_policy`).
    pub(super) fn policy_stats(&self) -> StorePolicyStats {
        let mut st = self.estimates.stats(self.policy);
        self.rule.add_stats(&mut st);
        st
    }

    /// Writes this run's rates to the cache directory for the next process
    /// (`restore_rule.rs`); nothing without a writable directory, or with fixed rates (which
    /// it did not measure).
    pub(super) fn save_rates(&mut self) {
        if self.rule.is_fixed() {
            return;
        }
        let Some(a) = self.cache.as_ref() else { return };
        let Some(disk) = a.cache.cache.disk() else {
            return;
        };
        if disk.save_device_rates(&a.driver, &self.rule.to_save(&self.estimates)) {
            self.rule.note_saved();
        }
    }

    /// The transfer buffer kept for `t`, taken out (`None`: none kept).
    pub(super) fn take_transfer(&mut self, t: Transfer) -> Option<HeapBuffer> {
        self.transfer.slot(t).take()
    }

    /// Keeps `buf` for `t`'s next batch; returns the buffer it replaces, for the caller to
    /// free.
    pub(super) fn keep_transfer(&mut self, t: Transfer, buf: HeapBuffer) -> Option<HeapBuffer> {
        self.transfer.slot(t).replace(buf)
    }
}

impl StreamingRenderer<'_> {
    /// Keeps every BLAS built from now on in `cache` and restores from it instead of
    /// rebuilding (see the module docs).
    pub fn attach_cache(&mut self, mut cache: StructureCache) {
        let n = self.view.blases.len();
        let host_bytes = cache.host_bytes;
        let clone = match self.opts.host_cache_mode {
            HostCacheMode::Clone => true,
            HostCacheMode::Serialize => false,
            // Serialised: on an H100 (island 0.63 at 8 GiB, one warm machine) a cold start took
            // 25.4 s to the PNG serialising and 37.2 s cloning (clones into host memory ran at
            // ~4 GB/s at eviction), a warm one 19.7 against 25.0 s (BENCHMARKS.md, session 34);
            // at eviction and after the frames (`stores_deferred`).
            HostCacheMode::Auto => false,
        };
        let auto = self.opts.host_cache_mode == HostCacheMode::Auto
            && !self.heap.host_visible_counts_against_budget();
        self.totals.host_cache_mode = match (host_bytes, clone, auto) {
            (0, _, _) => "off",
            (_, true, _) => "clone",
            (_, false, true) => "deferred",
            (_, false, false) => "serialize",
        };
        if clone && host_bytes > 0 {
            // The host's bytes go to clones; serialised blobs then only pass through to the
            // directory (`clones.rs`).
            self.clones.enable(n, host_bytes);
            cache.cache.host_mut().set_capacity_bytes(0);
        } else {
            cache.cache.host_mut().set_capacity_bytes(host_bytes);
        }
        let driver = self.ctx.driver_identity();
        // The rates the last process measured on this device, where the directory has them
        // (fixed rates, `--stream-rates`, ignore them).
        if let Some(disk) = cache.cache.disk().filter(|_| !self.reuse.rule.is_fixed()) {
            self.reuse.rule = RestoreRule::from_file(disk.device_rates(&driver));
            self.reuse.estimates.set_prior(self.reuse.rule.prior());
        }
        self.reuse.cache = Some(Attached {
            cache,
            keys: vec![None; n],
            driver,
        });
    }

    /// Detaches the structure cache (with what it holds) for another renderer of the same
    /// scene, e.g. the viewer's after an element toggle: its entries stay warm and its pending
    /// disk writes go on instead of being waited for.
    pub fn take_cache(&mut self) -> Option<StructureCache> {
        // What only this renderer holds (host clones, resident structures) goes to the
        // directory first; a failure is a warning (a cache never fails a render).
        if let Err(e) = self.persist_cache() {
            tracing::warn!(error = %e, "structure cache: writing this renderer's structures failed");
        }
        self.reuse.cache.take().map(|a| a.cache)
    }

    /// The structure cache's counts (`None`: no cache attached).
    pub fn cache_stats(&self) -> Option<CacheStats> {
        self.reuse.stats()
    }

    fn blas_key(&mut self, b: usize) -> Option<CacheKey> {
        let view = self.view;
        let flags = self.build_opts.blas_build.name();
        let compact = self.build_opts.compact;
        let a = self.reuse.cache.as_mut()?;
        if let Some(k) = a.keys[b] {
            return Some(k);
        }
        let rec = &view.blases[b];
        let geometries = &view.geometries[rec.item_base as usize..][..rec.item_count as usize];
        let mut k = CacheKeyBuilder::new(KEY_DOMAIN);
        k.bytes(&a.cache.scene_identity)
            .u32(b as u32)
            .bytes(bytemuck::bytes_of(rec))
            .bytes(bytemuck::cast_slice(geometries))
            .str(flags)
            .u32(u32::from(compact))
            .str(&a.driver);
        let key = k.finish();
        a.keys[b] = Some(key);
        Some(key)
    }

    /// Restores what the cache holds of BLASes `ids` (their meshes resident), where the restore
    /// rule says it pays (`restore_rule.rs`; `ahead`: decided and read while the meshes loaded,
    /// `cache/reads.rs`): returns the restored structures and the ids left to build. Anything
    /// that goes wrong (a bad entry, no room for the copy) leaves those BLASes to be built, as
    /// without a cache; only a device error fails.
    pub(super) fn restore_cached(
        &mut self,
        ids: &[usize],
        evict: bool,
        ahead: Option<GroupReads>,
    ) -> Result<Restored> {
        if self.reuse.cache.is_none() || ids.is_empty() {
            return Ok(Restored {
                built: Vec::new(),
                rest: ids.to_vec(),
            });
        }
        // Host clones first (`clones.rs`): a device-side copy, no host work.
        let from_clones = self.restore_clones(ids, evict)?;
        if from_clones.rest.is_empty() {
            return Ok(from_clones);
        }
        let mut restored =
            self.restore_serialized(&from_clones.rest, evict, ahead.unwrap_or_default())?;
        restored.built.extend(from_clones.built);
        Ok(restored)
    }

    /// [`Self::restore_cached`] from the serialised tiers (host memory, then the directory).
    fn restore_serialized(
        &mut self,
        ids: &[usize],
        evict: bool,
        ahead: GroupReads,
    ) -> Result<Restored> {
        let t = Instant::now();
        let wanted: HashSet<usize> = ids.iter().copied().collect();
        let covered = ahead.covered();
        let mut rest: Vec<usize> = ahead
            .declined()
            .iter()
            .copied()
            .filter(|b| wanted.contains(b))
            .collect();
        // Those not decided ahead: host hits, unknown keys, and any a clone did not restore.
        let mut keyed: Vec<(usize, CacheKey)> = Vec::with_capacity(ids.len());
        for &b in ids.iter().filter(|b| !covered.contains(b)) {
            match self.decide_restore(b) {
                Decision::Restore(key, _) | Decision::Unknown(key) => keyed.push((b, key)),
                Decision::Build => rest.push(b),
            }
        }
        let mut found: Vec<Found> = self
            .finish_group_reads(ahead, &wanted)
            .into_iter()
            .map(|(b, k, blob)| (b, k, blob.map(|blob| (blob, Tier::Disk))))
            .collect();
        found.extend(self.get_now(keyed));
        let mut hits: Vec<Hit> = Vec::new();
        for (b, key, got) in found {
            match got {
                Some((blob, tier)) => self.accept_hit(b, key, blob, tier, &mut hits, &mut rest),
                None => rest.push(b),
            }
        }
        if hits.is_empty() {
            rest.sort_unstable();
            return Ok(Restored {
                built: Vec::new(),
                rest,
            });
        }
        let mut restored = Vec::with_capacity(hits.len());
        self.restore_some(&hits, evict, &mut restored, &mut rest)?;
        rest.sort_unstable();
        self.frame.stats_mut().restore_ms += ms_since(t);
        Ok(Restored {
            built: restored,
            rest,
        })
    }

    /// The cache's blobs of `keyed` now (host memory, else the directory on this thread): a
    /// sample of the restore rule's disk reads where any came from there.
    fn get_now(&mut self, keyed: Vec<(usize, CacheKey)>) -> Vec<Found> {
        if keyed.is_empty() {
            return Vec::new();
        }
        let ctx = self.ctx.clone();
        let compatible = |h: &[u8; 32]| ctx.acceleration_structure_compatible(h).unwrap_or(false);
        let keys: Vec<CacheKey> = keyed.iter().map(|k| k.1).collect();
        let a = self.reuse.cache.as_mut().expect("attached");
        // One call for the whole set: entries on disk are read on several threads.
        let read = Instant::now();
        let found = a.cache.cache.get_many(&keys, &compatible);
        let ms = ms_since(read);
        self.frame.stats_mut().restore_read_ms += ms;
        let (n, bytes) = found
            .iter()
            .flatten()
            .filter(|(_, tier)| *tier == Tier::Disk)
            .fold((0u64, 0u64), |(n, s), (b, _)| (n + 1, s + b.len() as u64));
        self.reuse.rule.disk_read.add(n, bytes, ms);
        keyed
            .into_iter()
            .zip(found)
            .map(|((b, key), got)| (b, key, got))
            .collect()
    }

    /// Takes `blob` (BLAS `b`'s entry from `tier`) into `hits` when its serialised header
    /// matches its length; else removes the entry and leaves `b` to `rest`, with a warning.
    fn accept_hit(
        &mut self,
        b: usize,
        key: CacheKey,
        blob: Blob,
        tier: Tier,
        hits: &mut Vec<Hit>,
        rest: &mut Vec<usize>,
    ) {
        match SerializedHeader::read(&blob) {
            Some(h) if h.serialized_bytes == blob.len() as u64 && h.deserialized_bytes > 0 => {
                match tier {
                    Tier::Host => self.frame.stats_mut().restored_from_host += 1,
                    Tier::Disk => self.frame.stats_mut().restored_from_disk += 1,
                }
                hits.push(Hit {
                    blas: b,
                    blob,
                    header: h,
                });
            }
            _ => {
                tracing::warn!(blas = b, "structure cache: an entry whose serialised header does not match its length; rebuilt");
                let a = self.reuse.cache.as_mut().expect("attached");
                a.cache.cache.remove(&key);
                rest.push(b);
            }
        }
    }

    /// Deserialises `hits` in one submission; where the budget has no room for their copies,
    /// in halves (a single one that does not fit is left to be built, counted).
    fn restore_some(
        &mut self,
        hits: &[Hit],
        evict: bool,
        restored: &mut Vec<(usize, AccelStruct)>,
        rest: &mut Vec<usize>,
    ) -> Result<()> {
        let align = |v: u64| v.div_ceil(SERIALIZED_ALIGNMENT) * SERIALIZED_ALIGNMENT;
        let total: u64 = hits.iter().map(|h| align(h.blob.len() as u64)).sum();
        if total > TRANSFER_CAP_BYTES && hits.len() > 1 {
            let (l, r) = hits.split_at(hits.len() / 2);
            self.restore_some(l, evict, restored, rest)?;
            return self.restore_some(r, evict, restored, rest);
        }
        match self.maybe_evicting(evict, |s| s.deserialize(hits)) {
            Ok(r) => restored.extend(r),
            Err(GpuError::Budget(why)) if hits.len() > 1 => {
                tracing::debug!(%why, n = hits.len(), "structure cache: restoring in halves");
                let (l, r) = hits.split_at(hits.len() / 2);
                self.restore_some(l, evict, restored, rest)?;
                self.restore_some(r, evict, restored, rest)?;
            }
            Err(GpuError::Budget(why)) => {
                tracing::debug!(%why, "structure cache: no room to restore; building instead");
                self.frame.stats_mut().restore_skipped += 1;
                rest.push(hits[0].blas);
            }
            Err(e) => return Err(e),
        }
        Ok(())
    }

    /// One submission deserialising `hits` from a host-visible copy of their blobs.
    fn deserialize(&mut self, hits: &[Hit]) -> Result<Vec<(usize, AccelStruct)>> {
        let ctx = self.ctx.clone();
        let t = Instant::now();
        let align = |v: u64| v.div_ceil(SERIALIZED_ALIGNMENT) * SERIALIZED_ALIGNMENT;
        let total: u64 = hits.iter().map(|h| align(h.blob.len() as u64)).sum();
        let staging = self.transfer_buffer(Transfer::Upload, total)?;
        let device_staging = self.transfer_staging();
        let mut out: Vec<(usize, AccelStruct)> = Vec::with_capacity(hits.len());
        let result = (|| -> Result<()> {
            let base = staging.device_address()?;
            let mut offsets = Vec::with_capacity(hits.len());
            let mut at = 0u64;
            for Hit {
                blas: b,
                blob,
                header: h,
            } in hits
            {
                offsets.push(at);
                let accel = AccelStruct::new(
                    &ctx,
                    &mut self.heap,
                    &format!("blas {b} (restored)"),
                    h.deserialized_bytes,
                    AsLevel::Bottom,
                )?;
                out.push((*b, accel));
                at += align(blob.len() as u64);
            }
            // The host's copies in parallel: one thread's memcpy into pinned memory held
            // restores to a few GB/s.
            staging.with_mapped_mut(0, at as usize, |bytes| {
                let mut parts = Vec::with_capacity(hits.len());
                let mut rest = bytes;
                for (i, Hit { blob, .. }) in hits.iter().enumerate() {
                    let next = offsets
                        .get(i + 1)
                        .map_or(rest.len(), |&o| (o - offsets[i]) as usize);
                    let (part, tail) = rest.split_at_mut(next);
                    parts.push((&mut part[..blob.len()], &blob[..]));
                    rest = tail;
                }
                parts
                    .into_par_iter()
                    .for_each(|(dst, src)| dst.copy_from_slice(src));
            })?;
            self.frame.stats_mut().restore_upload_ms += ms_since(t);
            let gpu = Instant::now();
            let mut rec = ctx.record("restore blases")?;
            match &device_staging {
                None => {
                    for ((_, accel), &off) in out.iter().zip(&offsets) {
                        rec.deserialize_acceleration_structure(base.offset(off), accel.target())?;
                    }
                }
                Some(st) => {
                    // One bus copy a run into device memory, deserialised from there
                    // (transfer.rs).
                    let st_base = st.device_address()?;
                    let sizes: Vec<u64> = hits.iter().map(|h| h.blob.len() as u64).collect();
                    for run in staged_runs(&offsets, &sizes, st.size_bytes()) {
                        if run.staged {
                            rec.barrier();
                            rec.copy_buffer(&staging, run.start_bytes, st, 0, run.len_bytes)?;
                            rec.barrier();
                            self.frame.stats_mut().transfer_staged_runs += 1;
                        }
                        for i in run.blobs.clone() {
                            let src = run.address(offsets[i], st_base, base);
                            rec.deserialize_acceleration_structure(src, out[i].1.target())?;
                        }
                    }
                }
            }
            rec.barrier();
            rec.submit_and_wait()?;
            self.frame.stats_mut().restore_gpu_ms += ms_since(gpu);
            // A sample of the store rule's restore cost (disk reads excluded: the host tier's).
            let bytes = hits.iter().map(|h| h.header.deserialized_bytes).sum();
            self.reuse
                .estimates
                .restore
                .add(hits.len() as u64, bytes, ms_since(t));
            Ok(())
        })();
        self.put_back_transfer(Transfer::Upload, staging);
        if let Some(st) = device_staging {
            self.put_back_transfer(Transfer::Staging, st);
        }
        match result {
            Ok(()) => Ok(out),
            Err(e) => {
                for (_, a) in out {
                    a.release(&mut self.heap);
                }
                Err(e)
            }
        }
    }
}

/// The first bytes of a proxy-box table's cache entry: where a serialised structure has its
/// driver's compatibility header (the cache reads entries through it), so no driver accepts
/// the table as a structure and the table is accepted only as itself.
const PROXY_BOXES_MAGIC: [u8; SERIALIZED_HEADER_BYTES] =
    *b"motu proxy-box table v1\0\0\0\0\0\0\0\0\0";
const PROXY_BOXES_DOMAIN: &str = "motu-proxy-boxes-v1";

/// A proxy-box table as a cache blob: the magic, the index's and the table's lengths (u64
/// each), the index (`[first, fan]` per BLAS), the boxes.
fn encode_proxy_boxes(index: &[[u32; 2]], boxes: &[Box6]) -> Blob {
    let mut w = BlobWriter::new(
        &PROXY_BOXES_MAGIC,
        16 + std::mem::size_of_val(index) + std::mem::size_of_val(boxes),
    );
    w.u64(index.len() as u64)
        .u64(boxes.len() as u64)
        .pods(index)
        .pods(boxes);
    w.finish().into()
}

/// The boxes of a blob [`encode_proxy_boxes`] made for `index` (`None`: not such a blob).
fn decode_proxy_boxes(blob: &[u8], index: &[[u32; 2]], box_count: usize) -> Option<Vec<Box6>> {
    let mut r = BlobReader::new(blob, &PROXY_BOXES_MAGIC)?;
    if r.u64()? != index.len() as u64 || r.u64()? != box_count as u64 {
        return None;
    }
    r.expect(bytemuck::cast_slice(index))?;
    let boxes = r.pods::<Box6>(box_count)?;
    r.finish()?;
    Some(boxes)
}

/// What the start has of the box table before the structure cache is asked: the package's
/// matching entries filled in, and the BLASes left to make.
pub(super) type Partial = (Vec<Box6>, Vec<usize>);

impl StreamingRenderer<'_> {
    /// The boxes inside streamable BLASes (`proxy_boxes.rs`, laid out as `index`): from the
    /// structure cache when it holds this scene's table, else made from every mesh (seconds
    /// on a large scene; only the BLASes `partial` leaves, where the package stored the
    /// rest) and kept there for the next process.
    pub(super) fn proxy_boxes_cached(
        &mut self,
        index: &[[u32; 2]],
        box_count: usize,
        partial: Option<Partial>,
    ) -> Vec<Box6> {
        let view = self.view;
        let key = self.reuse.cache.as_ref().map(|a| {
            let mut k = CacheKeyBuilder::new(PROXY_BOXES_DOMAIN);
            k.bytes(&a.cache.scene_identity)
                .bytes(bytemuck::cast_slice(view.blases))
                .bytes(bytemuck::cast_slice(view.geometries))
                .bytes(bytemuck::cast_slice(index));
            k.finish()
        });
        if let (Some(key), Some(a)) = (key, self.reuse.cache.as_mut()) {
            let table = |h: &[u8; SERIALIZED_HEADER_BYTES]| *h == PROXY_BOXES_MAGIC;
            if let Some((blob, tier)) = a.cache.cache.get(&key, &table) {
                match decode_proxy_boxes(&blob, index, box_count) {
                    Some(boxes) => {
                        tracing::info!(
                            ?tier,
                            boxes = box_count,
                            "proxy boxes from the structure cache"
                        );
                        self.totals.proxy_boxes_cached = true;
                        self.totals.proxy_boxes_source = "cache";
                        return boxes;
                    }
                    None => {
                        tracing::warn!("structure cache: a proxy-box table that does not match this scene's layout; made again");
                        a.cache.cache.remove(&key);
                    }
                }
            }
        }
        let boxes = match partial {
            Some((mut table, left)) => {
                proxy_boxes::fill(&view, self.source, index, &mut table, &left);
                table
            }
            None => proxy_boxes::compute(&view, self.source, index, box_count),
        };
        self.totals.proxy_boxes_source = "computed";
        if let (Some(key), Some(a)) = (key, self.reuse.cache.as_mut()) {
            a.cache.cache.put(key, encode_proxy_boxes(index, &boxes));
        }
        boxes
    }
}

mod reads;
mod store;
use reads::Decision;
pub(super) use reads::GroupReads;
#[cfg(test)]
mod tests;
