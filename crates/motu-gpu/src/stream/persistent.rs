//! Persistent TLASes: a streamed TLAS that holds every one of its instances, resident or not,
//! and follows residency by an *update* (a refit with new instance records) instead of a
//! rebuild.
//!
//! A rebuilt TLAS holds only resident instances, so its storage follows residency, but each
//! rebuild needs its instance records, a new structure and its build scratch at once: at a
//! quarter of island 0.3 about 2.1 GB for a 7M-record rebuild, a quarter of the room, taken
//! from the BLASes several times a frame (their eviction and rebuilding is most of the
//! frame's passes; BENCHMARKS.md, session 18). A persistent TLAS is built once over all its
//! instances (plus its proxy and marks slots) with `ALLOW_UPDATE`; its records live in host
//! memory (the build reads them over the bus: no VRAM on a discrete GPU) and are patched in
//! place where a BLAS's residency changed, and its update needs only a small scratch kept
//! with it. The cost is the structure's size at full residency, resident for good.
//!
//! An instance whose BLAS is not resident references the BLAS's *placeholder*: an AABB BLAS
//! with one box, a point at the centre of the BLAS's bounds, under instance mask 0 (no ray
//! meets it, and a refit shrinks the nodes over non-resident instances, so rays skip them:
//! the instance LOD pass, `scene/lod_pass.rs`, does the same). Updates may change an
//! instance's reference and mask but not make an active instance inactive, and a refit keeps
//! the topology the first build chose: the first build uses *full* placeholders, the BLASes'
//! whole bounds, so the topology is the one a full build would choose, and an update right
//! after it puts the non-resident instances on their points (the full placeholders are then
//! released). Proxy boxes and
//! demand work as before (the proxy and marks BLASes are rebuilt and their slots repointed;
//! an absent one points at the empty placeholder, mask 0).

use motu_abi::HierarchyView;
use motu_alloc::{AllocKind, BuildSize, MemoryClass};
use motu_vk::{AsBuild, AsBuildFlags, AsBuildMode, AsGeometry, AsLevel, BufferUsage, HeapBuffer};
use rayon::prelude::*;

use super::tlas_records::{instance_record, tail_record, RECORD_BYTES};
use super::StreamingRenderer;
use crate::error::{GpuError, Result};
use crate::scene::{aabbs_geometry, build_batched, set_instance_mask, AccelStruct, ResourceReport};

/// How streamed TLASes follow residency (`--stream-tlas`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TlasUpdate {
    /// Persistent TLASes (updated) for TLASes of a million instances and more that take at
    /// most an eighth of the budget (`auto_persistent`), else rebuilt.
    #[default]
    Auto,
    /// Persistent TLASes wherever the device allows (instance counts), whatever they take.
    Update,
    /// TLASes rebuilt over their resident instances whenever residency changes.
    Rebuild,
}

impl TlasUpdate {
    /// The name `--stream-tlas` takes and `--stats` reports.
    pub fn name(self) -> &'static str {
        match self {
            TlasUpdate::Auto => "auto",
            TlasUpdate::Update => "update",
            TlasUpdate::Rebuild => "rebuild",
        }
    }
}

/// A persistent TLAS's state beside its structure.
pub(super) struct Persistent {
    /// Host-visible instance records, every instance then the proxy and marks slots.
    records: HeapBuffer,
    /// Update scratch, kept.
    scratch: HeapBuffer,
    /// Per BLAS: the reference its instances' records hold now.
    written: Vec<u64>,
    record_count: u32,
}

impl Persistent {
    pub(super) fn record_count(&self) -> u32 {
        self.record_count
    }

    pub(super) fn release(self, heap: &mut motu_vk::GpuHeap) {
        heap.free(self.records);
        heap.free(self.scratch);
    }

    /// VRAM bytes beside the structure (the update scratch; the records where host memory
    /// counts).
    pub(super) fn size_bytes(&self, host_counts: bool) -> u64 {
        self.scratch.size_bytes()
            + if host_counts {
                self.records.size_bytes()
            } else {
                0
            }
    }
}

