//! A streamed render's `stream` object in `--stats`: per frame and pass, the run's totals, the
//! floor, the start's phases and the structure cache's counters; and the floor's and the
//! persistent TLASes' parts that `motu report --json` prints. Each key is the library field of
//! the same name.

use super::mirror::mirror;

mirror! {
    /// `motu_gpu::FrameStreamStats` as JSON.
    FrameStreamStats from motu_gpu::FrameStreamStats {
        frame: u64,
        passes: u32,
        complete: bool,
        incomplete_pixels: u64,
        fallback_pixels: u64,
        build_budget_spent: bool,
        truncated_rays: u64,
        reshot_pixels: u64,
        guard_rays: u64,
        blas_built: u32,
        tlas_built: u32,
        tlas_rebuilt: u32,
        tlas_rebuild_groups: u32,
        prefetched: u32,
        prefetch_skipped: u32,
        prefetch_kept_frame: bool,
        probe_rays: u64,
        probe_ms: f64,
        probe_skipped_still: bool,
        probe_rounds: u32,
        probe_verify_rounds: u32,
        probe_later_merged: bool,
        probe_pass_rows: u32,
        probe_pass_marks: u32,
        probe_need_blases: u32,
        probe_need_bytes: u64,
        probe_need_mesh_bytes: u64,
        evicted: u32,
        evicted_bytes: u64,
        evicted_for_tlas: u32,
        evicted_on_refusal: u32,
        evicted_in_prefetch: u32,
        returned_in_frame: u32,
        returned_in_frame_bytes: u64,
        returned_after_prefetch: u32,
        deferred: u32,
        bytes_streamed: u64,
        built_bytes: u64,
        triangles_built: u64,
        blas_structure_bytes: u64,
        restored_blases: u32,
        restored_bytes: u64,
        restored_from_host: u32,
        restored_from_disk: u32,
        restore_ms: f64,
        restore_skipped: u32,
        rebuilt_blases: u32,
        rebuilt_bytes: u64,
        cache_stored: u32,
        cache_stored_bytes: u64,
        cache_store_ms: f64,
        cache_skipped: u32,
        host_cache_skipped_stores: u32,
        host_cache_skipped_store_bytes: u64,
        store_serialize_ms: f64,
        store_copy_ms: f64,
        store_put_ms: f64,
        restore_read_ms: f64,
        restore_upload_ms: f64,
        restore_gpu_ms: f64,
        cloned_blases: u32,
        cloned_bytes: u64,
        clone_ms: f64,
        clone_skipped: u32,
        restored_from_clone: u32,
        transfer_batches: u32,
        transfer_allocations: u32,
        build_ms: f64,
        trace_ms: f64,
        frame_ms: f64,
        host_ms: f64,
        mesh_ms: f64,
        blas_ms: f64,
        tlas_ms: f64,
        evict_ms: f64,
        tables_ms: f64,
        build_steps: u32,
        build_groups: u32,
        refused_groups: u32,
        tlas_builds: u32,
        tlas_instances_written: u64,
        tlas_records_compacted: u64,
        tlas_compact_ms: f64,
        tlas_records_host_fallbacks: u32,
        tlas_records_kept_written: u64,
        tlas_records_kept_bytes: u64,
        tlas_records_released: u32,
        tlas_updates: u32,
        tlas_rebuild_transient_bytes: u64,
        defrag_moves: u32,
        defrag_freed_bytes: u64,
        defrag_ms: f64,
        working_set_blases: u32,
        working_set_bytes: u64,
        working_set_mesh_bytes: u64,
        first_pass_missed_evicted: u32,
        first_pass_missed_unprobed: u32,
        first_pass_missed_probed: u32,
        pass_log: Vec<PassStats>,
        resident_bytes: u64,
        resident_host_mesh_bytes: u64,
        resident_blases: u32,
        resident_tlases: u32,
        resident_textures: u32,
        vram_peak_bytes: u64,
        vram_budget_bytes: u64,
        heap_block_bytes: u64,
        heap_in_use_bytes: u64,
        room_bytes: u64,
    }
}

mirror! {
    /// `motu_gpu::PassStats` as JSON.
    PassStats from motu_gpu::PassStats {
        traced: u64,
        open_pixels: u64,
        needed: u32,
        later: u32,
        trace_ms: f64,
        host_ms: f64,
        build_ms: f64,
        tlas_ms: f64,
        blas_built: u32,
        built_bytes: u64,
        evicted: u32,
        evicted_bytes: u64,
        evicted_for_tlas: u32,
        evicted_on_refusal: u32,
        last_pass: bool,
        open_closest: u64,
        left_waiting: u64,
        secondary_rays: u64,
        tlas_walks: u64,
        mark_walks: u64,
        mark_tlas_walks: u64,
    }
}

