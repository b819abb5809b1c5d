//! Acceleration-structure builds: triangle and PI BLAS sets, TLASes with their proxy BLASes,
//! and rebuilding the TLASes whose instance set changed.

use motu_abi::PiRecord;
use motu_alloc::{AllocKind, BuildSize, ItemId, MemoryClass};
use motu_vk::{
    AsBuildFlags, AsGeometry, AsLevel, BufferUsage, FitRequest,
    ACCELERATION_STRUCTURE_OFFSET_ALIGNMENT,
};

use super::residency::EvictWhy;
use super::skeleton::{proxy_blas_record, proxy_pi, staging_released};
use super::tlas_records::{tail_record, TlasRecords, RECORD_BYTES};
use super::{StreamingRenderer, TlasGpu};
use crate::error::{GpuError, Result};
use crate::scene::{aabbs_geometry, blas_geometry, build_batched, AccelStruct, ResourceReport};

impl<'a> StreamingRenderer<'a> {
    /// Builds the BLASes `ids` of the original hierarchy (meshes must be resident; `aabb_base`
    /// for PI BLASes) in batches. On failure nothing is left allocated.
    pub(super) fn build_blas_set(
        &mut self,
        ids: &[usize],
        aabb_base: u64,
    ) -> Result<Vec<(usize, AccelStruct)>> {
        let mut descs = Vec::with_capacity(ids.len());
        let mut sizes = Vec::with_capacity(ids.len());
        let mut order = Vec::with_capacity(ids.len());
        for &b in ids {
            let meshes = &self.meshes;
            let Some((g, c, shape)) =
                blas_geometry(&self.view, b, |m| meshes[m].as_ref(), aabb_base)?
            else {
                continue;
            };
            let sz = self
                .ctx
                .blas_build_sizes(&shape, self.build_opts.blas_build.flags())?;
            sizes.push(BuildSize {
                result_bytes: sz.acceleration_structure_size_bytes,
                scratch_bytes: sz.build_scratch_size_bytes,
            });
            descs.push((g, c));
            order.push(b);
        }
        let mut report = ResourceReport::default();
        let built = build_batched(
            &self.ctx,
            &mut self.heap,
            &mut report,
            &sizes,
            AsLevel::Bottom,
            &self.build_opts,
            |k| (descs[k].0.clone(), descs[k].1.clone()),
            |_, _| Ok(()),
            &mut |_| {},
        )?;
        Ok(built.into_iter().map(|(k, a)| (order[k], a)).collect())
    }

