//! (Re)building TLASes with their proxy and marks BLASes ([`StreamingRenderer::build_tlases`]):
//! a [`TlasBuild`] runs one method per phase (old structures out, proxies planned, room
//! probed, proxies built, persistent TLASes updated, the others' records encoded, uploaded
//! and built, everything swapped in), each phase's products named structs. A TLAS whose
//! clusters' residency did not change keeps its proxy and marks BLASes (same boxes, same PI
//! slots): a BLAS moved, or evicted and built back, rebuilds only the TLAS.

use motu_alloc::BuildSize;
use motu_vk::{AsGeometry, AsLevel, Context};

use super::buffers::staging_released;
use super::tlas_records::{tail_record, TlasRecords, RECORD_BYTES};
use super::tlases::{ProxyPair, TlasGpu};
use super::topology::Topology;
use super::StreamingRenderer;
use crate::error::{GpuError, Result};
use crate::scene::{build_batched, AccelStruct, BuildOptions, ResourceReport};

mod inputs;
mod one_submit;
mod plan;
mod storage;
mod times;

use inputs::{
    alloc_box_buffer, alloc_instance_buffer, proxy_geometry, proxy_sizes, queue_proxy_uploads,
};
use times::PhaseTimes;

/// One proxy BLAS (`marks` false: a TLAS's non-resident clusters) or marks BLAS (its
/// resident ones) to build over boxes `first_box..first_box + box_count` of the box buffer.
struct ProxyItem {
    tlas: u32,
    marks: bool,
    first_box: u32,
    box_count: u32,
}

/// TLAS `tlas`'s clusters in box order: the `non_resident` first (the proxy's boxes and PI
/// slots), then the resident ones (the marks'), each in cluster order; `key` holds the
/// residency bits the order comes from ([`ProxyPair::key`]).
struct ClusterOrder {
    tlas: u32,
    order: Vec<u32>,
    non_resident: u32,
    key: Vec<u64>,
}

/// What the proxies of a build are: the BLASes to build and, per TLAS, its boxes' order.
/// Boxes and PI records are written from the clusters straight into the staging ring:
/// building them as host vectors took ~55 ms of each rebuild at island 0.3 (0.8M clusters,
/// 85 MB of fresh pages).
#[derive(Default)]
struct ProxyPlan {
    items: Vec<ProxyItem>,
    orders: Vec<ClusterOrder>,
    box_count: u32,
}

/// The proxy and marks BLASes of the build's TLASes (built, or kept from their last build),
/// until each pair is installed in its TLAS (or all released when the build fails).
#[derive(Default)]
struct Proxies(Vec<(u32, ProxyPair)>);

impl Proxies {
    fn pair(&self, t: u32) -> Option<&ProxyPair> {
        self.0.iter().find(|(u, _)| *u == t).map(|(_, p)| p)
    }

    /// Device address of TLAS `t`'s proxy (`marks` false) or marks BLAS; 0: none.
    fn address(&self, t: u32, marks: bool) -> u64 {
        self.pair(t)
            .and_then(|p| if marks { &p.marks } else { &p.proxy }.as_ref())
            .map_or(0, |a| a.address)
    }

    /// The records following TLAS `t`'s own: its proxy's and marks' (their GPU BLAS records
    /// from `topo`).
    fn tail_records(&self, t: u32, topo: &Topology) -> Vec<[u8; RECORD_BYTES]> {
        [false, true]
            .into_iter()
            .filter_map(|marks| {
                let a = self.address(t, marks);
                (a != 0).then(|| tail_record(topo.proxy_blas_record(t as usize, marks), marks, a))
            })
            .collect()
    }

    /// TLAS `t`'s pair (none: an empty one).
    fn take(&mut self, t: u32) -> ProxyPair {
        match self.0.iter().position(|(u, _)| *u == t) {
            Some(k) => self.0.swap_remove(k).1,
            None => ProxyPair::default(),
        }
    }

    fn release(self, heap: &mut motu_vk::GpuHeap) {
        self.0.into_iter().for_each(|(_, p)| p.release(heap));
    }

