//! The GPU tables part ([`GpuTables`]): the device copies of the node tables the shaders read
//! (with the proxy and marks records `topology.rs` derives), the proxy clusters' member table,
//! the boxes inside streamable BLASes, and the per-BLAS stamp buffers.
//!
//! Invariants: every table is uploaded once at the start (`skeleton.rs`); only the PI slots
//! of the proxies, the marks' BLAS records, the mesh geometry addresses and the TLAS addresses
//! are rewritten while streaming, at the indices kept here; `addresses` are the tables' device
//! addresses by [`Slot`](crate::scene::Slot), 0 for an empty table; `walked` is the host copy
//! of `walked_buf`, written before each pass.

use motu_vk::HeapBuffer;

use crate::error::{GpuError, Result};
use crate::scene::SLOT_COUNT;

/// The GPU tables of a [`StreamingRenderer`](super::StreamingRenderer) (see the module docs).
#[derive(Default)]
pub(super) struct GpuTables {
    /// Every uploaded table, in upload order.
    pub buffers: Vec<HeapBuffer>,
    /// Device address per slot (0: empty table).
    pub addresses: [u64; SLOT_COUNT],
    /// Indices into `buffers` of the tables rewritten while streaming.
    pub pis_table: usize,
    pub blases_table: usize,
    pub mesh_geo_table: usize,
    pub tlas_addr_table: usize,
    /// Device address of the proxy clusters' member table (u32 global instance indices), 0
    /// when no TLAS has a proxy.
    pub cluster_members: u64,
    /// `[first, fan]` per BLAS and the boxes inside BLASes (`proxy_boxes.rs`): 0 when none.
    pub proxy_box_index: u64,
    pub proxy_boxes: u64,
    /// Per BLAS: the last pass stamp a ray saw it (written by the shaders).
    pub blas_stamps: Option<HeapBuffer>,
    /// Per BLAS: the latest pass stamp it was resident in (host copy of `walked_buf`).
    pub walked: Vec<u32>,
    pub walked_buf: Option<HeapBuffer>,
}

impl GpuTables {
    /// Tables for `blases` BLASes, nothing uploaded yet.
    pub fn new(blases: usize) -> GpuTables {
        GpuTables {
            walked: vec![0; blases],
            ..Default::default()
        }
    }

    /// The walked-stamps buffer the shaders read.
    pub fn walked_table(&self) -> Result<&HeapBuffer> {
        self.walked_buf
            .as_ref()
            .ok_or_else(|| GpuError::InvalidRequest("streaming: no walked table".into()))
    }
}
