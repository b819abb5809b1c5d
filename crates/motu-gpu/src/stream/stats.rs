//! What a [`StreamingRenderer`](super::StreamingRenderer) reports: per frame
//! ([`FrameStreamStats`], with a [`PassStats`] a pass) and over the run ([`StreamTotals`]).
//! Their JSON is `motu_render::stats` (`stream` in `--stats`), whose conversion names every
//! field: a field added here gets its key there.

pub use super::room_split::RoomSplit;

/// Per-frame streaming statistics (`--stats`, one entry per frame).
#[derive(Clone, Debug, Default)]
pub struct FrameStreamStats {
    pub frame: u64,
    /// Build–traverse passes this frame.
    pub passes: u32,
    /// False when `max_passes` ran out with pixels still incomplete.
    pub complete: bool,
    /// Pixels still incomplete after the last pass (rendered as misses, or as the fallback).
    pub incomplete_pixels: u64,
    /// Of those, pixels shown by the fallback (`StreamOptions::fallback`): not exact.
    pub fallback_pixels: u64,
    /// TLASes left *stale* after the frame (its prefetch included): dirty only because
    /// BLASes under them were built, traced as they are (their proxies keep those BLASes'
    /// rays open, on the fallback) and rebuilt by later frames within their build budget.
    /// Only frames with a build budget in milliseconds leave any (`stream/piece_order.rs`);
    /// a frame that leaves any is not `complete`.
    pub tlas_pieces_stale: u32,
    /// Of `incomplete_pixels`: those whose closest-hit ray waits for a BLAS that was resident
    /// (its box met in a stale TLAS's proxy). Pixels open only for secondary rays name no
    /// structure and are not counted here.
    pub stale_blocked_pixels: u64,
    /// Stale TLASes rebuilt by the frame's build steps within the budget (of `tlas_rebuilt`).
    pub tlas_stale_rebuilt: u32,
    /// The frame stopped because its build budget (`frame_build_bytes`/`frame_build_ms`) was
    /// spent.
    pub build_budget_spent: bool,
    /// Build queues of this frame that stopped because the next BLAS did not fit the free
    /// room while the frame flew (on the clock, progressive, its next camera another:
    /// `flying.rs`), where it evicts nothing; what they left shows the fallback until the
    /// camera rests.
    pub flying_no_room: u32,
    /// Pixels whose traversal was cut short this frame (a stack overflow or the trace cap).
    pub truncated_rays: u64,
    /// Pixels traced again in passes after the first.
    pub reshot_pixels: u64,
    /// Guard-band rays traced (prefetch probes).
    pub guard_rays: u64,
    /// Triangle BLASes built (demand plus prefetch).
    pub blas_built: u32,
    /// Child TLASes made resident.
    pub tlas_built: u32,
    /// Resident TLASes rebuilt because their instance set changed (with their proxies).
    pub tlas_rebuilt: u32,
    /// Groups those rebuilds ran in: large TLASes (the pieces of a split root) one at a time,
    /// small ones together, so a rebuild's transient is one group's.
    pub tlas_rebuild_groups: u32,
    /// Structures built after the frame from the guard band and the next camera's probe.
    pub prefetched: u32,
    /// Structures the prefetch wanted but left unbuilt: no room beside what the probe saw
    /// resident and the TLAS rebuilds' reserve (the next frame's first pass opens those its
    /// rays need).
    pub prefetch_skipped: u32,
    /// The prefetch kept what this frame's passes saw beside what the probe met: the frame's
    /// working set fit its room next to its `tlas_rebuild_transient_bytes` and the free space
    /// inside blocks (`StreamOptions::prefetch_keeps_frame`).
    pub prefetch_kept_frame: bool,
    /// Rays of the probe of the next frame's camera (its pixels' primary rays; 0: no probe),
    /// and the probe's trace time (not in `trace_ms`).
    pub probe_rays: u64,
    pub probe_ms: f64,
    /// The next frame's camera was this frame's and all the frame saw is still resident (it
    /// took one pass, or no later pass evicted what an earlier one saw), so the probe, which
    /// could only meet what this frame met, was skipped.
    pub probe_skipped_still: bool,
    /// The frame was complete and named a next camera, but on the clock no probe round fit
    /// what was left of it (with counts: `FrameCaps::probe` false), so no probe ran (0 or 1).
    pub probe_skipped_clock: u32,
    /// Probe rounds run after this frame (`StreamOptions::probe_rounds`): the first probes
    /// the next camera's pixels, each later one only the pixels the round before left open,
    /// after the prefetch built what they needed.
    pub probe_rounds: u32,
    /// Of `probe_rounds`: verifying rounds (`StreamOptions::probe_verify_rounds`), each over
    /// every pixel after the rounds before had prefetched.
    pub probe_verify_rounds: u32,
    /// The first round's prefetch evicted and `StreamOptions::probe_later` is
    /// `ProbeLater::Verify`: no open-pixel round ran, the verifying rounds probed the open
    /// pixels with every other.
    pub probe_later_merged: bool,
    /// The row stride of the probe's pass marks after this frame (0: none;
    /// `StreamOptions::pass_marks`), and the resident BLASes they refreshed: passed by a final
    /// probe ray, met by no probe ray's hit or open walk.
    pub probe_pass_rows: u32,
    pub probe_pass_marks: u32,
    /// The resident streamed BLASes the probe rounds' rays hit or passed through (met, or
    /// marked passed), and their bytes (structures, and each of their meshes once): what of
    /// the resident set the next frame's rays use. With everything resident and pass marks
    /// on every row (`--stream-probe-pass-rows 1`), the next frame's *one-pass need*: above
    /// its `room_bytes`, no residency order can serve that frame in one pass while whole
    /// BLASes are the unit (exactly so for primary visibility; a shadow ray may also be
    /// served by another of its occluders). Pass marks off, passed BLASes are not counted.
    pub probe_need_blases: u32,
    pub probe_need_bytes: u64,
    /// Of `probe_need_bytes`: the meshes (geometry and shading attributes), what a unit of
    /// residency smaller than a BLAS and its meshes could leave out for structures rays only
    /// pass or only shadow and AO rays meet.
    pub probe_need_mesh_bytes: u64,
    /// Structures evicted (BLASes and TLASes), and the bytes released (structures plus their
    /// meshes; also those of structures a refused TLAS rebuild gave back, counted in
    /// `deferred`).
    pub evicted: u32,
    pub evicted_bytes: u64,
    /// Of `evicted`: made up front for TLAS rebuilds (their buffers are dedicated blocks, so
    /// only emptied blocks count), and after the budget refused an allocation. The rest made
    /// room for BLAS build groups by estimate.
    pub evicted_for_tlas: u32,
    pub evicted_on_refusal: u32,
    /// Of `evicted`: made by the prefetch after the frame's passes (room for what the guard
    /// band and the probe of the next camera met).
    pub evicted_in_prefetch: u32,
    /// Of `evicted_in_prefetch`: structures resident while a probe round of the next camera
    /// ran and met by it (the next frame's rays need them; the prefetch's own builds given
    /// back are not counted). The prefetch pins those, so only a TLAS rebuild that finds no
    /// other room gives them up (`rebuild.rs`, `unpins_before_giving_back`).
    pub evicted_probe_met_in_prefetch: u32,
    /// BLASes this frame evicted and then made resident again (built or restored, by a later
    /// pass or by its prefetch), and their bytes (structures plus meshes): churn within one
    /// frame. A frame whose working set fits its `room_bytes` should have none.
    pub returned_in_frame: u32,
    pub returned_in_frame_bytes: u64,
    /// BLASes this frame's passes made resident again that the previous frame's prefetch
    /// evicted (a prefetch that gave up what the next frame's rays needed).
    pub returned_after_prefetch: u32,
    /// Demanded structures left unbuilt in a pass because they did not fit next to what the
    /// pass's incomplete pixels need (built in a later pass, once those pixels completed).
    pub deferred: u32,
    /// Mesh bytes streamed from the source to the device.
    pub bytes_streamed: u64,
    /// Bytes built this frame: acceleration structures plus the meshes streamed for them.
    pub built_bytes: u64,
    /// Triangles in the BLASes built.
    pub triangles_built: u64,
    /// Bytes of the BLASes built (their final, compacted structures; not restored ones).
    pub blas_structure_bytes: u64,
    /// BLASes restored from the structure cache by copy instead of built (`cache.rs`), their
    /// bytes, from which tier, and the time the restores took (part of `build_ms`).
    pub restored_blases: u32,
    pub restored_bytes: u64,
    pub restored_from_host: u32,
    pub restored_from_disk: u32,
    pub restore_ms: f64,
    /// Cached BLASes built instead of restored: no room for their copy next to what the
    /// step must keep.
    pub restore_skipped: u32,
    /// Cached BLASes built because the restore rule said building is faster on this device
    /// (`restore_rule.rs`): held in host memory; held only in the directory (never read), and
    /// their entries' bytes.
    pub host_restore_declined: u32,
    pub disk_restore_declined: u32,
    pub disk_restore_declined_bytes: u64,
    /// Of `blas_built`: BLASes this renderer had built (or restored) before, built again, and
    /// their structure bytes: what a cache saves.
    pub rebuilt_blases: u32,
    pub rebuilt_bytes: u64,
    /// BLASes serialised into the structure cache in the frame (at eviction by default; after
    /// their builds with `--stream-host-cache serialize`), the bytes, the time (part of
    /// `build_ms`), and those skipped for want of room to read them back.
    pub cache_stored: u32,
    pub cache_stored_bytes: u64,
    pub cache_store_ms: f64,
    pub cache_skipped: u32,
    /// BLASes built that the host tier's store rule did not store (restoring them was not
    /// expected to save their store's cost: `store_policy.rs`), and their structure bytes.
    pub host_cache_skipped_stores: u32,
    pub host_cache_skipped_store_bytes: u64,
    /// BLASes not written to the cache directory because the restore rule said the next
    /// process would rather build them (`restore_rule.rs`; the host tier's own rule may still
    /// have kept them in host memory), and their structure bytes.
    pub disk_store_skipped: u32,
    pub disk_store_skipped_bytes: u64,
    /// Of `cache_store_ms`: size queries, the readback buffer and the GPU's serialise copies;
    /// the host's copies out of the readback buffer; handing the blobs to the cache (with the
    /// disk writer's queue waits).
    pub store_serialize_ms: f64,
    pub store_copy_ms: f64,
    pub store_put_ms: f64,
    /// Of `restore_ms`: finding and reading the entries (disk reads: what the frame's thread
    /// waited for, the reads beside the mesh uploads included); the staging buffer and the
    /// host's copies into it; the GPU's deserialise copies.
    pub restore_read_ms: f64,
    pub restore_upload_ms: f64,
    pub restore_gpu_ms: f64,
    /// Wall milliseconds of the directory reads run beside the build groups' mesh uploads
    /// (`cache/reads.rs`; on their own thread: of it, only what the frame waited for is in
    /// `restore_read_ms`).
    pub restore_read_background_ms: f64,
    /// Evicted BLASes cloned into host memory (`clones.rs`), their bytes and the time (part of
    /// `build_ms`); clones refused (host memory, or larger than the bound); and of
    /// `restored_blases` (and of `restored_from_host`), those cloned back.
    pub cloned_blases: u32,
    pub cloned_bytes: u64,
    pub clone_ms: f64,
    pub clone_skipped: u32,
    pub restored_from_clone: u32,
    /// Store and restore batches, and the host-visible buffers allocated for them (kept and
    /// reused on a discrete GPU: far fewer than batches; `transfer.rs`).
    pub transfer_batches: u32,
    pub transfer_allocations: u32,
    /// Runs of blobs moved through the device-local staging buffer (staged transfers,
    /// `transfer.rs`; 0 with direct transfers: unified memory, `MOTU_AS_TRANSFER=direct`).
    pub transfer_staged_runs: u32,
    /// The staging buffer freed for a structure's room (nothing else could be evicted); 1 at
    /// most in a renderer's life.
    pub transfer_staging_released: u32,
    pub build_ms: f64,
    /// Wall time of the trace submissions.
    pub trace_ms: f64,
    /// Wall time of the whole frame (passes, build steps, prefetch, readback).
    pub frame_ms: f64,
    /// Host work of the pass loop outside traces and build steps: stamp and request
    /// readback, demand lists, pixel lists, per-pass table writes.
    pub host_ms: f64,
    /// Of `build_ms`: streaming meshes (and their textures) from the source to the device.
    pub mesh_ms: f64,
    /// Of `mesh_ms` (`scene/upload/group.rs`): the buffers allocated (with evictions for
    /// them and new memory blocks); the source told what comes (read-ahead advice, first-touch
    /// chunk checksums); the meshes read and checked (page faults on the package's map,
    /// decompression); copied into host-mapped buffers; staged through the ring. The rest of
    /// `mesh_ms`: textures, the last flush.
    pub mesh_alloc_ms: f64,
    pub mesh_prepare_ms: f64,
    pub mesh_read_ms: f64,
    pub mesh_copy_ms: f64,
    pub mesh_staged_ms: f64,
    /// Bytes the mesh uploads copied; memory blocks made for the meshes (each a fresh
    /// `vkAllocateMemory`, mapped where host-visible) and their bytes; the process's page
    /// faults while the meshes were read and while they were copied; chunks the source
    /// decompressed for them (a compressed package's).
    pub mesh_upload_bytes: u64,
    pub mesh_blocks_created: u32,
    pub mesh_block_bytes_created: u64,
    /// Of `mesh_blocks_created`: host blocks made ahead on a thread of their own or kept
    /// from a destroyed one (`GpuHeap::set_host_blocks_ahead`), not allocated in the frame.
    pub mesh_blocks_from_spare: u32,
    pub mesh_read_faults: u64,
    pub mesh_copy_faults: u64,
    pub mesh_chunk_decodes: u64,
    /// First-touch checksums of whole chunks the meshes' reads ran (in `mesh_prepare_ms`),
    /// and the chunks' stored bytes: a small mesh in a chunk no read touched yet costs all of
    /// its chunk (64 MiB by default).
    pub mesh_chunk_checks: u64,
    pub mesh_chunk_checked_bytes: u64,
    /// Of `build_ms`: triangle BLAS builds (with compaction).
    pub blas_ms: f64,
    /// Of `build_ms`: TLAS (and proxy BLAS) rebuilds, including their evict-and-retry rounds.
    pub tlas_ms: f64,
    /// Of `tlas_ms`, its rebuilds' phases (`tlas_build.rs`; the rest is evict-and-retry
    /// rounds): the records' GPU builds, waited (and persistent TLASes' updates); the records'
    /// copies to the device; the proxy and marks BLASes (boxes planned, uploaded and built);
    /// the PI slots rewritten and the new structures swapped in (old ones released); the
    /// room probe (and kept records' sizing); the records counted and sized.
    pub tlas_gpu_ms: f64,
    pub tlas_upload_ms: f64,
    /// Queue submissions of the frame (every one-shot command buffer: uploads, builds,
    /// compactions, traces, readbacks) and the fence waits on them (the CPU blocked until the
    /// GPU finished); of those, the TLAS rebuilds' (`tlas_build.rs`: proxy boxes' and records'
    /// uploads, proxy, marks and TLAS builds, compaction copies, GPU records).
    pub submits: u64,
    pub fence_waits: u64,
    pub tlas_submits: u64,
    pub tlas_fence_waits: u64,
    /// TLAS rebuild calls whose proxy and marks BLASes and TLASes went in one submission
    /// (`tlas_build/one_submit.rs`; the others: compaction on, a persistent TLAS updated, a
    /// level over one batch, or that path's allocations refused).
    pub tlas_one_submission: u32,
    /// Rebuilt TLASes built into the storage of the structure they replaced (no allocation
    /// and no free: `tlas_build/storage.rs`), and those given fresh storage.
    pub tlas_storage_reused: u32,
    pub tlas_storage_allocated: u32,
    /// Old structures released because their piece had outgrown them (the misses that
    /// `--stream-tlas-headroom` exists for).
    pub tlas_storage_grew: u32,
    pub tlas_proxy_ms: f64,
    pub tlas_swap_ms: f64,
    pub tlas_room_ms: f64,
    pub tlas_encode_ms: f64,
    /// Proxy and marks BLASes the rebuilds built, and those they kept from the TLAS's last
    /// build because its clusters' residency had not changed (a BLAS under it moved, or was
    /// evicted and built back).
    pub tlas_proxies_built: u32,
    pub tlas_proxies_kept: u32,
    /// Rebuilt TLASes and proxy and marks BLASes copied to their compacted size
    /// (`--stream-tlas-compact on`; none where compaction gains nothing, as on lavapipe), the
    /// bytes that saved summed over the frame's rebuilds, and the most it saved at once on the
    /// resident ones after a build step (the room `--stream-tlas-compact off` would take more).
    pub tlas_compactions: u32,
    pub tlas_compact_saved_bytes: u64,
    pub tlas_compact_resident_saved_bytes: u64,
    /// TLAS rebuilds and updates by when they ran: before the frame's first pass (what the
    /// frame buffers evicted, or the previous frame's steps left dirty), in the build steps
    /// between passes, in the prefetch after them. Of all those, `tlas_rebuilt_again`: a TLAS
    /// rebuilt again with no trace since its last rebuild (the first one wasted).
    pub tlas_rebuilt_at_start: u32,
    pub tlas_rebuilt_in_passes: u32,
    pub tlas_rebuilt_in_prefetch: u32,
    pub tlas_rebuilt_again: u32,
    /// Of `build_ms`: choosing and releasing eviction victims.
    pub evict_ms: f64,
    /// Of `build_ms`: rewriting the per-step tables (TLAS and mesh addresses, shading).
    pub tables_ms: f64,
    /// Build steps (one after each pass that left pixels open, plus the prefetch).
    pub build_steps: u32,
    /// BLAS build groups attempted, and how many of them the budget refused (a refused group
    /// is retried in halves; its meshes were streamed for nothing).
    pub build_groups: u32,
    pub refused_groups: u32,
    /// TLAS builds (each rebuild of a dirty TLAS counts, retries included) and the instance
    /// records written for them (for persistent TLASes: the records patched).
    pub tlas_builds: u32,
    pub tlas_instances_written: u64,
    /// Of the rebuilds' records: those the compaction pass wrote on the GPU from the kept
    /// records (`--stream-tlas-records gpu`; `tlas_instances_written` is then the host's:
    /// the proxy and marks records, and the records of TLASes written from the host), and the
    /// milliseconds of those passes (tables' upload, dispatch and wait).
    pub tlas_records_compacted: u64,
    pub tlas_compact_ms: f64,
    /// Rebuilds of a TLAS without kept records, so the host wrote its records
    /// (`--stream-tlas-records gpu`): at its first rebuild (they are made at a second), or
    /// where they did not fit or were released for room.
    pub tlas_records_host_fallbacks: u32,
    /// Records the host encoded into kept records (once per TLAS, at its first rebuild with
    /// `gpu`; not in `tlas_instances_written`).
    pub tlas_records_kept_written: u64,
    /// Bytes of the kept records and their tables after the frame's last rebuild (0 in a
    /// frame without rebuilds); part of the skeleton.
    pub tlas_records_kept_bytes: u64,
    /// TLASes whose kept records were released for a structure's room this frame (they yield
    /// to structures; none is made again in the frame).
    pub tlas_records_released: u32,
    /// Of `tlas_builds`: updates of persistent TLASes (a refit over every instance, no new
    /// structure; see `StreamOptions::tlas_update`).
    pub tlas_updates: u32,
    /// The largest of the frame's TLAS rebuilds while it builds: its instance records, the
    /// structures as built and their build scratch, by the driver's size queries (the proxies
    /// and the compacted copies aside). Held only during the rebuild, so `room_bytes`
    /// (measured after the frame) does not count it: a rebuild leaves about `room_bytes`
    /// less this for BLASes, which is why a frame whose working set is within `room_bytes`
    /// can still need more than one pass.
    pub tlas_rebuild_transient_bytes: u64,
    /// Allocations moved to empty memory blocks (`StreamOptions::defrag`), the bytes of blocks
    /// that freed, and the time it took (part of `build_ms`).
    pub defrag_moves: u32,
    pub defrag_freed_bytes: u64,
    pub defrag_ms: f64,
    /// The frame's working set: distinct BLASes its rays used (hit or open while resident,
    /// or built for them) and their bytes (structures plus meshes). Above what the budget
    /// leaves for structures, some BLAS must be built more than once in the frame.
    pub working_set_blases: u32,
    pub working_set_bytes: u64,
    /// Of `working_set_bytes`: the working set's meshes, each once (resident at the frame's
    /// end), where they count against the budget (0 with meshes in host memory). With everything resident, a frame's one-pass need under a unit of residency that
    /// keeps meshes apart from structures is at most the previous frame's `probe_need_bytes`
    /// less its `probe_need_mesh_bytes` plus this: only BLASes rays hit need their meshes
    /// (`tools/stream-need.sh` prints that bound).
    pub working_set_mesh_bytes: u64,
    /// Of `working_set_bytes`, by the kinds of ray whose closest hit a BLAS held in the frame
    /// (one BLAS may count under several): camera rays, shadow and AO rays, bounce rays; those
    /// only secondary rays (shadow, AO, bounce) hit, neither camera nor guard-band rays; and
    /// those built for the frame's rays that none hit (rays passed through them). The rest is
    /// what only guard-band rays hit.
    pub working_set_camera_bytes: u64,
    pub working_set_occlusion_bytes: u64,
    pub working_set_bounce_bytes: u64,
    pub working_set_secondary_only_bytes: u64,
    pub working_set_unhit_bytes: u64,
    /// Why the first pass found structures missing (each one needed by some pixel, so the
    /// frame takes another pass), judged against the previous frame's probe of this camera:
    /// resident while the probe ran but met by none of its rays (passed without a hit: the
    /// hardware reports no such pass) and evicted since, by the prefetch or for the frame;
    /// not resident then and met by no probe ray (secondary rays from hits the probe could not
    /// see yet, or no probe ran); met by the probe but not resident now (the prefetch skipped
    /// it or evicted it again). Zero when the first pass completed the frame.
    pub first_pass_missed_evicted: u32,
    pub first_pass_missed_unprobed: u32,
    pub first_pass_missed_probed: u32,
    /// Per pass: where its time went.
    pub pass_log: Vec<PassStats>,
    /// Resident acceleration-structure and geometry bytes after the frame (counted against
    /// the budget).
    pub resident_bytes: u64,
    /// Resident meshes' bytes in host memory outside the budget after the frame
    /// ([`MeshMemory`]; 0 where meshes are device-local or host memory counts).
    pub resident_host_mesh_bytes: u64,
    pub resident_blases: u32,
    pub resident_tlases: u32,
    /// Image textures resident after the frame (they stream with the meshes that sample them).
    pub resident_textures: u32,
    /// Highest bytes of blocks counted against the budget so far (never above it).
    pub vram_peak_bytes: u64,
    pub vram_budget_bytes: u64,
    /// After the frame: bytes of blocks counted against the budget, and of the live
    /// allocations in them. Their difference is free space inside blocks that only requests
    /// fitting its ranges can use.
    pub heap_block_bytes: u64,
    pub heap_in_use_bytes: u64,
    /// The budget less what stays in use beside BLASes and their meshes after the frame
    /// (skeleton, tables, frame buffers, pipeline, staging): the most that structures may hold
    /// at once. A pass walks only what is resident, so a frame whose `working_set_bytes` is
    /// above it needs at least `ceil(working_set_bytes / room_bytes)` passes at this budget.
    pub room_bytes: u64,
    /// `vram_budget_bytes − room_bytes` by what holds it (the parts sum to it exactly).
    pub room_split: RoomSplit,
}

