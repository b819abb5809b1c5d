//! Where the budget goes beside the room ([`RoomSplit`]): `budget − room_bytes` split by
//! allocation kind, from the allocator's per-kind use of the budget less what the room is
//! for (streamed BLASes, their budgeted meshes, kept TLAS records).

use motu_alloc::AllocKind;

/// `vram_budget_bytes − room_bytes` of a frame, by what holds it (`FrameStreamStats::room_split`).
/// The parts (every field but the two marked "of which") sum to it exactly: each is the
/// allocator's live bytes of one allocation kind counted against the budget, less the
/// streamed structures, meshes and kept records of that kind. Free space inside memory
/// blocks is not in it: `room_bytes` counts it as room (`heap_block_bytes −
/// heap_in_use_bytes`, usable only by requests that fit its ranges).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RoomSplit {
    /// BLAS storage that does not stream: the PI (AABB) BLASes, each TLAS's proxy and marks
    /// BLASes, persistent TLASes' placeholders.
    pub skeleton_blas_bytes: u64,
    /// Of `skeleton_blas_bytes`: the TLASes' proxy and marks BLASes.
    pub proxy_blas_bytes: u64,
    /// TLAS storage (every resident piece and the root, headroom included).
    pub tlas_bytes: u64,
    /// TLAS instance buffers held after the frame (persistent TLASes' records on the device),
    /// kept records aside.
    pub instance_buffer_bytes: u64,
    /// Node tables the shaders read: instances, BLAS, PI and TLAS records, the proxy
    /// clusters' member table, the boxes inside BLASes (kept records' tables aside).
    pub table_bytes: u64,
    /// Of `table_bytes`: the instance table (one record an instance).
    pub instance_table_bytes: u64,
    /// Geometry that is not a streamed mesh (PI boxes, proxy box inputs held).
    pub geometry_bytes: u64,
    /// Image textures and shading tables.
    pub texture_bytes: u64,
    /// Build scratch held after the frame.
    pub scratch_bytes: u64,
    /// Staging and readback buffers counted against the budget (unified memory).
    pub staging_bytes: u64,
    /// Everything else: frame buffers (carried hits, AOV, colour, lists), stamps, the trace
    /// pipeline's shader binding tables.
    pub other_bytes: u64,
}

/// What the room is for, by kind: subtracted from the allocator's per-kind use.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct RoomHolders {
    /// Resident streamed BLASes (BLAS storage).
    pub streamed_blas_bytes: u64,
    /// Resident streamed meshes where they count against the budget (geometry).
    pub budgeted_mesh_bytes: u64,
    /// Kept TLAS records (instance buffers) and their tables (node tables).
    pub kept_record_bytes: u64,
    pub kept_table_bytes: u64,
    /// Of the skeleton: proxy and marks BLASes, and the instance table.
    pub proxy_blas_bytes: u64,
    pub instance_table_bytes: u64,
}

impl RoomSplit {
    /// The split of the budget's live bytes `by_kind` (in [`AllocKind::ALL`]'s order) less
    /// `holders`.
    pub(super) fn of(by_kind: [u64; 9], holders: &RoomHolders) -> RoomSplit {
        let kind = |k: AllocKind| by_kind[AllocKind::ALL.iter().position(|&x| x == k).unwrap_or(0)];
        RoomSplit {
            skeleton_blas_bytes: kind(AllocKind::BlasStorage)
                .saturating_sub(holders.streamed_blas_bytes),
            proxy_blas_bytes: holders.proxy_blas_bytes,
            tlas_bytes: kind(AllocKind::TlasStorage),
            instance_buffer_bytes: kind(AllocKind::InstanceBuffer)
                .saturating_sub(holders.kept_record_bytes),
            table_bytes: kind(AllocKind::NodeTable).saturating_sub(holders.kept_table_bytes),
            instance_table_bytes: holders.instance_table_bytes,
            geometry_bytes: kind(AllocKind::Geometry).saturating_sub(holders.budgeted_mesh_bytes),
            texture_bytes: kind(AllocKind::Texture),
            scratch_bytes: kind(AllocKind::Scratch),
            staging_bytes: kind(AllocKind::Staging),
            other_bytes: kind(AllocKind::Other),
        }
    }

    /// The sum of the parts (the two "of which" fields aside): `budget − room_bytes`.
    pub fn total_bytes(&self) -> u64 {
        self.skeleton_blas_bytes
            + self.tlas_bytes
            + self.instance_buffer_bytes
            + self.table_bytes
            + self.geometry_bytes
            + self.texture_bytes
            + self.scratch_bytes
            + self.staging_bytes
            + self.other_bytes
    }
}