/// Build flags of a persistent TLAS (the size query and the build must agree): fast trace,
/// updatable, not compacted (a compacted copy would need the full size again beside it, and
/// TLAS compaction saves 0–2%).
pub(super) fn persistent_flags() -> AsBuildFlags {
    AsBuildFlags {
        allow_update: true,
        allow_compaction: false,
        ..AsBuildFlags::default()
    }
}

/// Instances the persistent candidates must hold together before `Auto` makes them
/// persistent: below it a rebuild takes milliseconds (lavapipe, the default island's 22k
/// instances: 2–6 ms) while tracing past the placeholders costs more (lavapipe: traces
/// 1.5–2× slower), where at island 0.3 (9M instances, H200) an update takes 60 ms against a
/// rebuild's 170–260 ms (BENCHMARKS.md, session 19).
pub(super) const AUTO_MIN_INSTANCES: u64 = 1 << 20;

/// The share of the budget persistent TLASes (and their placeholders) may take under `Auto`:
/// an eighth. On the H200 at island 0.3 they take 1.8 GB: at half its full build (9% of the
/// budget) frames took half the time; at a quarter (18%) the room they took from the BLASes
/// (working set 7.25 GB against a room of 7.30 GB) cost 1.5 passes more a frame and 75% more
/// time (BENCHMARKS.md, session 19).
pub(super) const AUTO_MAX_BUDGET_SHARE: u64 = 8;

/// `Auto`'s choice: persistent when the candidates hold at least [`AUTO_MIN_INSTANCES`]
/// instances and take at most `1 / AUTO_MAX_BUDGET_SHARE` of the budget.
pub(super) fn auto_persistent(instances: u64, persistent_bytes: u64, budget_bytes: u64) -> bool {
    instances >= AUTO_MIN_INSTANCES && persistent_bytes <= budget_bytes / AUTO_MAX_BUDGET_SHARE
}

/// Records of a persistent TLAS over `instance_count` instances: theirs, the proxy, the marks.
pub(super) fn persistent_records(instance_count: u32) -> u32 {
    instance_count + 2
}

/// What persistent TLASes would keep resident (`StreamOptions::tlas_update`), by size queries:
/// the renderer's `auto` decides on it and `motu report` prints it
/// (`streaming.persistent_tlas`), so users see at which budget `auto` turns to updates.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PersistentEstimate {
    /// The TLASes that would be persistent, and the instances they hold together.
    pub tlases: u32,
    pub instances: u64,
    /// Their structures at full residency, update scratch and placeholders (and their instance
    /// records where host memory counts against the budget).
    pub bytes: u64,
    /// The least budget at which `auto` makes them persistent; `None`: never (fewer than
    /// 2^20 instances, where a rebuild takes milliseconds).
    pub auto_min_budget_bytes: Option<u64>,
}

/// [`PersistentEstimate`] of `view`'s candidates (`has_clusters`: TLASes with triangle
/// instances; at most `max_instances` records each), with `placeholder_bytes` per placeholder
/// BLAS and `updatable(records)` = (structure, update scratch) of a TLAS built with
/// [`persistent_flags`] ([`FloorSizes::tlas_updatable`](super::FloorSizes::tlas_updatable)).
/// `host_records`: instance records (host memory) count too.
pub(super) fn persistent_estimate(
    view: &HierarchyView<'_>,
    has_clusters: &[bool],
    max_instances: u64,
    host_records: bool,
    placeholder_bytes: u64,
    mut updatable: impl FnMut(u32) -> Result<Option<(u64, u64)>>,
) -> Result<(Vec<u32>, PersistentEstimate)> {
    let candidates: Vec<u32> = persistent_candidates(view, has_clusters)
        .into_iter()
        .filter(|&t| {
            u64::from(persistent_records(view.tlases[t as usize].instance_count)) <= max_instances
        })
        .collect();
    if candidates.is_empty() {
        return Ok((candidates, PersistentEstimate::default()));
    }
    let mut bytes = 0u64;
    let mut instances = 0u64;
    for &t in &candidates {
        let n = persistent_records(view.tlases[t as usize].instance_count);
        let (structure, scratch) = updatable(n)?
            .ok_or_else(|| GpuError::InvalidRequest("no size query for updatable TLASes".into()))?;
        let records = if host_records {
            u64::from(n) * RECORD_BYTES as u64
        } else {
            0
        };
        bytes += structure + scratch + records;
        instances += u64::from(view.tlases[t as usize].instance_count);
    }
    // One placeholder per buildable BLAS, plus the empty one.
    let placeholders = view.blases.iter().filter(|b| super::streamable(b)).count() as u64 + 1;
    bytes += placeholders * placeholder_bytes.div_ceil(256) * 256;
    let auto_min_budget_bytes =
        (instances >= AUTO_MIN_INSTANCES).then(|| bytes.saturating_mul(AUTO_MAX_BUDGET_SHARE));
    let estimate = PersistentEstimate {
        tlases: candidates.len() as u32,
        instances,
        bytes,
        auto_min_budget_bytes,
    };
    Ok((candidates, estimate))
}