/// One pass of a frame (`FrameStreamStats::pass_log`).
#[derive(Clone, Debug, Default)]
pub struct PassStats {
    /// Pixels (and guard rays) traced in this pass.
    pub traced: u64,
    /// Pixels still open after it.
    pub open_pixels: u64,
    /// Structures the pass demanded (nearest open) and saw open behind those.
    pub needed: u32,
    pub later: u32,
    /// Its step built none of `later`: more than a 16th of the image's pixels were open
    /// (`stream/demand.rs`, `OPEN_EARLY_PIXEL_SHARE`).
    pub later_deferred: bool,
    /// Of `needed`: those some camera ray waits for (built first).
    pub needed_camera: u32,
    pub trace_ms: f64,
    pub host_ms: f64,
    /// Its build step (0 after the last pass).
    pub build_ms: f64,
    pub tlas_ms: f64,
    pub blas_built: u32,
    /// Structure bytes its BLAS builds made (as `FrameStreamStats::built_bytes`).
    pub built_bytes: u64,
    pub evicted: u32,
    /// Bytes its evictions released (as `FrameStreamStats::evicted_bytes`).
    pub evicted_bytes: u64,
    /// Of `evicted`: up front for TLAS rebuilds, after a refused allocation.
    pub evicted_for_tlas: u32,
    pub evicted_on_refusal: u32,
    /// The pass was its frame's last (its pass cap, or its build budget spent): an open
    /// primary ray traced no secondary rays ahead of its hit.
    pub last_pass: bool,
    /// Of `open_pixels`: those whose primary or bounce ray is open (waiting for the
    /// structure it names), not only secondary rays.
    pub open_closest: u64,
    /// Of `open_pixels`: left as they are for the frame's last pass (not traced again): their
    /// primary or bounce ray waits for a structure that is still not resident.
    pub left_waiting: u64,
    /// The shaders' counts (device-independent): secondary rays traced (shadow, AO, bounce),
    /// TLAS walks of the rays' walks, the mark walks of rays left open (and guard rays), and
    /// those mark walks' TLAS walks.
    pub secondary_rays: u64,
    pub tlas_walks: u64,
    pub mark_walks: u64,
    pub mark_tlas_walks: u64,
    /// Proxy member boxes tested in their quantised form, and the exact tests (an instance
    /// record read) they let through (`stream/member_boxes.rs`; device-independent). The query
    /// backend always counts them; the pipeline backend, whose tests run in intersection and
    /// any-hit shaders, only in counting mode
    /// ([`StreamOptions::count_proxy_calls`](super::StreamOptions::count_proxy_calls), else 0).
    pub proxy_member_tests: u64,
    pub proxy_exact_tests: u64,
    /// Counting mode only ([`StreamOptions::count_proxy_calls`](super::StreamOptions::count_proxy_calls),
    /// else all 0): the pass's proxy work by ray kind and outcome (`stream/proxy_count.rs`).
    pub proxy_calls_camera: super::ProxyCalls,
    pub proxy_calls_guard: super::ProxyCalls,
    pub proxy_calls_shadow: super::ProxyCalls,
    pub proxy_calls_ao: super::ProxyCalls,
    pub proxy_calls_bounce: super::ProxyCalls,
}