    /// The planned TLASes' new pairs (their boxes' residency key), holding the `built` proxy
    /// and marks BLASes (build indices into `plan.items`).
    fn install(&mut self, plan: &ProxyPlan, built: Built) {
        let first = self.0.len();
        self.0.extend(plan.orders.iter().map(|o| {
            let key = o.key.clone();
            (
                o.tlas,
                ProxyPair {
                    key,
                    ..ProxyPair::default()
                },
            )
        }));
        for (k, accel, saved_bytes) in built {
            let item = &plan.items[k];
            let Some((_, pair)) = self.0[first..].iter_mut().find(|(t, _)| *t == item.tlas) else {
                unreachable!("every planned item's TLAS has an order")
            };
            pair.saved_bytes += saved_bytes;
            *if item.marks {
                &mut pair.marks
            } else {
                &mut pair.proxy
            } = Some(accel);
        }
    }
}

/// The rebuilt TLASes' instance records, counted, with their build sizes and places in the
/// instance buffer.
struct RebuildRecords<'r> {
    records: TlasRecords<'r>,
    /// Per rebuilt TLAS (in the order of its ids): records, build sizes, byte offset.
    counts: Vec<u32>,
    sizes: Vec<BuildSize>,
    offsets: Vec<u64>,
    /// The instance buffer's bytes.
    total_bytes: u64,
}

impl RebuildRecords<'_> {
    /// Counts the rebuild into the frame's stats (once, when its structures are built).
    fn note(&self, st: &mut super::FrameStreamStats) {
        st.tlas_builds += self.counts.len() as u32;
        st.tlas_instances_written += self.records.host_written();
        st.tlas_records_compacted += self.records.compacted();
        let transient = self.sizes.iter().fold(self.total_bytes, |t, s| {
            t + s.result_bytes + s.scratch_bytes
        });
        st.tlas_rebuild_transient_bytes = st.tlas_rebuild_transient_bytes.max(transient);
    }
}

/// When a TLAS was rebuilt (`--stats`: `tlas_rebuilt_at_start`, `_in_passes`,
/// `_in_prefetch`): before the frame's first pass, in a build step between its passes, or in
/// the prefetch after them.
#[derive(Clone, Copy)]
enum RebuildWhy {
    Start,
    Pass,
    Prefetch,
}

/// Built structures: (build index, structure, bytes compaction saved on it).
type Built = Vec<(usize, AccelStruct, u64)>;

/// One [`StreamingRenderer::build_tlases`] call.
struct TlasBuild<'r, 'a> {
    r: &'r mut StreamingRenderer<'a>,
    ctx: Context,
    /// Resident BLAS addresses (0: not resident): the clusters' residency, read by the
    /// parallel record encoder.
    addrs: Vec<u64>,
    /// Per TLAS of the rebuild (not persistent, in the order of its ids): its records are
    /// compacted on the GPU from the kept ones (`tlas_compact.rs`), else written by the host.
    gpu: Vec<bool>,
    /// The old proxy and marks BLASes of the build's TLASes, until planned (kept or released).
    old_proxies: Vec<(u32, ProxyPair)>,
    /// The old structures of the build's TLASes held for the new ones to reuse (`storage.rs`).
    old_storage: storage::OldStorage,
    times: PhaseTimes,
}

impl<'a> StreamingRenderer<'a> {
    /// How rebuilt TLASes and their proxy and marks BLASes are built (their size queries
    /// too): compacted only with `--stream-tlas-compact on` ([`super::StreamOptions::tlas_compact`]).
    pub(super) fn rebuild_opts(&self) -> BuildOptions {
        BuildOptions {
            compact: self.build_opts.compact && self.opts.tlas_compact,
            ..self.build_opts
        }
    }

    /// (Re)builds TLASes `ids` with their proxies from the current residency. The old ones are
    /// released first (old and new together would double the largest transient of a small
    /// budget, the root's); on failure they stay absent and dirty for the caller to retry with
    /// less resident (never traced: the caller rebuilds or poisons before the next trace).
    pub(super) fn build_tlases(&mut self, ids: &[u32]) -> Result<()> {
        let ctx = self.ctx.clone();
        let mut b = TlasBuild {
            r: self,
            ctx,
            addrs: Vec::new(),
            gpu: Vec::new(),
            old_proxies: Vec::new(),
            old_storage: storage::OldStorage::default(),
            times: PhaseTimes::new(),
        };
        let (submits0, waits0) = (b.ctx.submit_count(), b.ctx.fence_wait_count());
        let result = b.run(ids);
        // Old storage no path took (a refusal, an error): released, the TLAS absent as before.
        b.release_old_storage();
        let TlasBuild { r, times, ctx, .. } = b;
        let st = r.frame.stats_mut();
        st.tlas_submits += ctx.submit_count() - submits0;
        st.tlas_fence_waits += ctx.fence_wait_count() - waits0;
        times.record(st);
        result
    }
}