/// The TLASes that may be persistent: those with triangle instances (the others never change)
/// whose records' custom indices fit 24 bits.
pub(super) fn persistent_candidates(view: &HierarchyView<'_>, has_clusters: &[bool]) -> Vec<u32> {
    (0..view.tlases.len() as u32)
        .filter(|&t| {
            has_clusters[t as usize]
                && persistent_records(view.tlases[t as usize].instance_count) < 1 << 24
        })
        .collect()
}

impl StreamingRenderer<'_> {
    /// Encodes instance `j` of TLAS `t` as the persistent TLAS holds it: its BLAS if resident
    /// (`addrs`), else its placeholder under mask 0. Flags and shader offset are the
    /// resident instance's either way, so an update changes only the reference and the mask.
    fn persistent_record(&self, t: u32, j: usize, addrs: &[u64], full: bool) -> [u8; RECORD_BYTES] {
        let rec = &self.view.tlases[t as usize];
        let inst = &self.view.instances[rec.instance_range()][j];
        let b = inst.blas as usize;
        let mut enc = instance_record(&self.view, inst, j as u32, self.reference(b, addrs, full));
        if addrs[b] == 0 {
            set_instance_mask(&mut enc, 0);
        }
        enc
    }

    /// What BLAS `b`'s instances reference: the BLAS if resident (`addrs`), else its
    /// placeholder (`full`: see [`Self::placeholder`]).
    fn reference(&self, b: usize, addrs: &[u64], full: bool) -> u64 {
        if addrs[b] != 0 {
            addrs[b]
        } else {
            self.placeholder(b, full)
        }
    }

    /// BLAS `b`'s placeholder: its bounds' centre, or (`full`, while they exist) its whole
    /// bounds; the empty one where it has none.
    fn placeholder(&self, b: usize, full: bool) -> u64 {
        let ph = self.tlases.placeholders();
        let whole = if full {
            ph.full_per_blas.get(b).copied()
        } else {
            None
        };
        let p = whole
            .filter(|&a| a != 0)
            .or_else(|| ph.per_blas.get(b).copied())
            .unwrap_or(0);
        if p != 0 {
            p
        } else {
            ph.empty
        }
    }

    /// The proxy's (`marks` false) or marks' record of persistent TLAS `t`: `addr`, or the
    /// empty placeholder under mask 0 when absent.
    fn persistent_tail(&self, t: u32, marks: bool, addr: u64) -> [u8; RECORD_BYTES] {
        let blas_record = self.topo.proxy_blas_record(t as usize, marks);
        if addr != 0 {
            return tail_record(blas_record, marks, addr);
        }
        let mut inst = tail_record(blas_record, marks, self.tlases.placeholders().empty);
        set_instance_mask(&mut inst, 0);
        inst
    }

    /// Builds the placeholders once, for the persistent TLASes: per buildable BLAS a point at
    /// its bounds' centre and (for the first builds only) its whole bounds, and one empty box
    /// at the origin.
    pub(super) fn build_placeholders(&mut self) -> Result<()> {
        let view = self.view;
        let nb = view.blases.len();
        let mut boxes: Vec<[f32; 6]> = Vec::new();
        // (BLAS, full) per box; None: the empty one.
        let mut owner: Vec<Option<(usize, bool)>> = Vec::new();
        for b in 0..nb {
            if !self.topo.buildable(b) {
                continue;
            }
            let r = &view.blases[b];
            if (0..3).all(|k| r.bounds_min[k] <= r.bounds_max[k]) {
                let whole = r.bounds_box();
                let c: [f32; 3] = std::array::from_fn(|k| 0.5 * (whole[k] + whole[k + 3]));
                boxes.push(whole);
                owner.push(Some((b, true)));
                boxes.push([c[0], c[1], c[2], c[0], c[1], c[2]]);
                owner.push(Some((b, false)));
            }
        }
        boxes.push([0.0; 6]);
        owner.push(None);
        let ctx = self.ctx.clone();
        let buf = self.heap.alloc_buffer(
            "placeholder-aabbs",
            (boxes.len() * 24) as u64,
            BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT | BufferUsage::TRANSFER_DST,
            AllocKind::Geometry,
            MemoryClass::DeviceLocal,
            16,
        )?;
        let r = (|| -> Result<Vec<(usize, AccelStruct)>> {
            self.up_mut()?
                .upload(&ctx, &buf, 0, bytemuck::cast_slice(&boxes))?;
            self.up_mut()?.flush(&ctx)?;
            let base = buf.device_address()?.0;
            let sizes = vec![self.placeholder_build_size()?; boxes.len()];
            let mut report = ResourceReport::default();
            build_batched(
                &ctx,
                &mut self.heap,
                &mut report,
                &sizes,
                AsLevel::Bottom,
                &self.build_opts,
                |k| (vec![aabbs_geometry(base + k as u64 * 24, true)], vec![1]),
                |_, _| Ok(()),
                &mut |_| {},
            )
        })();
        self.heap.free(buf);
        let built = r?;
        let ph = self.tlases.placeholders_mut();
        ph.per_blas = vec![0u64; nb];
        ph.full_per_blas = vec![0u64; nb];
        for (k, a) in built {
            match owner[k] {
                Some((b, true)) => {
                    ph.full_per_blas[b] = a.address;
                    ph.full_structures.push(a);
                }
                Some((b, false)) => {
                    ph.per_blas[b] = a.address;
                    ph.bytes += a.size_bytes;
                    ph.structures.push(a);
                }
                None => {
                    ph.empty = a.address;
                    ph.bytes += a.size_bytes;
                    ph.structures.push(a);
                }
            }
        }
        Ok(())
    }

    /// The build sizes of one placeholder (an AABB BLAS of one box, built as BLASes are).
    pub(super) fn placeholder_build_size(&self) -> Result<BuildSize> {
        let s = self.ctx.blas_build_sizes(
            &[motu_vk::BlasGeometry::Aabbs {
                aabb_count: 1,
                opaque: true,
            }],
            self.build_opts.blas_build.flags(),
        )?;
        Ok(BuildSize {
            result_bytes: s.acceleration_structure_size_bytes,
            scratch_bytes: s.build_scratch_size_bytes,
        })
    }

    /// Turns every persistent TLAS into a rebuilt one (released now, dirty: the step's
    /// rebuild builds it over the resident instances) and releases the placeholders: the
    /// floor is sized for rebuilt TLASes, so a BLAS that does not fit next to persistent ones
    /// fits without them. Returns whether there was any.
    pub(super) fn drop_persistent(&mut self) -> bool {
        let any = self.tlases.end_persistent_mode(&mut self.heap);
        if any {
            tracing::warn!(
                persistent_tlas_bytes = self.totals.persistent_tlas_bytes,
                "a BLAS does not fit next to the persistent TLASes: TLASes are rebuilt from now on"
            );
            self.tlases.placeholders_mut().release(&mut self.heap);
            self.totals.tlas_mode = "rebuild";
            self.totals.persistent_tlases = 0;
            self.totals.persistent_tlas_bytes = 0;
            self.totals.persistent_dropped = true;
        }
        any
    }

    /// Builds persistent TLAS `t` over every instance (the first time), records from the
    /// current residency (`addrs`) and its proxy and marks (`tail`, 0: absent). On failure
    /// nothing stays allocated.
    pub(super) fn build_persistent(
        &mut self,
        t: u32,
        addrs: &[u64],
        tail: [u64; 2],
    ) -> Result<(AccelStruct, Persistent)> {
        let ctx = self.ctx.clone();
        let count = self.view.tlases[t as usize].instance_count;
        let n = persistent_records(count);
        let sizes = ctx.tlas_build_sizes(n, persistent_flags())?;
        let records = self.heap.alloc_buffer(
            &format!("stream-tlas-{t}-records"),
            u64::from(n) * RECORD_BYTES as u64,
            BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT,
            AllocKind::InstanceBuffer,
            MemoryClass::HostVisible,
            16,
        )?;
        let filled = records.with_mapped_mut(0, n as usize * RECORD_BYTES, |out| {
            let (body, rest) = out.split_at_mut(count as usize * RECORD_BYTES);
            body.par_chunks_mut(RECORD_BYTES)
                .enumerate()
                .for_each(|(j, r)| r.copy_from_slice(&self.persistent_record(t, j, addrs, true)));
            rest[..RECORD_BYTES].copy_from_slice(&self.persistent_tail(t, false, tail[0]));
            rest[RECORD_BYTES..].copy_from_slice(&self.persistent_tail(t, true, tail[1]));
        });
        if let Err(e) = filled {
            self.heap.free(records);
            return Err(e.into());
        }
        let accel = match AccelStruct::new(
            &ctx,
            &mut self.heap,
            &format!("stream-tlas-{t}"),
            sizes.acceleration_structure_size_bytes,
            AsLevel::Top,
        ) {
            Ok(a) => a,
            Err(e) => {
                self.heap.free(records);
                return Err(e.into());
            }
        };
        let r = (|| -> Result<HeapBuffer> {
            let build_scratch =
                self.alloc_scratch("stream-tlas-build-scratch", sizes.build_scratch_size_bytes)?;
            let r = self.record_tlas_build(&accel, &records, &build_scratch, n, false);
            self.heap.free(build_scratch);
            r?;
            self.alloc_scratch(
                "stream-tlas-update-scratch",
                sizes.update_scratch_size_bytes,
            )
        })();
        match r {
            Ok(scratch) => {
                // The caller's first update puts non-resident instances on their points.
                let written = (0..addrs.len())
                    .map(|b| self.reference(b, addrs, true))
                    .collect();
                Ok((
                    accel,
                    Persistent {
                        records,
                        scratch,
                        written,
                        record_count: n,
                    },
                ))
            }
            Err(e) => {
                accel.release(&mut self.heap);
                self.heap.free(records);
                Err(e)
            }
        }
    }

    /// Updates persistent TLAS `t` to the current residency (`addrs`) and proxy and marks
    /// (`tail`): patches the records of instances whose BLAS's reference changed, in place,
    /// then refits. Returns the records rewritten (the proxy's and marks' always).
    pub(super) fn update_persistent(
        &mut self,
        t: u32,
        addrs: &[u64],
        tail: [u64; 2],
    ) -> Result<u64> {
        let Some(mut g) = self.tlases.take_for_update(t) else {
            return Err(GpuError::InvalidRequest(format!(
                "streaming: persistent TLAS {t} is not resident"
            )));
        };
        let r = (|| -> Result<u64> {
            let (accel, p) = g.update_parts();
            let p = p.ok_or_else(|| {
                GpuError::InvalidRequest(format!("streaming: TLAS {t} is not persistent"))
            })?;
            let want: Vec<u64> = (0..addrs.len())
                .map(|b| self.reference(b, addrs, false))
                .collect();
            // Updated even when no record changes: the TLAS is dirty because a BLAS came or
            // went, so its proxy and marks were rebuilt, maybe at the same addresses with other
            // boxes, and the refit must see their bounds.
            let changed: Vec<bool> = want.iter().zip(&p.written).map(|(a, b)| a != b).collect();
            let count = self.view.tlases[t as usize].instance_count as usize;
            let range = self.view.tlases[t as usize].instance_range();
            let instances = &self.view.instances[range];
            let this = &*self;
            let rewritten = p.records.with_mapped_mut(
                0,
                p.record_count as usize * RECORD_BYTES,
                |out| -> u64 {
                    let (body, rest) = out.split_at_mut(count * RECORD_BYTES);
                    // Chunks of records, each scanned for instances of changed BLASes.
                    const CHUNK: usize = 1 << 14;
                    let n: u64 = body
                        .par_chunks_mut(CHUNK * RECORD_BYTES)
                        .enumerate()
                        .map(|(c, chunk)| {
                            let mut n = 0u64;
                            for (k, r) in chunk.chunks_exact_mut(RECORD_BYTES).enumerate() {
                                let j = c * CHUNK + k;
                                if changed[instances[j].blas as usize] {
                                    r.copy_from_slice(&this.persistent_record(t, j, addrs, false));
                                    n += 1;
                                }
                            }
                            n
                        })
                        .sum();
                    rest[..RECORD_BYTES].copy_from_slice(&this.persistent_tail(t, false, tail[0]));
                    rest[RECORD_BYTES..].copy_from_slice(&this.persistent_tail(t, true, tail[1]));
                    n + 2
                },
            )?;
            self.record_tlas_build(accel, &p.records, &p.scratch, p.record_count, true)?;
            p.written = want;
            Ok(rewritten)
        })();
        self.tlases.put_back(t, g);
        r
    }

    fn alloc_scratch(&mut self, label: &str, size_bytes: u64) -> Result<HeapBuffer> {
        let align = self.ctx.limits().scratch_alignment_bytes();
        // One alignment more: the scratch address is rounded up to it inside the buffer.
        Ok(self.heap.alloc_buffer(
            label,
            size_bytes + align,
            BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS,
            AllocKind::Scratch,
            MemoryClass::DeviceLocal,
            align,
        )?)
    }

    /// Builds (`update` false) or updates in place `accel` from `n` records, and waits.
    fn record_tlas_build(
        &self,
        accel: &AccelStruct,
        records: &HeapBuffer,
        scratch: &HeapBuffer,
        n: u32,
        update: bool,
    ) -> Result<()> {
        let geometry = [AsGeometry::Instances {
            address: records.device_address()?.0,
        }];
        let align = self.ctx.limits().scratch_alignment_bytes();
        let scratch_address = scratch.device_address()?.0.div_ceil(align) * align;
        let build = AsBuild {
            level: AsLevel::Top,
            flags: persistent_flags(),
            // An update reads and writes the same structure, which the spec allows in place;
            // it was built with ALLOW_UPDATE over the same record count.
            mode: if update {
                AsBuildMode::UpdateInPlace
            } else {
                AsBuildMode::Build
            },
            dst: accel.target(),
            geometries: &geometry,
            primitive_counts: &[n],
            scratch_address,
        };
        let mut rec = self.ctx.record(if update {
            "tlas update"
        } else {
            "tlas build (persistent)"
        })?;
        // The structure, the records (host-visible, written before this submission and not
        // touched until it is waited on) and the scratch (aligned inside its buffer: allocated
        // with the device's scratch alignment) live until `submit_and_wait` returns.
        rec.barrier();
        rec.build_acceleration_structures(&[build])?;
        rec.barrier();
        rec.submit_and_wait().map_err(Into::into)
    }
}