mirror! {
    /// `motu_gpu::StreamTotals` as JSON.
    StreamTotals from motu_gpu::StreamTotals {
        frames: u64,
        passes: u64,
        blas_built: u64,
        tlas_built: u64,
        tlas_rebuilt: u64,
        tlas_rebuild_groups: u64,
        evicted: u64,
        deferred: u64,
        incomplete_frames: u64,
        fallback_pixels: u64,
        bytes_streamed: u64,
        built_bytes: u64,
        triangles_built: u64,
        build_ms: f64,
        restored_blases: u64,
        restored_bytes: u64,
        restore_ms: f64,
        restore_gb_per_s: f64,
        rebuilt_blases: u64,
        rebuilt_bytes: u64,
        cache_stored: u64,
        cache_stored_bytes: u64,
        cache_store_ms: f64,
        store_gb_per_s: f64,
        host_cache_skipped_stores: u64,
        host_cache_skipped_store_bytes: u64,
        store_policy: StorePolicyStats,
        blas_structure_bytes: u64,
        blas_build_gb_per_s: f64,
        blas_ms: f64,
        store_serialize_ms: f64,
        store_copy_ms: f64,
        store_put_ms: f64,
        restore_read_ms: f64,
        restore_upload_ms: f64,
        restore_gpu_ms: f64,
        transfer_batches: u32,
        transfer_allocations: u32,
        host_cache_mode: &'static str,
        cloned_blases: u64,
        cloned_bytes: u64,
        clone_ms: f64,
        restored_from_clone: u64,
        host_clone_bytes: u64,
        persisted_blases: u64,
        persisted_bytes: u64,
        persist_ms: f64,
        persisted_from_clone: u64,
        scene_triangles: u64,
        skeleton_bytes: u64,
        proxy_boxes: u64,
        proxy_boxes_ms: f64,
        proxy_boxes_cached: bool,
        proxy_boxes_source: &'static str,
        proxy_boxes_stale_blases: u64,
        derived_ms: f64,
        persistent_choice_ms: f64,
        skeleton_ms: f64,
        tlas_mode: &'static str,
        tlas_records_mode: &'static str,
        tlas_records_kept_bytes: u64,
        tlas_records_released: u32,
        persistent_tlases: u32,
        persistent_tlas_bytes: u64,
        persistent_dropped: bool,
        mesh_memory: &'static str,
        meshes_budgeted: bool,
        host_memory_counted: bool,
        host_mesh_peak_bytes: u64,
        vram_peak_bytes: u64,
        vram_budget_bytes: u64,
    }
}

mirror! {
    /// `motu_gpu::StorePolicyStats` as JSON.
    StorePolicyStats from motu_gpu::StorePolicyStats {
        policy: &'static str,
        build_batches: u32,
        build_ms_per_blas: f64,
        build_gb_per_s: f64,
        build_mean_gb_per_s: f64,
        restore_batches: u32,
        restore_ms_per_blas: f64,
        restore_gb_per_s: f64,
        restore_mean_gb_per_s: f64,
        store_batches: u32,
        store_ms_per_blas: f64,
        store_gb_per_s: f64,
        store_mean_gb_per_s: f64,
        built_blases: u64,
        returns: u64,
        returned_blases: u64,
        returns_per_blas: f64,
        returns_after_return: f64,
    }
}

mirror! {
    /// `motu_gpu::StreamFloor` as JSON.
    StreamFloor from motu_gpu::StreamFloor {
        tables_bytes: u64,
        skeleton_structures_bytes: u64,
        largest_blas: Option<u32>,
        largest_blas_build_bytes: u64,
        tlas_rebuild_bytes: u64,
        frame_bytes: u64,
        shading_tables_bytes: u64,
        shading_attributes_bytes: u64,
        shading_textures_bytes: u64,
        width: u32,
        height: u32,
        pipeline_bytes: u64,
        staging_bytes: u64,
        allocator_slack_bytes: u64,
        min_resident_bytes: u64,
    }
}

mirror! {
    /// `motu_gpu::PersistentEstimate` as JSON.
    PersistentEstimate from motu_gpu::PersistentEstimate {
        tlases: u32,
        instances: u64,
        bytes: u64,
        auto_min_budget_bytes: Option<u64>,
    }
}

mirror! {
    /// `motu_gpu::FullBuildOverhead` as JSON.
    FullBuildOverhead from motu_gpu::FullBuildOverhead {
        frame_bytes: u64,
        staging_bytes: u64,
        allocator_slack_bytes: u64,
        total_bytes: u64,
    }
}

mirror! {
    /// `motu_ascache::CacheStats` as JSON.
    CacheStats from motu_ascache::CacheStats {
        host_hits: u64,
        disk_hits: u64,
        misses: u64,
        hit_bytes: u64,
        puts: u64,
        put_bytes: u64,
        host: HostStats,
        disk: Option<DiskStats>,
    }
}

mirror! {
    /// `motu_ascache::HostStats` as JSON.
    HostStats from motu_ascache::HostStats {
        capacity_bytes: u64,
        entries: u64,
        bytes: u64,
        hits: u64,
        misses: u64,
        inserted: u64,
        inserted_bytes: u64,
        refused: u64,
        refused_bytes: u64,
        evicted_entries: u64,
        evicted_bytes: u64,
    }
}

mirror! {
    /// `motu_ascache::DiskStats` as JSON.
    DiskStats from motu_ascache::DiskStats {
        capacity_bytes: u64,
        writable: bool,
        entries: u64,
        bytes: u64,
        found_at_open: u64,
        found_bytes_at_open: u64,
        hits: u64,
        hit_bytes: u64,
        misses: u64,
        written: u64,
        written_bytes: u64,
        skipped_writes: u64,
        evicted_entries: u64,
        evicted_bytes: u64,
        removed_bad: u64,
        stale_temp_files_removed: u64,
        warnings: WarningCounts,
        write_busy_ms: f64,
        submit_wait_ms: f64,
        flush_wait_ms: f64,
    }
}

mirror! {
    /// `motu_ascache::WarningCounts` as JSON.
    WarningCounts from motu_ascache::WarningCounts {
        corrupt: u64,
        truncated: u64,
        foreign: u64,
        incompatible: u64,
        read_only: u64,
        full: u64,
        io: u64,
    }
}