impl TlasBuild<'_, '_> {
    /// The phases in order (see the module docs).
    fn run(&mut self, ids: &[u32]) -> Result<()> {
        self.release_old(ids);
        self.times.swap_ms = self.times.lap();
        self.addrs = self
            .r
            .res
            .blases()
            .iter()
            .map(|a| a.as_ref().map_or(0, |a| a.address))
            .collect();
        let (plan, mut proxies) = self.plan_proxies(ids);
        self.times.proxy_host_ms = self.times.lap();
        // Persistent TLASes are updated (or built once over every instance); the rest rebuilt.
        let (persistent_ids, rebuild_ids): (Vec<u32>, Vec<u32>) = ids
            .iter()
            .partition(|&&t| self.r.tlases.in_persistent_mode(t));
        if let Err(e) = self.probe_room(&rebuild_ids, &plan, &proxies) {
            proxies.release(&mut self.r.heap);
            return Err(e);
        }
        self.times.probe_ms = self.times.lap();
        // Proxies and TLASes in one submission where it applies (`one_submit.rs`); refused
        // with old storage held, tried once more without it (the room it had before reuse).
        let tries = if persistent_ids.is_empty() {
            1 + u32::from(!self.old_storage.is_empty())
        } else {
            0
        };
        for _ in 0..tries {
            match self.one_submission(&rebuild_ids, &plan, &mut proxies) {
                Ok(Some((built, records))) => {
                    self.r.frame.stats_mut().tlas_one_submission += 1;
                    self.times.records = records;
                    self.times.proxy_boxes = plan.box_count;
                    self.swap_in(&rebuild_ids, built, Vec::new(), &mut proxies);
                    return Ok(());
                }
                Ok(None) => self.release_old_storage(),
                Err(e) => {
                    proxies.release(&mut self.r.heap);
                    return Err(e);
                }
            }
        }
        // The step-by-step path allocates its own structures.
        self.release_old_storage();
        if let Err(e) = self.build_proxies(&plan, &mut proxies) {
            proxies.release(&mut self.r.heap);
            return Err(e);
        }
        self.times.proxy_build_ms = self.times.lap();
        let updated = match self.update_persistent_tlases(&persistent_ids, &proxies) {
            Ok(u) => u,
            Err(e) => {
                proxies.release(&mut self.r.heap);
                return Err(e);
            }
        };
        self.times.update_ms = self.times.lap();
        let (built, records) = match self.rebuild(&rebuild_ids, &proxies) {
            Ok(r) => r,
            Err(e) => {
                proxies.release(&mut self.r.heap);
                return Err(e);
            }
        };
        self.times.build_ms = self.times.lap();
        self.times.records = records;
        self.times.proxy_boxes = plan.box_count;
        self.times.storage_allocated += built.len() as u32;
        self.swap_in(&rebuild_ids, built, updated, &mut proxies);
        Ok(())
    }

    /// The rebuild's transient probed first; kept records are then made only in free budget
    /// beyond what the rebuild needs (they never evict, nor take its room).
    fn probe_room(&mut self, rebuild_ids: &[u32], plan: &ProxyPlan, kept: &Proxies) -> Result<()> {
        if rebuild_ids.is_empty() {
            return Ok(());
        }
        let tails: Vec<u64> = rebuild_ids
            .iter()
            .map(|&t| {
                let planned = plan.items.iter().filter(|i| i.tlas == t).count() as u64;
                planned + kept.pair(t).map_or(0, ProxyPair::count)
            })
            .collect();
        self.probe_with_storage(rebuild_ids, &tails)?;
        let r = &mut *self.r;
        if r.opts.tlas_records == super::TlasRecordsMode::Gpu {
            // The host path skips this sizing: it keeps nothing.
            let counts = r.resident_instance_counts();
            let mut room_bytes = 0u64;
            for &t in rebuild_ids {
                room_bytes += r.tlas_rebuild_bytes(t, counts[t as usize])?;
            }
            self.gpu = r.prepare_kept_records(rebuild_ids, room_bytes)?;
        } else {
            self.gpu = vec![false; rebuild_ids.len()];
        }
        Ok(())
    }