    /// (Re)builds TLASes `ids` with their proxies from the current residency. The old ones are
    /// released first (old and new together would double the largest transient of a small
    /// budget, the root's); on failure they stay absent and dirty for the caller to retry with
    /// less resident (never traced: the caller rebuilds or poisons before the next trace).
    pub(super) fn build_tlases(&mut self, ids: &[u32]) -> Result<()> {
        let ctx = self.ctx.clone();
        let view = self.view;
        // Phase times for the debug line below (`MOTU_LOG`).
        let lap = |t: &mut std::time::Instant| {
            let d = t.elapsed().as_secs_f64() * 1e3;
            *t = std::time::Instant::now();
            d
        };
        let mut t_phase = std::time::Instant::now();
        for &t in ids {
            if self.is_persistent(t) {
                // The structure stays; its old proxy and marks go first, as a rebuilt TLAS's
                // whole build does (dirty: never traced until updated).
                if let Some(g) = self.tlas[t as usize].as_mut() {
                    for a in [g.proxy.take(), g.marks.take()].into_iter().flatten() {
                        a.release(&mut self.heap);
                    }
                }
                self.dirty.insert(t);
            } else if let Some(old) = self.tlas[t as usize].take() {
                old.release(&mut self.heap);
                self.dirty.insert(t);
            }
        }
        // Persistent TLASes are updated (or built once over every instance); the rest rebuilt.
        let (persistent_ids, rebuild_ids): (Vec<u32>, Vec<u32>) =
            ids.iter().partition(|&&t| self.persistent_mode[t as usize]);
        if !rebuild_ids.is_empty() {
            self.probe_tlas_room(&rebuild_ids)?;
        }
        let t_probe = lap(&mut t_phase);
        // 1. Proxy BLASes (the clusters of non-resident BLASes) and marks BLASes (the
        // resident ones), compacted; their shared PI slots (proxy first) and the marks' BLAS
        // record are rewritten to match.
        // Resident BLAS addresses (0: not resident): the clusters' residency here, read by the
        // parallel record encoder below.
        let addrs: Vec<u64> = self
            .blas
            .iter()
            .map(|a| a.as_ref().map_or(0, |a| a.address))
            .collect();
        // (tlas, marks, first box, count)
        let mut proxy_items: Vec<(u32, bool, u32, u32)> = Vec::new();
        // (tlas, its clusters in box order, how many of them are non-resident). Boxes and PI
        // records are written from the clusters straight into the staging ring: building them
        // as host vectors took ~55 ms of each rebuild at island 0.3 (0.8M clusters, 85 MB of
        // fresh pages).
        let mut pi_rewrites: Vec<(u32, Vec<u32>, u32)> = Vec::new();
        let mut box_count = 0u32;
        for &t in ids {
            // The marks' custom index (the TLAS's instance count + 1) must fit the 24 bits of
            // an instance's; a TLAS at the device cap goes without (the prefetch then sees only
            // its hits, as before the marks: slower, never wrong).
            let with_marks = view.tlases[t as usize].instance_count + 1 < 1 << 24;
            // Non-resident clusters first (the proxy's boxes), then resident ones (the marks'),
            // each in cluster order.
            let clusters = &self.clusters[t as usize];
            let resident = |i: &u32| addrs[clusters[*i as usize].blas as usize] != 0;
            let all = 0..clusters.len() as u32;
            let mut order: Vec<u32> = Vec::with_capacity(clusters.len());
            order.extend(all.clone().filter(|i| !resident(i)));
            let non_resident = order.len() as u32;
            if with_marks {
                order.extend(all.filter(resident));
            }
            let marks = order.len() as u32 - non_resident;
            if non_resident > 0 {
                proxy_items.push((t, false, box_count, non_resident));
            }
            if marks > 0 {
                proxy_items.push((t, true, box_count + non_resident, marks));
            }
            box_count += order.len() as u32;
            if !order.is_empty() {
                pi_rewrites.push((t, order, non_resident));
            }
        }
        let t_proxy_host = lap(&mut t_phase);
        let mut proxies: Vec<(u32, bool, AccelStruct)> = Vec::new();
        if box_count > 0 {
            let buf = self.heap.alloc_buffer(
                "proxy-aabbs",
                u64::from(box_count) * 24,
                BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT | BufferUsage::TRANSFER_DST,
                AllocKind::Geometry,
                MemoryClass::DeviceLocal,
                16,
            )?;
            let r = (|| -> Result<Vec<(usize, AccelStruct)>> {
                let up = self.up.as_mut().ok_or_else(staging_released)?;
                let mut at = 0u64;
                for (t, order, _) in &pi_rewrites {
                    let clusters = &self.clusters[*t as usize];
                    let r = up.upload_with(&ctx, &buf, at, order.len(), |k| {
                        clusters[order[k] as usize].bounds
                    });
                    if let Err(e) = r {
                        // Copies queued for the box buffer must not outlive it.
                        up.abandon();
                        return Err(e);
                    }
                    at += order.len() as u64 * 24;
                }
                up.flush(&ctx)?;
                let base = buf.device_address()?.0;
                let mut descs = Vec::new();
                let mut sizes = Vec::new();
                for &(_, _, first, n) in &proxy_items {
                    descs.push((
                        vec![aabbs_geometry(base + u64::from(first) * 24, false)],
                        vec![n],
                    ));
                    let sz = ctx.blas_build_sizes(
                        &[motu_vk::BlasGeometry::Aabbs {
                            aabb_count: n,
                            opaque: false,
                        }],
                        self.build_opts.blas_build.flags(),
                    )?;
                    sizes.push(BuildSize {
                        result_bytes: sz.acceleration_structure_size_bytes,
                        scratch_bytes: sz.build_scratch_size_bytes,
                    });
                }
                let mut report = ResourceReport::default();
                build_batched(
                    &ctx,
                    &mut self.heap,
                    &mut report,
                    &sizes,
                    AsLevel::Bottom,
                    &self.build_opts,
                    |k| (descs[k].0.clone(), descs[k].1.clone()),
                    |_, _| Ok(()),
                    &mut |_| {},
                )
            })();
            self.heap.free(buf);
            for (k, a) in r? {
                proxies.push((proxy_items[k].0, proxy_items[k].1, a));
            }
        }
        let t_proxy = lap(&mut t_phase);
        // 2a. Persistent TLASes: records patched where residency changed, then an update.
        let mut updated: Vec<u32> = Vec::new();
        for &t in &persistent_ids {
            let tail = [false, true].map(|marks| {
                proxies
                    .iter()
                    .find(|(pt, m, _)| *pt == t && *m == marks)
                    .map_or(0, |(_, _, a)| a.address)
            });
            let r = if self.is_persistent(t) {
                self.update_persistent(t, &addrs, tail).map(|n| {
                    let st = &mut self.frame_stats;
                    st.tlas_builds += 1;
                    st.tlas_updates += 1;
                    st.tlas_instances_written += n;
                })
            } else {
                self.build_persistent(t, &addrs, tail)
                    .map(|(accel, p)| {
                        let n = p.record_count();
                        self.tlas[t as usize] = Some(TlasGpu {
                            accel,
                            proxy: None,
                            marks: None,
                            persistent: Some(p),
                        });
                        self.frame_stats.tlas_builds += 1;
                        self.frame_stats.tlas_instances_written += u64::from(n);
                    })
                    .and_then(|()| {
                        // Built over every instance's whole bounds (the topology of a full
                        // build); the non-resident ones now shrink to their points.
                        let n = self.update_persistent(t, &addrs, tail)?;
                        self.frame_stats.tlas_updates += 1;
                        self.frame_stats.tlas_builds += 1;
                        self.frame_stats.tlas_instances_written += n;
                        Ok(())
                    })
            };
            if let Err(e) = r {
                if matches!(e, GpuError::Budget(_)) && !self.is_persistent(t) {
                    // Built over every instance it does not fit: rebuilt from now on (the
                    // caller's retry rebuilds it).
                    tracing::warn!(tlas = t, %e, "persistent TLAS does not fit; rebuilt instead");
                    self.persistent_mode[t as usize] = false;
                }
                proxies
                    .into_iter()
                    .for_each(|(_, _, a)| a.release(&mut self.heap));
                return Err(e);
            }
            updated.push(t);
        }
        let t_update = lap(&mut t_phase);
        let ids = &rebuild_ids[..];
        // 2. TLASes over the resident BLASes plus the proxy instance. Non-resident instances
        // are left out (their proxy boxes stand for them), so a TLAS's size follows what is
        // resident, not its instance count; the custom index keeps each instance's record.
        let ring_region = self.up_mut()?.region_bytes();
        let records = TlasRecords::count(view, &addrs, ids, ring_region, |t| {
            // The proxy's and the marks' records follow the TLAS's own (see
            // `StreamingRenderer::new`); only probe passes' rays see the marks.
            let count = view.tlases[t as usize].instance_count;
            proxies
                .iter()
                .filter(|(pt, _, _)| *pt == t)
                .map(|(_, marks, a)| tail_record(count, *marks, a.address))
                .collect()
        });
        let counts = records.record_counts();
        let mut sizes = Vec::with_capacity(ids.len());
        for &n in &counts {
            let s = ctx.tlas_build_sizes(n, AsBuildFlags::tlas(self.build_opts.compact))?;
            sizes.push(BuildSize {
                result_bytes: s.acceleration_structure_size_bytes,
                scratch_bytes: s.build_scratch_size_bytes,
            });
        }
        // Each TLAS's byte offset in the instance buffer, and the buffer's size.
        let mut offsets = Vec::with_capacity(ids.len());
        let mut total = 0u64;
        for &n in &counts {
            offsets.push(total);
            total += u64::from(n) * RECORD_BYTES as u64;
        }
        self.frame_stats.tlas_builds += ids.len() as u32;
        self.frame_stats.tlas_instances_written += total / RECORD_BYTES as u64;
        let transient = sizes
            .iter()
            .fold(total, |t, s| t + s.result_bytes + s.scratch_bytes);
        let st = &mut self.frame_stats;
        st.tlas_rebuild_transient_bytes = st.tlas_rebuild_transient_bytes.max(transient);
        let t_encode = lap(&mut t_phase);
        let mut t_upload = 0.0;
        let inst_buf = match self.heap.alloc_buffer(
            "stream-tlas-instances",
            total.max(64),
            BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT | BufferUsage::TRANSFER_DST,
            AllocKind::InstanceBuffer,
            MemoryClass::DeviceLocal,
            16,
        ) {
            Ok(b) => b,
            Err(e) => {
                proxies
                    .into_iter()
                    .for_each(|(_, _, a)| a.release(&mut self.heap));
                return Err(e.into());
            }
        };
        let uploaded = (|| -> Result<u64> {
            let up = self.up.as_mut().ok_or_else(staging_released)?;
            if let Err(e) = records.upload(&ctx, up, &inst_buf, &offsets) {
                // Copies queued for the instance buffer must not outlive it.
                up.abandon();
                return Err(e);
            }
            up.flush(&ctx)?;
            Ok(inst_buf.device_address()?.0)
        })();
        // Freed as soon as the TLASes are built (`inputs_done`), before their compacted copies
        // are allocated: the records are read by the build only.
        let mut inst_buf = Some(inst_buf);
        let built = uploaded.and_then(|inst_addr| {
            t_upload = lap(&mut t_phase);
            let mut report = ResourceReport::default();
            build_batched(
                &ctx,
                &mut self.heap,
                &mut report,
                &sizes,
                AsLevel::Top,
                &self.build_opts,
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
            self.heap.free(b);
        }
        let built = match built {
            Ok(b) => b,
            Err(e) => {
                proxies
                    .into_iter()
                    .for_each(|(_, _, a)| a.release(&mut self.heap));
                return Err(e);
            }
        };
        let t_build = lap(&mut t_phase);
        // 3. Swap in; rewrite the proxy PI slots and the marks' BLAS records.
        for (t, order, non_resident) in &pi_rewrites {
            let base = self.proxy_pi_base[*t as usize];
            let marks = proxy_blas_record(
                &view.tlases[*t as usize],
                base + non_resident,
                order.len() as u32 - non_resident,
            );
            let marks_offset = u64::from(self.marks_blas[*t as usize])
                * std::mem::size_of::<motu_abi::BlasRecord>() as u64;
            let pis_buf = &self.tables[self.pis_table];
            let blases_buf = &self.tables[self.blases_table];
            let clusters = &self.clusters[*t as usize];
            let up = self.up.as_mut().ok_or_else(staging_released)?;
            up.upload_with(
                &ctx,
                pis_buf,
                u64::from(base) * std::mem::size_of::<PiRecord>() as u64,
                order.len(),
                |k| proxy_pi(&clusters[order[k] as usize]),
            )?;
            up.upload(&ctx, blases_buf, marks_offset, bytemuck::bytes_of(&marks))?;
        }
        self.up_mut()?.flush(&ctx)?;
        let mut take = |t: u32, marks: bool| {
            proxies
                .iter()
                .position(|(pt, m, _)| *pt == t && *m == marks)
                .map(|p| proxies.swap_remove(p).2)
        };
        for (k, accel) in built {
            let t = ids[k];
            let (proxy, marks) = (take(t, false), take(t, true));
            if let Some(old) = self.tlas[t as usize].replace(TlasGpu {
                accel,
                proxy,
                marks,
                persistent: None,
            }) {
                old.release(&mut self.heap);
            }
            self.dirty.remove(&t);
        }
        for t in updated {
            let (proxy, marks) = (take(t, false), take(t, true));
            if let Some(g) = self.tlas[t as usize].as_mut() {
                g.proxy = proxy;
                g.marks = marks;
            }
            self.dirty.remove(&t);
        }
        tracing::debug!(
            records = total / RECORD_BYTES as u64,
            probe_ms = t_probe,
            update_ms = t_update,
            proxy_boxes = box_count,
            proxy_host_ms = t_proxy_host,
            proxy_build_ms = t_proxy,
            encode_ms = t_encode,
            upload_ms = t_upload,
            build_ms = t_build,
            swap_ms = t_phase.elapsed().as_secs_f64() * 1e3,
            "TLAS rebuild phases"
        );
        Ok(())
    }

    /// Fails fast with the budget's refusal when rebuilding TLASes `ids` cannot fit now:
    /// asks the allocator whether what every attempt holds at once fits (the instance buffer,
    /// the largest TLAS's build scratch and its structure: a subset of the real peak, so a
    /// refusal here is one the build would meet). A refused attempt is retried after evicting
    /// (`with_eviction`, `rebuild_dirty`'s give-back rounds) and used to refuse only after
    /// encoding, uploading every resident instance record and building the proxies: at ⅛ of
    /// the 0.3 island (2.8M resident records per rebuild) 46 TLAS builds for 14 rebuilds,
    /// two thirds of the frame's 13.4 s of TLAS time. Asked, not allocated: allocating and
    /// freeing those buffers (dedicated blocks of up to a gigabyte) took 36–116 ms a rebuild
    /// on the H200, 6% of a frame at a quarter of island 0.3 (BENCHMARKS.md, session 18).
    fn probe_tlas_room(&mut self, ids: &[u32]) -> Result<()> {
        let counts = self.resident_instance_counts();
        let mut records = 0u64;
        let mut largest = (0u64, 0u64);
        for &t in ids {
            // The proxy and the marks (each present when it has a box).
            let cl = &self.clusters[t as usize];
            let proxy = cl.iter().any(|c| self.blas[c.blas as usize].is_none());
            let marks = cl.iter().any(|c| self.blas[c.blas as usize].is_some());
            let n = (counts[t as usize] + u64::from(proxy) + u64::from(marks)).max(1);
            records += n;
            let s = self.ctx.tlas_build_sizes(
                u32::try_from(n).unwrap_or(u32::MAX),
                AsBuildFlags::tlas(self.build_opts.compact),
            )?;
            if s.acceleration_structure_size_bytes > largest.0 {
                largest = (
                    s.acceleration_structure_size_bytes,
                    s.build_scratch_size_bytes,
                );
            }
        }
        let scratch_align = self.ctx.limits().scratch_alignment_bytes();
        Ok(self.heap.try_fit(&[
            FitRequest {
                label: "stream-tlas-probe-instances",
                size_bytes: (records * RECORD_BYTES as u64).max(64),
                usage: BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT | BufferUsage::TRANSFER_DST,
                kind: AllocKind::InstanceBuffer,
                class: MemoryClass::DeviceLocal,
                alignment: 16,
            },
            FitRequest {
                label: "stream-tlas-probe-scratch",
                size_bytes: largest.1.max(scratch_align),
                usage: BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS,
                kind: AllocKind::Scratch,
                class: MemoryClass::DeviceLocal,
                alignment: scratch_align,
            },
            FitRequest {
                label: "stream-tlas-probe",
                size_bytes: largest.0.max(256),
                usage: BufferUsage::ACCELERATION_STRUCTURE_STORAGE,
                kind: AllocKind::TlasStorage,
                class: MemoryClass::DeviceLocal,
                alignment: ACCELERATION_STRUCTURE_OFFSET_ALIGNMENT,
            },
        ])?)
    }

    /// Rebuilds every dirty TLAS, in groups ([`Self::next_rebuild_group`]). When the budget
    /// refuses even with everything unpinned evicted, gives back structures this step built,
    /// least requested first (their pixels stay incomplete); fails only when none is left.
    pub(super) fn rebuild_dirty(&mut self) -> Result<()> {
        let t0 = std::time::Instant::now();
        let r = self.rebuild_dirty_untimed();
        self.frame_stats.tlas_ms += t0.elapsed().as_secs_f64() * 1e3;
        r
    }

    /// Per TLAS: instance records of resident BLASes now (what its rebuild holds).
    pub(super) fn resident_instance_counts(&self) -> Vec<u64> {
        let mut counts = vec![0u64; self.view.tlases.len()];
        for (b, a) in self.blas.iter().enumerate() {
            if a.is_some() {
                self.add_instance_counts(b as u32, &mut counts);
            }
        }
        counts
    }

    /// Adds BLAS `b`'s instance records to `counts`, per parent TLAS.
    pub(super) fn add_instance_counts(&self, b: u32, counts: &mut [u64]) {
        let b = b as usize;
        for (&t, &n) in self.parents[b].iter().zip(&self.parent_counts[b]) {
            counts[t as usize] += u64::from(n);
        }
    }

    /// Bytes rebuilding TLAS `t` with `count` resident instance records takes beyond what its
    /// current build holds (instance buffer, structure, scratch; the proxy, its boxes and the
    /// fragmentation of blocks by a quarter more); 0 for a persistent TLAS.
    pub(super) fn tlas_rebuild_bytes(&self, t: u32, count: u64) -> Result<u64> {
        if self.is_persistent(t) {
            // Updated in place with its kept scratch: only its proxy and marks are rebuilt.
            return Ok(0);
        }
        let count = count + 2;
        let s = self.ctx.tlas_build_sizes(
            u32::try_from(count).unwrap_or(u32::MAX),
            AsBuildFlags::tlas(self.build_opts.compact),
        )?;
        let need = count * RECORD_BYTES as u64
            + s.acceleration_structure_size_bytes
            + s.build_scratch_size_bytes;
        let old = self.tlas[t as usize]
            .as_ref()
            .map_or(0, |g| g.accel.size_bytes);
        Ok((need + need / 4).saturating_sub(old))
    }

    fn rebuild_dirty_untimed(&mut self) -> Result<()> {
        // Each group's rebuild settles (or fails) on its own; evictions for one group may
        // dirty TLASes another group rebuilt, which the next round picks up.
        let mut rounds = 0usize;
        while !self.dirty.is_empty() {
            rounds += 1;
            if rounds > 64 + 4 * (self.view.tlases.len() + self.item_count()) {
                return Err(GpuError::InvalidRequest(
                    "streaming: TLAS rebuilds do not settle".into(),
                ));
            }
            let (group, need) = self.next_rebuild_group()?;
            self.rebuild_group(&group, need)?;
            self.frame_stats.tlas_rebuild_groups += 1;
        }
        Ok(())
    }

    /// The dirty TLASes to rebuild together next: the one whose rebuild needs the most room,
    /// then the next largest while the group's rebuilds together need no more than that one
    /// or a 64th of the budget. A TLAS split into pieces (when the streamer loads the
    /// package, `--stream-split-instances`, or at import, `--max-instances`) is thus rebuilt
    /// piece by piece, each piece's instance buffer, scratch and new structure released or
    /// kept before the next: the room a rebuild takes from resident BLASes is one piece's, not
    /// the whole root's (at a quarter of island 0.3 split into 1M-instance pieces: 0.25 GB
    /// against 1.9 GB rebuilt at once, 2.6 passes and 1.2 s a frame against 3.5 passes and
    /// 4.5 s; BENCHMARKS.md, session 21). Small TLASes still share one batch (one submission,
    /// one instance buffer).
    /// Returns the group and the room its rebuilds need together.
    fn next_rebuild_group(&self) -> Result<(Vec<u32>, u64)> {
        let counts = self.resident_instance_counts();
        let mut need: Vec<(u64, u32)> = Vec::with_capacity(self.dirty.len());
        for &t in &self.dirty {
            need.push((self.tlas_rebuild_bytes(t, counts[t as usize])?, t));
        }
        Ok(group_by_need(need, self.build_opts.budget_bytes))
    }

    /// Rebuilds the TLASes of `group` that are dirty (see [`Self::rebuild_dirty`]); `need`: the
    /// room their rebuilds take ([`Self::next_rebuild_group`], all of them dirty when chosen).
    fn rebuild_group(&mut self, group: &[u32], need: u64) -> Result<()> {
        let target = |s: &Self| -> Vec<u32> {
            group
                .iter()
                .copied()
                .filter(|t| s.dirty.contains(t))
                .collect()
        };
        if !target(self).is_empty() {
            // Room made once up front: each refused attempt re-encodes and re-uploads every
            // resident instance record of the dirty TLASes.
            // TLASes, their scratch and instance buffers are large (dedicated blocks): count
            // only budget no block holds as free, and evict a quarter more for fragmentation.
            let free = |s: &Self| {
                let r = s.heap.report();
                r.budget_bytes.saturating_sub(r.budget_block_bytes)
            };
            // A few rounds at most: evicted items free whole blocks only when they empty
            // them, so this could otherwise evict everything unpinned.
            let mut short = need.saturating_sub(free(self));
            if short > 0 && self.opts.defrag {
                // Whole blocks freed by moving what sparse ones hold, before evicting.
                self.defragment(short)?;
                short = need.saturating_sub(free(self));
            }
            // What the rebuild needs against what blocks leave free (`MOTU_LOG`), the numbers
            // behind `evicted_for_tlas`.
            tracing::debug!(
                need,
                free = free(self),
                dirty = self.dirty.len(),
                group = group.len(),
                records = self.resident_instance_counts().iter().sum::<u64>(),
                "TLAS rebuild room"
            );
            let mut rounds = 0;
            while short > 0 && rounds < 4 && self.evict_some(short, EvictWhy::TlasRoom)? {
                short = need.saturating_sub(free(self));
                rounds += 1;
            }
        }
        let mut rounds = 0;
        while !target(self).is_empty() {
            rounds += 1;
            if rounds > 64 + self.item_count() {
                return Err(GpuError::InvalidRequest(
                    "streaming: TLAS rebuilds do not settle".into(),
                ));
            }
            let ids: Vec<u32> = target(self);
            let rebuilt = ids.len() as u32;
            match self.with_eviction(|s| {
                // Eviction may have given some up (a child TLAS): rebuild what is still dirty.
                let now: Vec<u32> = target(s);
                s.build_tlases(&now)
            }) {
                Ok(()) => self.frame_stats.tlas_rebuilt += rebuilt,
                Err(GpuError::Budget(_)) if self.unpin_pass_pins() => {}
                Err(GpuError::Budget(msg)) => {
                    // Give back about a 32nd of the budget of this step's builds per round
                    // (least requested first): one at a time would re-encode every instance
                    // record once per structure.
                    let step = (self.build_opts.budget_bytes / 32).max(1);
                    let mut given = 0u64;
                    while given < step && self.built_now.len() > 1 {
                        let b = self.built_now.pop().unwrap_or_default();
                        given += self.blas_bytes[b as usize];
                        self.frame_stats.deferred += 1;
                        if self.residency.contains(ItemId(b)) {
                            self.evict(b as usize);
                            self.frame_stats.evicted -= 1;
                        }
                    }
                    let Some(last) = self.built_now.pop() else {
                        let report = self.heap.report();
                        return Err(GpuError::Budget(format!(
                            "streaming: rebuilding {} TLAS(es) does not fit under the budget of \
                             {} bytes with every evictable structure evicted ({} bytes in use, \
                             skeleton {} bytes); raise --vram-budget ({msg})",
                            ids.len(),
                            report.budget_bytes,
                            report.budget_in_use_bytes,
                            self.totals.skeleton_bytes
                        )));
                    };
                    self.frame_stats.deferred += 1;
                    if self.residency.contains(ItemId(last)) {
                        self.evict(last as usize);
                        // Given back, not evicted for room: count it as deferred only.
                        self.frame_stats.evicted -= 1;
                    }
                }
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }
}

/// Of dirty TLASes given as (room its rebuild needs, TLAS), those to rebuild together: the
/// largest, then the next largest while the sum stays within that one's need or a 64th of
/// `budget_bytes` (see `next_rebuild_group`); with the group's need summed.
fn group_by_need(mut need: Vec<(u64, u32)>, budget_bytes: u64) -> (Vec<u32>, u64) {
    // Largest first, ties by index (a stable order across runs).
    need.sort_by_key(|&(n, t)| (std::cmp::Reverse(n), t));
    let cap = need.first().map_or(0, |&(n, _)| n.max(budget_bytes / 64));
    let mut sum = 0u64;
    let mut group = Vec::new();
    for (n, t) in need {
        if group.is_empty() || sum + n <= cap {
            sum += n;
            group.push(t);
        }
    }
    (group, sum)
}

#[cfg(test)]
mod tests {
    use super::group_by_need;

    #[test]
    fn large_rebuilds_go_alone_and_small_ones_together() {
        let budget = 64 * 100;
        // Three pieces over a 64th of the budget, three small TLASes.
        let mut dirty = vec![(10, 4), (250, 1), (1, 6), (300, 0), (5, 5), (200, 2)];
        let mut groups = Vec::new();
        while !dirty.is_empty() {
            let (g, need) = group_by_need(dirty.clone(), budget);
            let listed: u64 = dirty
                .iter()
                .filter(|(_, t)| g.contains(t))
                .map(|p| p.0)
                .sum();
            assert_eq!(need, listed);
            dirty.retain(|(_, t)| !g.contains(t));
            groups.push(g);
        }
        assert_eq!(groups, vec![vec![0], vec![1], vec![2], vec![4, 5, 6]]);
        // One TLAS over the cap still gets a group of its own.
        assert_eq!(group_by_need(vec![(9000, 3)], budget), (vec![3], 9000));
        // Equal needs: by index; two that fit a 64th together share a group.
        assert_eq!(
            group_by_need(vec![(40, 2), (40, 1)], budget),
            (vec![1, 2], 80)
        );
        assert_eq!(group_by_need(vec![(60, 2), (60, 1)], budget), (vec![1], 60));
        assert!(group_by_need(Vec::new(), budget).0.is_empty());
    }
}