/// Totals over all frames rendered so far.
#[derive(Clone, Debug, Default)]
pub struct StreamTotals {
    pub frames: u64,
    pub passes: u64,
    pub blas_built: u64,
    pub tlas_built: u64,
    pub tlas_rebuilt: u64,
    pub tlas_rebuild_groups: u64,
    /// The frames' `tlas_storage_reused`, `tlas_storage_allocated` and `tlas_storage_grew`
    /// summed.
    pub tlas_storage_reused: u64,
    pub tlas_storage_allocated: u64,
    pub tlas_storage_grew: u64,
    /// The frames' `submits`, `fence_waits`, `tlas_submits` and `tlas_fence_waits` summed.
    pub submits: u64,
    pub fence_waits: u64,
    pub tlas_submits: u64,
    pub tlas_fence_waits: u64,
    pub evicted: u64,
    pub deferred: u64,
    /// Frames that ran out of passes with pixels still incomplete.
    pub incomplete_frames: u64,
    /// Pixels shown by the fallback, over all frames.
    pub fallback_pixels: u64,
    pub bytes_streamed: u64,
    pub built_bytes: u64,
    pub triangles_built: u64,
    pub build_ms: f64,
    /// The structure cache (`cache.rs`): restores, rebuilds and stores over all frames (as
    /// [`FrameStreamStats`]), and the restores' rate in GB/s.
    pub restored_blases: u64,
    pub restored_bytes: u64,
    pub restore_ms: f64,
    pub restore_gb_per_s: f64,
    pub rebuilt_blases: u64,
    pub rebuilt_bytes: u64,
    pub cache_stored: u64,
    pub cache_stored_bytes: u64,
    pub cache_store_ms: f64,
    /// Serialised bytes stored over the stores' time (GB/s; 0 with none).
    pub store_gb_per_s: f64,
    /// Over all frames (as [`FrameStreamStats`]): BLASes the store rule did not store, and
    /// their structure bytes.
    pub host_cache_skipped_stores: u64,
    pub host_cache_skipped_store_bytes: u64,
    /// Over all frames (as [`FrameStreamStats`]), and for `disk_store_skipped` also after
    /// them (`persist_cache`): the restore rule's decisions (`restore_rule.rs`).
    pub host_restore_declined: u64,
    pub disk_restore_declined: u64,
    pub disk_restore_declined_bytes: u64,
    pub disk_store_skipped: u64,
    pub disk_store_skipped_bytes: u64,
    /// The host tier's store rule and the estimates it decided from at the end of the run
    /// (with the restore rule's disk reads and the rates file).
    pub store_policy: super::StorePolicyStats,
    /// Bytes of the BLASes built, over all frames, and the rate they were built at: those
    /// bytes over the BLAS steps' time less their restores and cache stores (GB/s).
    pub blas_structure_bytes: u64,
    pub blas_build_gb_per_s: f64,
    /// Of `build_ms` over all frames: the BLAS steps (builds, restores, cache stores).
    pub blas_ms: f64,
    /// The phases of storing and restoring over all frames (as [`FrameStreamStats`]).
    pub store_serialize_ms: f64,
    pub store_copy_ms: f64,
    pub store_put_ms: f64,
    pub restore_read_ms: f64,
    pub restore_upload_ms: f64,
    pub restore_gpu_ms: f64,
    pub restore_read_background_ms: f64,
    pub transfer_batches: u32,
    pub transfer_allocations: u32,
    pub transfer_staged_runs: u32,
    pub transfer_staging_released: u32,
    /// How evicted BLASes were kept in host memory: "clone" (device-side clones, `clones.rs`),
    /// "deferred" (serialised at eviction and after the frames, the default), "serialize"
    /// (serialised as built), "off" (no host bytes), "" (no cache attached).
    pub host_cache_mode: &'static str,
    /// Over all frames (as [`FrameStreamStats`]): clones made, their bytes and time, and the
    /// BLASes cloned back; the clones' bytes held after the last frame.
    pub cloned_blases: u64,
    pub cloned_bytes: u64,
    pub clone_ms: f64,
    pub restored_from_clone: u64,
    pub host_clone_bytes: u64,
    /// Written to the cache directory after the frames (`persist_cache`: the structures still
    /// resident, and with host clones the clones): BLASes, serialised bytes, milliseconds.
    pub persisted_blases: u64,
    pub persisted_bytes: u64,
    pub persist_ms: f64,
    /// Of `persisted_blases`: those serialised from a host clone (evicted, not resident).
    pub persisted_from_clone: u64,
    /// Triangles of every buildable triangle BLAS: what one full build costs.
    pub scene_triangles: u64,
    /// Bytes the skeleton (tables, PI BLASes, root TLAS, proxies) took at start.
    pub skeleton_bytes: u64,
    /// Boxes inside the streamable BLASes (top boxes and leaves, `proxy_boxes.rs`) that a ray
    /// must enter, beside a member instance's box, to open a BLAS; and the milliseconds
    /// computing them from the meshes took at start.
    pub proxy_boxes: u64,
    pub proxy_boxes_ms: f64,
    /// Whether the boxes came from the structure cache (made by an earlier process).
    pub proxy_boxes_cached: bool,
    /// Where the boxes came from: "package" (every streamable BLAS's entry of the package's
    /// `proxy_boxes` section matched its records), "cache" (the structure cache), "computed"
    /// (made from the meshes at start; where the package stored some, only the rest), or ""
    /// before the start.
    pub proxy_boxes_source: &'static str,
    /// BLASes whose entry in the package's table was made for other records (a warning: their
    /// boxes were taken from the cache or made).
    pub proxy_boxes_stale_blases: u64,
    /// Milliseconds of the start's other phases: the derived tables (parents per BLAS, proxy
    /// clusters per TLAS, the GPU tables' records), choosing persistent TLASes (driver size
    /// queries), and the resident skeleton (tables uploaded, PI BLASes, TLASes and proxies
    /// built).
    pub derived_ms: f64,
    pub persistent_choice_ms: f64,
    pub skeleton_ms: f64,
    /// How TLASes followed residency (`update` or `rebuild`, as `--stream-tlas` resolved),
    /// the persistent ones, and the VRAM they and their placeholders keep (structures at
    /// full residency, update scratch, and records where host memory counts).
    pub tlas_mode: &'static str,
    /// Where rebuilt TLASes' records came from (`gpu` or `host`, `--stream-tlas-records`), the
    /// most bytes kept for the GPU path, and how many TLASes' kept records were released for a
    /// structure's room (they yield to structures; rebuilds then wrote from the host until a
    /// later frame made them again).
    pub tlas_records_mode: &'static str,
    /// What rebuilt TLASes were built for (`fast-trace` or `fast-build`, `--stream-tlas-build`).
    pub tlas_build: &'static str,
    /// Whether rebuilt TLASes and their proxies were compacted (`--stream-tlas-compact`), and
    /// the frames' `tlas_rebuilt_again` summed.
    pub tlas_compact: bool,
    pub tlas_rebuilt_again: u64,
    pub tlas_records_kept_bytes: u64,
    pub tlas_records_released: u32,
    pub persistent_tlases: u32,
    pub persistent_tlas_bytes: u64,
    /// A BLAS did not fit next to the persistent TLASes, so they were dropped and TLASes
    /// rebuilt from then on (the floor is sized for rebuilt TLASes).
    pub persistent_dropped: bool,
    /// Where streamed meshes live ([`MeshMemory`] resolved: `device` or `host`) and whether
    /// they count against the budget (host memory does on unified memory).
    pub mesh_memory: &'static str,
    pub meshes_budgeted: bool,
    /// Whether host-visible memory (staging, persistent TLASes' records, host meshes) counts
    /// against the budget: unified memory (lavapipe, integrated GPUs), not a discrete GPU.
    pub host_memory_counted: bool,
    /// Most bytes of resident meshes in host memory outside the budget after any frame.
    pub host_mesh_peak_bytes: u64,
    pub vram_peak_bytes: u64,
    pub vram_budget_bytes: u64,
}