    /// Phase 0: the old structures go (dirty: never traced until rebuilt or updated). A
    /// persistent TLAS's structure stays. Their proxy and marks BLASes wait for the plan,
    /// which keeps those whose boxes are the same and releases the others. Where the
    /// one-submission path can take the rebuild, the structures are held for the new ones to
    /// be built into instead (`storage.rs`).
    fn release_old(&mut self, ids: &[u32]) {
        let keep = self.keeps_storage(ids);
        let r = &mut *self.r;
        let t0 = std::time::Instant::now();
        for &t in ids {
            if let Some((pair, storage)) = r.tlases.start_rebuild(t, keep, &mut r.heap) {
                self.old_proxies.push((t, pair));
                if let Some(a) = storage {
                    self.old_storage.push(t, a);
                }
            }
        }
        self.times.free_ms += t0.elapsed().as_secs_f64() * 1e3;
    }

    /// Phase 1 on the host: which proxy BLASes (the clusters of non-resident BLASes) and marks
    /// BLASes (the resident ones) TLASes `ids` get, and the order of their boxes. A TLAS whose
    /// clusters' residency is that of its old pair's build keeps the pair (returned); the
    /// other old pairs are released.
    fn plan_proxies(&mut self, ids: &[u32]) -> (ProxyPlan, Proxies) {
        let view = self.r.view;
        let mut plan = ProxyPlan::default();
        let mut kept = Proxies::default();
        let mut old = std::mem::take(&mut self.old_proxies);
        for &t in ids {
            let clusters = self.r.topo.clusters(t as usize);
            let (key, non_resident) = plan::residency_key(clusters, &self.addrs);
            let old_pair = old
                .iter()
                .position(|(u, _)| *u == t)
                .map(|k| old.swap_remove(k).1);
            match old_pair {
                Some(pair) if pair.key == key && !key.is_empty() => {
                    self.times.proxies_kept += pair.count() as u32;
                    kept.0.push((t, pair));
                    continue;
                }
                Some(pair) => pair.release(&mut self.r.heap),
                None => {}
            }
            // The marks' custom index (the TLAS's instance count + 1) must fit the 24 bits of
            // an instance's; a TLAS at the device cap goes without (the prefetch then sees only
            // its hits, as before the marks: slower, never wrong).
            let with_marks = view.tlases[t as usize].instance_count + 1 < 1 << 24;
            let order = plan::cluster_order(&key, clusters.len(), non_resident, with_marks);
            let marks = order.len() as u32 - non_resident;
            let first = plan.box_count;
            for (is_marks, first_box, box_count) in [
                (false, first, non_resident),
                (true, first + non_resident, marks),
            ] {
                if box_count > 0 {
                    plan.items.push(ProxyItem {
                        tlas: t,
                        marks: is_marks,
                        first_box,
                        box_count,
                    });
                }
            }
            plan.box_count += order.len() as u32;
            if !order.is_empty() {
                plan.orders.push(ClusterOrder {
                    tlas: t,
                    order,
                    non_resident,
                    key,
                });
            }
        }
        // Old pairs of TLASes not planned (none: `ids` are the released ones).
        old.into_iter()
            .for_each(|(_, p)| p.release(&mut self.r.heap));
        (plan, kept)
    }

    /// Phase 1 on the device: the planned proxy and marks BLASes, built compacted from a box
    /// buffer freed after, into `proxies`. The planned TLASes' PI slots and marks records are
    /// rewritten to their new order in the same flush as the boxes (nothing traces a TLAS
    /// being rebuilt: it is absent or dirty until swapped in).
    fn build_proxies(&mut self, plan: &ProxyPlan, proxies: &mut Proxies) -> Result<()> {
        if plan.box_count == 0 {
            return Ok(());
        }
        let ctx = &self.ctx;
        let r = &mut *self.r;
        let rb = r.rebuild_opts();
        let buf = alloc_box_buffer(&mut r.heap, plan)?;
        let built = (|| -> Result<Built> {
            queue_proxy_uploads(ctx, r, plan, &buf)?;
            r.up.as_mut().ok_or_else(staging_released)?.flush(ctx)?;
            let base = buf.device_address()?.0;
            let sizes = proxy_sizes(ctx, plan, &rb)?;
            let mut report = ResourceReport::default();
            let built = build_batched(
                ctx,
                &mut r.heap,
                &mut report,
                &sizes,
                AsLevel::Bottom,
                &rb,
                |k| proxy_geometry(base, &plan.items[k]),
                |_, _| Ok(()),
                &mut |_| {},
            )?;
            Ok(with_saved_bytes(built, &sizes))
        })();
        r.heap.free(buf);
        let built = built?;
        self.times.proxies_built += built.len() as u32;
        self.times.count_compactions(&built);
        proxies.install(plan, built);
        Ok(())
    }

