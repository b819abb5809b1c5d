//! The full build's resources (`resources` in `--stats`, `detail` in `motu view --stats`) and
//! the allocator's report inside them: each key is the library field of the same name.

use super::mirror::mirror;
use std::collections::BTreeMap;

mirror! {
    /// `motu_gpu::ResourceReport` as JSON.
    ResourceReport from motu_gpu::ResourceReport {
        unreachable_tlases: u64,
        unreachable_blases: u64,
        box_list_tlases: u32,
        box_list_instances: u64,
        budget_bytes: u64,
        max_allocations: u32,
        blas_count: u32,
        tlas_count: u32,
        blas_bytes: u64,
        blas_compacted_bytes: u64,
        tlas_bytes: u64,
        tlas_compacted_bytes: u64,
        as_bytes: u64,
        scratch_peak_bytes: u64,
        instance_buffer_peak_bytes: u64,
        geometry_bytes: u64,
        table_bytes: u64,
        texture_bytes: u64,
        shading_attribute_bytes: u64,
        build_batches: u32,
        peak_bytes: u64,
        allocation_count: u32,
        peak_allocation_count: u32,
        build_ms: f64,
        upload_build_overlap_batches: u32,
        upload_overlap_bytes: u64,
        upload_overlap_ms: f64,
        upload_stall_ms: f64,
        alloc: Option<AllocReport>,
    }
}

mirror! {
    /// `motu_alloc::AllocReport` as JSON.
    AllocReport from motu_alloc::AllocReport {
        budget_bytes: u64,
        max_allocation_count: u32,
        max_allocation_size_bytes: u64,
        allocation_count: u32,
        peak_allocation_count: u32,
        live_suballocation_count: u64,
        budget_block_bytes: u64,
        budget_in_use_bytes: u64,
        peak_block_bytes: u64,
        peak_in_use_bytes: u64,
        classes: BTreeMap<String, ClassStats>,
        kinds: BTreeMap<String, KindStats>,
    }
}

mirror! {
    /// `motu_alloc::ClassStats` as JSON.
    ClassStats from motu_alloc::ClassStats {
        counts_against_budget: bool,
        budget_bytes: u64,
        standard_block_bytes: u64,
        block_count: u32,
        dedicated_block_count: u32,
        empty_block_count: u32,
        block_bytes: u64,
        in_use_bytes: u64,
        free_bytes: u64,
        free_range_count: u64,
        largest_free_range_bytes: u64,
        fragmentation: f64,
        peak_block_bytes: u64,
        peak_in_use_bytes: u64,
    }
}

mirror! {
    /// `motu_alloc::KindStats` as JSON.
    KindStats from motu_alloc::KindStats {
        bytes: u64,
        count: u64,
        peak_bytes: u64,
        peak_count: u64,
        total_allocations: u64,
        total_bytes: u64,
    }
}