impl StreamTotals {
    /// Adds frame `st`'s counts (the allocator's `report` after it).
    pub(super) fn add_frame(&mut self, st: &FrameStreamStats, report: &motu_alloc::AllocReport) {
        let tot = self;
        tot.frames += 1;
        tot.passes += u64::from(st.passes);
        tot.blas_built += u64::from(st.blas_built);
        tot.tlas_built += u64::from(st.tlas_built);
        tot.tlas_rebuilt += u64::from(st.tlas_rebuilt);
        tot.tlas_rebuilt_again += u64::from(st.tlas_rebuilt_again);
        tot.tlas_rebuild_groups += u64::from(st.tlas_rebuild_groups);
        tot.tlas_storage_reused += u64::from(st.tlas_storage_reused);
        tot.tlas_storage_allocated += u64::from(st.tlas_storage_allocated);
        tot.tlas_storage_grew += u64::from(st.tlas_storage_grew);
        tot.submits += st.submits;
        tot.fence_waits += st.fence_waits;
        tot.tlas_submits += st.tlas_submits;
        tot.tlas_fence_waits += st.tlas_fence_waits;
        tot.evicted += u64::from(st.evicted);
        tot.deferred += u64::from(st.deferred);
        tot.incomplete_frames += u64::from(!st.complete);
        tot.fallback_pixels += st.fallback_pixels;
        tot.bytes_streamed += st.bytes_streamed;
        tot.built_bytes += st.built_bytes;
        tot.restored_blases += u64::from(st.restored_blases);
        tot.restored_bytes += st.restored_bytes;
        tot.restore_ms += st.restore_ms;
        tot.rebuilt_blases += u64::from(st.rebuilt_blases);
        tot.rebuilt_bytes += st.rebuilt_bytes;
        tot.cache_stored += u64::from(st.cache_stored);
        tot.cache_stored_bytes += st.cache_stored_bytes;
        tot.cache_store_ms += st.cache_store_ms;
        tot.store_gb_per_s = if tot.cache_store_ms > 0.0 {
            tot.cache_stored_bytes as f64 / (tot.cache_store_ms * 1e6)
        } else {
            0.0
        };
        tot.host_cache_skipped_stores += u64::from(st.host_cache_skipped_stores);
        tot.host_cache_skipped_store_bytes += st.host_cache_skipped_store_bytes;
        tot.host_restore_declined += u64::from(st.host_restore_declined);
        tot.disk_restore_declined += u64::from(st.disk_restore_declined);
        tot.disk_restore_declined_bytes += st.disk_restore_declined_bytes;
        tot.disk_store_skipped += u64::from(st.disk_store_skipped);
        tot.disk_store_skipped_bytes += st.disk_store_skipped_bytes;
        tot.blas_structure_bytes += st.blas_structure_bytes;
        tot.blas_ms += st.blas_ms;
        let building_ms = tot.blas_ms - tot.restore_ms - tot.cache_store_ms;
        tot.blas_build_gb_per_s = if building_ms > 0.0 {
            tot.blas_structure_bytes as f64 / (building_ms * 1e6)
        } else {
            0.0
        };
        tot.store_serialize_ms += st.store_serialize_ms;
        tot.store_copy_ms += st.store_copy_ms;
        tot.store_put_ms += st.store_put_ms;
        tot.restore_read_ms += st.restore_read_ms;
        tot.restore_upload_ms += st.restore_upload_ms;
        tot.restore_gpu_ms += st.restore_gpu_ms;
        tot.restore_read_background_ms += st.restore_read_background_ms;
        tot.transfer_batches += st.transfer_batches;
        tot.transfer_allocations += st.transfer_allocations;
        tot.transfer_staged_runs += st.transfer_staged_runs;
        tot.transfer_staging_released += st.transfer_staging_released;
        tot.cloned_blases += u64::from(st.cloned_blases);
        tot.cloned_bytes += st.cloned_bytes;
        tot.clone_ms += st.clone_ms;
        tot.restored_from_clone += u64::from(st.restored_from_clone);
        tot.restore_gb_per_s = if tot.restore_ms > 0.0 {
            tot.restored_bytes as f64 / (tot.restore_ms * 1e6)
        } else {
            0.0
        };
        tot.triangles_built += st.triangles_built;
        tot.build_ms += st.build_ms;
        tot.vram_peak_bytes = report.peak_block_bytes;
        tot.host_mesh_peak_bytes = tot.host_mesh_peak_bytes.max(st.resident_host_mesh_bytes);
    }
}