    /// Phase 2a: persistent TLASes `ids`, their records patched where residency changed, then
    /// updated (built over every instance first when they are not yet). Returns them.
    fn update_persistent_tlases(&mut self, ids: &[u32], proxies: &Proxies) -> Result<Vec<u32>> {
        let r = &mut *self.r;
        let addrs = &self.addrs;
        let mut updated = Vec::with_capacity(ids.len());
        for &t in ids {
            let tail = [false, true].map(|marks| proxies.address(t, marks));
            let done = if r.tlases.is_persistent(t) {
                r.update_persistent(t, addrs, tail).map(|n| {
                    let st = r.frame.stats_mut();
                    st.tlas_builds += 1;
                    st.tlas_updates += 1;
                    st.tlas_instances_written += n;
                })
            } else {
                r.build_persistent(t, addrs, tail)
                    .map(|(accel, p)| {
                        let n = p.record_count();
                        r.tlases
                            .put_persistent(t, TlasGpu::persistent_over(accel, p));
                        r.frame.stats_mut().tlas_builds += 1;
                        r.frame.stats_mut().tlas_instances_written += u64::from(n);
                    })
                    .and_then(|()| {
                        // Built over every instance's whole bounds (the topology of a full
                        // build); the non-resident ones now shrink to their points.
                        let n = r.update_persistent(t, addrs, tail)?;
                        r.frame.stats_mut().tlas_updates += 1;
                        r.frame.stats_mut().tlas_builds += 1;
                        r.frame.stats_mut().tlas_instances_written += n;
                        Ok(())
                    })
            };
            if let Err(e) = done {
                if matches!(e, GpuError::Budget(_)) && !r.tlases.is_persistent(t) {
                    // Built over every instance it does not fit: rebuilt from now on (the
                    // caller's retry rebuilds it).
                    tracing::warn!(tlas = t, %e, "persistent TLAS does not fit; rebuilt instead");
                    r.tlases.leave_persistent_mode(t);
                }
                return Err(e);
            }
            updated.push(t);
        }
        Ok(updated)
    }

