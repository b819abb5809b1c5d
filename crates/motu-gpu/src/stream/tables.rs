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
use crate::scene::{Slot, SLOT_COUNT};

/// The GPU tables of a [`StreamingRenderer`](super::StreamingRenderer) (see the module docs).
#[derive(Default)]
pub(super) struct GpuTables {
    /// Every uploaded table, in upload order.
    buffers: Vec<HeapBuffer>,
    /// Device address per slot (0: empty table).
    addresses: [u64; SLOT_COUNT],
    /// Indices into `buffers` of the tables rewritten while streaming.
    pis_table: usize,
    blases_table: usize,
    mesh_geo_table: usize,
    tlas_addr_table: usize,
    /// Device address of the proxy clusters' member table (u32 global instance indices), 0
    /// when no TLAS has a proxy.
    cluster_members: u64,
    /// `[first, fan]` per BLAS and the boxes inside BLASes (`proxy_boxes.rs`): 0 when none.
    proxy_box_index: u64,
    proxy_boxes: u64,
    /// Per BLAS: the last pass stamp a ray saw it (written by the shaders).
    blas_stamps: Option<HeapBuffer>,
    /// Per BLAS: the latest pass stamp it was resident in (host copy of `walked_buf`).
    walked: Vec<u32>,
    walked_buf: Option<HeapBuffer>,
    /// Bytes of the instance table (`Slot::Instances`), and whether it is in host memory.
    instance_table_bytes: u64,
    instance_table_in_host: bool,
}

impl GpuTables {
    /// Tables for `blases` BLASes, nothing uploaded yet.
    pub fn new(blases: usize) -> GpuTables {
        GpuTables {
            walked: vec![0; blases],
            ..Default::default()
        }
    }

    /// Keeps `buf`, uploaded at `address`, as the table of `slot`; the slots rewritten while
    /// streaming remember where it is.
    pub fn keep_slot(&mut self, slot: Slot, buf: HeapBuffer, address: u64) {
        let at = self.buffers.len();
        match slot {
            Slot::Instances => {
                self.instance_table_bytes = buf.size_bytes();
                self.instance_table_in_host = buf.is_host_mapped();
            }
            Slot::Pis => self.pis_table = at,
            Slot::Blases => self.blases_table = at,
            Slot::MeshGeo => self.mesh_geo_table = at,
            Slot::TlasAddresses => self.tlas_addr_table = at,
            _ => {}
        }
        self.addresses[slot as usize] = address;
        self.buffers.push(buf);
    }

    /// Keeps the proxy clusters' member table, uploaded at `address`.
    pub fn keep_cluster_members(&mut self, buf: HeapBuffer, address: u64) {
        self.cluster_members = address;
        self.buffers.push(buf);
    }

    /// Keeps the boxes inside streamable BLASes: their index and the boxes.
    pub fn keep_proxy_boxes(&mut self, index: (HeapBuffer, u64), boxes: (HeapBuffer, u64)) {
        self.proxy_box_index = index.1;
        self.proxy_boxes = boxes.1;
        self.buffers.extend([index.0, boxes.0]);
    }

    /// Keeps further tables (the shading tables); returns the index of the first for
    /// [`Self::table`].
    pub fn keep_tables(&mut self, buffers: Vec<HeapBuffer>) -> usize {
        let first = self.buffers.len();
        self.buffers.extend(buffers);
        first
    }

    /// Table `i` of those kept by [`Self::keep_tables`].
    pub fn table(&self, i: usize) -> &HeapBuffer {
        &self.buffers[i]
    }

    /// The tables rewritten while streaming: proxy PI slots, BLAS records (the marks'),
    /// mesh geometry addresses, TLAS addresses.
    pub fn pis(&self) -> &HeapBuffer {
        &self.buffers[self.pis_table]
    }

    pub fn blases(&self) -> &HeapBuffer {
        &self.buffers[self.blases_table]
    }

    pub fn mesh_geo(&self) -> &HeapBuffer {
        &self.buffers[self.mesh_geo_table]
    }

    pub fn tlas_addresses(&self) -> &HeapBuffer {
        &self.buffers[self.tlas_addr_table]
    }

    /// Bytes the instance table holds of the budget (`host_counts`: whether host memory counts
    /// against it).
    pub fn instance_table_budget_bytes(&self, host_counts: bool) -> u64 {
        if self.instance_table_in_host && !host_counts {
            0
        } else {
            self.instance_table_bytes
        }
    }

    /// The tables' addresses by slot (0: empty), for a pass's push constants.
    pub fn addresses(&self) -> [u64; SLOT_COUNT] {
        self.addresses
    }

    /// Device addresses of the member table, the box index and the boxes (0: none).
    pub fn proxy_addresses(&self) -> (u64, u64, u64) {
        (self.cluster_members, self.proxy_box_index, self.proxy_boxes)
    }

    /// Keeps the stamp buffers: the one the shaders write, the walked one the host writes.
    pub fn keep_stamps(&mut self, blas_stamps: HeapBuffer, walked: HeapBuffer) {
        self.blas_stamps = Some(blas_stamps);
        self.walked_buf = Some(walked);
    }

    /// The stamps the shaders write (absent before the start).
    pub fn blas_stamps(&self) -> Option<&HeapBuffer> {
        self.blas_stamps.as_ref()
    }

    /// Stamps the BLASes `walked` with pass `stamp` in the walked table the shaders read.
    pub fn write_walked(&mut self, walked: impl Iterator<Item = usize>, stamp: u32) -> Result<()> {
        for b in walked {
            self.walked[b] = stamp;
        }
        if !self.walked.is_empty() {
            self.walked_table()?.write(0, &self.walked)?;
        }
        Ok(())
    }

    /// The walked-stamps buffer the shaders read.
    pub fn walked_table(&self) -> Result<&HeapBuffer> {
        self.walked_buf
            .as_ref()
            .ok_or_else(|| GpuError::InvalidRequest("streaming: no walked table".into()))
    }
}