impl FrameStreamStats {
    /// A build group's mesh upload: its allocations (`(ms, blocks before, blocks after)`, as
    /// `GpuHeap::created_blocks` counts them) and `split`.
    pub(super) fn note_mesh_upload(
        &mut self,
        (alloc_ms, before, after): (f64, motu_vk::BlockCounts, motu_vk::BlockCounts),
        split: &crate::scene::UploadSplit,
    ) {
        self.mesh_alloc_ms += alloc_ms;
        self.mesh_blocks_created += (after.created - before.created) as u32;
        self.mesh_block_bytes_created += after.bytes - before.bytes;
        self.mesh_blocks_from_spare += (after.from_spare - before.from_spare) as u32;
        self.mesh_prepare_ms += split.prepare_ms;
        self.mesh_read_ms += split.read_ms;
        self.mesh_copy_ms += split.copy_ms;
        self.mesh_staged_ms += split.staged_ms;
        self.mesh_upload_bytes += split.bytes;
        self.mesh_read_faults += split.read_faults;
        self.mesh_copy_faults += split.copy_faults;
        self.mesh_chunk_decodes += split.chunk_decodes;
        self.mesh_chunk_checks += split.chunk_checks;
        self.mesh_chunk_checked_bytes += split.chunk_checked_bytes;
    }
}

/// A frame's start: the clock and the context's submission and fence-wait counts, for the
/// frame's [`FrameStreamStats::frame_ms`], `submits` and `fence_waits`.
pub(super) struct FrameMark {
    t0: std::time::Instant,
    submits: u64,
    fence_waits: u64,
}

impl FrameMark {
    pub(super) fn now(ctx: &motu_vk::Context) -> FrameMark {
        FrameMark {
            t0: std::time::Instant::now(),
            submits: ctx.submit_count(),
            fence_waits: ctx.fence_wait_count(),
        }
    }

    /// The frame's milliseconds, submissions and waits since the mark, into `st`.
    pub(super) fn note(self, ctx: &motu_vk::Context, st: &mut FrameStreamStats) {
        st.frame_ms = self.t0.elapsed().as_secs_f64() * 1e3;
        st.submits = ctx.submit_count() - self.submits;
        st.fence_waits = ctx.fence_wait_count() - self.fence_waits;
    }
}