    /// Phase 2b on the host: the rebuilt TLASes' records counted (resident BLASes' instances
    /// plus the proxy and marks: non-resident instances are left out, their proxy boxes stand
    /// for them, so a TLAS's size follows what is resident, not its instance count; the custom
    /// index keeps each instance's record), their build sizes and buffer offsets.
    fn count_records<'s, 'v: 's>(
        r: &mut StreamingRenderer<'v>,
        ctx: &Context,
        addrs: &'s [u64],
        ids: &[u32],
        gpu: &[bool],
        proxies: &Proxies,
    ) -> Result<RebuildRecords<'s>> {
        let view: motu_abi::HierarchyView<'s> = r.view;
        let ring_region = r.up_mut()?.region_bytes();
        let topo = &r.topo;
        let records = TlasRecords::count(view, addrs, ids, gpu, ring_region, |t| {
            // The proxy's and the marks' records follow the TLAS's own (see
            // `StreamingRenderer::new`); only probe passes' rays see the marks.
            proxies.tail_records(t, topo)
        });
        let counts = records.record_counts();
        let mut sizes = Vec::with_capacity(ids.len());
        for &n in &counts {
            let s = ctx.tlas_build_sizes(n, r.rebuild_opts().tlas_flags())?;
            sizes.push(BuildSize {
                result_bytes: s.acceleration_structure_size_bytes,
                scratch_bytes: s.build_scratch_size_bytes,
            });
        }
        let mut offsets = Vec::with_capacity(ids.len());
        let mut total_bytes = 0u64;
        for &n in &counts {
            offsets.push(total_bytes);
            total_bytes += u64::from(n) * RECORD_BYTES as u64;
        }
        Ok(RebuildRecords {
            records,
            counts,
            sizes,
            offsets,
            total_bytes,
        })
    }

    /// Phase 2b: TLASes `ids` rebuilt over the resident BLASes plus their proxy and marks
    /// instances. Returns the new structures (indices into `ids`) and the records written.
    fn rebuild(&mut self, ids: &[u32], proxies: &Proxies) -> Result<(Built, u64)> {
        let ctx = self.ctx.clone();
        let (r, times) = (&mut *self.r, &mut self.times);
        let rr = Self::count_records(r, &ctx, &self.addrs, ids, &self.gpu, proxies)?;
        rr.note(r.frame.stats_mut());
        let RebuildRecords {
            records,
            counts,
            sizes,
            offsets,
            total_bytes,
        } = rr;
        times.encode_ms = times.lap();
        let inst_buf = alloc_instance_buffer(&mut r.heap, total_bytes)?;
        let rb = r.rebuild_opts();
        let uploaded = (|| -> Result<u64> {
            let up = r.up.as_mut().ok_or_else(staging_released)?;
            if let Err(e) = records.upload(&ctx, up, &inst_buf, &offsets) {
                // Copies queued for the instance buffer must not outlive it.
                up.abandon();
                return Err(e);
            }
            up.flush(&ctx)?;
            let inst_addr = inst_buf.device_address()?.0;
            // The GPU TLASes' own records, between the host's.
            let ms = r.compact_records(&records.gpu_jobs(&offsets), &self.addrs, inst_addr)?;
            r.frame.stats_mut().tlas_compact_ms += ms;
            Ok(inst_addr)
        })();
        // Freed as soon as the TLASes are built (`inputs_done`), before their compacted copies
        // are allocated: the records are read by the build only.
        let mut inst_buf = Some(inst_buf);
        let built = uploaded.and_then(|inst_addr| {
            times.upload_ms = times.lap();
            let mut report = ResourceReport::default();
            build_batched(
                &ctx,
                &mut r.heap,
                &mut report,
                &sizes,
                AsLevel::Top,
                &rb,
                |k| {
                    (
                        vec![AsGeometry::Instances {
                            address: inst_addr + offsets[k],
                        }],
                        vec![counts[k]],
                    )
                },
                |_, _| Ok(()),
                &mut |heap| {
                    if let Some(b) = inst_buf.take() {
                        heap.free(b);
                    }
                },
            )
        });
        if let Some(b) = inst_buf.take() {
            r.heap.free(b);
        }
        let built = with_saved_bytes(built?, &sizes);
        times.count_compactions(&built);
        Ok((built, total_bytes / RECORD_BYTES as u64))
    }

    /// Phase 3: the rebuilt TLASes (`built`, indices into `rebuilt`) and the `updated`
    /// persistent ones take their proxies and are clean.
    fn swap_in(&mut self, rebuilt: &[u32], built: Built, updated: Vec<u32>, proxies: &mut Proxies) {
        let r = &mut *self.r;
        let stamp = r.frame.stamp();
        let why = if r.frame.prefetching() {
            RebuildWhy::Prefetch
        } else if r.frame.stats().passes == 0 {
            RebuildWhy::Start
        } else {
            RebuildWhy::Pass
        };
        let ts = built
            .iter()
            .map(|b| rebuilt[b.0])
            .chain(updated.iter().copied());
        for t in ts {
            let again = r.tlases.note_rebuilt(t, stamp);
            let st = r.frame.stats_mut();
            *match why {
                RebuildWhy::Start => &mut st.tlas_rebuilt_at_start,
                RebuildWhy::Pass => &mut st.tlas_rebuilt_in_passes,
                RebuildWhy::Prefetch => &mut st.tlas_rebuilt_in_prefetch,
            } += 1;
            st.tlas_rebuilt_again += u32::from(again);
        }
        for (k, accel, saved_bytes) in built {
            let t = rebuilt[k];
            let g = TlasGpu::rebuilt_with(accel, proxies.take(t), saved_bytes);
            r.tlases.rebuilt(t, g, &mut r.heap);
        }
        for t in updated {
            r.tlases.updated(t, proxies.take(t), &mut r.heap);
        }
        // Pairs of TLASes neither rebuilt nor updated (none unless a build came back short).
        std::mem::take(proxies).release(&mut r.heap);
    }
}

/// `built` (build index, structure) with the bytes compaction saved on each: its built size
/// (`sizes`) less what it holds (0: not compacted).
fn with_saved_bytes(built: Vec<(usize, AccelStruct)>, sizes: &[BuildSize]) -> Built {
    built
        .into_iter()
        .map(|(k, a)| {
            let saved = sizes[k].result_bytes.saturating_sub(a.size_bytes);
            (k, a, saved)
        })
        .collect()
}