/// The placeholders of the persistent TLASes (see the module docs).
#[derive(Default)]
pub(super) struct Placeholders {
    /// Per BLAS: its placeholder's address, a point (0: none; the empty one stands in).
    pub(super) per_blas: Vec<u64>,
    /// Per BLAS: the placeholder of its whole bounds, for the persistent TLASes' first builds
    /// (released after them: `release_full`).
    pub(super) full_per_blas: Vec<u64>,
    pub(super) full_structures: Vec<AccelStruct>,
    /// The empty box's placeholder (absent proxies and marks, BLASes without bounds).
    pub(super) empty: u64,
    pub(super) bytes: u64,
    pub(super) structures: Vec<AccelStruct>,
}

impl Placeholders {
    /// Releases the whole-bounds placeholders (no persistent TLAS references them once its
    /// first update ran).
    pub(super) fn release_full(&mut self, heap: &mut motu_vk::GpuHeap) {
        for a in self.full_structures.drain(..) {
            a.release(heap);
        }
        self.full_per_blas.clear();
    }

    pub(super) fn release(&mut self, heap: &mut motu_vk::GpuHeap) {
        self.release_full(heap);
        for a in self.structures.drain(..) {
            a.release(heap);
        }
        self.per_blas.clear();
        self.empty = 0;
        self.bytes = 0;
    }
}

#[cfg(test)]
mod tests;
