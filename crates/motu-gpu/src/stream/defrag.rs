//! Emptying memory blocks by moving what they hold (`StreamOptions::defrag`, opt-in).
//!
//! Streamed BLASes and meshes are small and live in shared blocks; evicting them frees space
//! *inside* blocks, while a TLAS rebuild's instance buffer, scratch and structure are
//! dedicated blocks that need budget *outside* blocks. Once BLASes have spread over every
//! block, a rebuild finds no such room and the streamer evicts whole swaths of what frames
//! need (BENCHMARKS.md, sessions 22, 23, 26). Here the emptiest blocks whose every allocation
//! is a streamed BLAS, mesh or texture are drained instead: each allocation is copied into
//! free space other blocks already have (no new block), the originals are freed, and the
//! emptied blocks return their bytes to the budget. A moved BLAS has a new address, so its
//! resident parents become dirty (rebuilt before any trace); a moved mesh's or texture's
//! addresses are rewritten with the step's tables.

use std::collections::HashMap;

use motu_alloc::{AllocationId, BlockId};
use motu_vk::HeapBuffer;

use super::StreamingRenderer;
use crate::error::Result;
use crate::scene::AccelStruct;

/// What owns an allocation a drain may move.
#[derive(Clone, Copy)]
enum Owner {
    Blas(usize),
    Mesh(usize),
    Texture(usize),
}

/// What one drain did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Drained {
    /// Allocations moved, by what they hold.
    pub(crate) blases: u32,
    pub(crate) meshes: u32,
    pub(crate) textures: u32,
    /// Bytes of blocks the drain freed.
    pub(crate) freed_bytes: u64,
}

/// Of a block's free space, the share a drain counts on placing moved allocations in (the rest
/// is ranges too small or misaligned for them).
const USABLE_FREE: f64 = 0.75;

impl<'a> StreamingRenderer<'a> {
    /// Frees at least `bytes` of blocks (or as much as it can) by draining the emptiest
    /// standard blocks whose every allocation is a streamed BLAS, mesh or texture. Returns the
    /// allocations it moved and the bytes of blocks freed.
    pub(super) fn defragment(&mut self, bytes: u64) -> Result<Drained> {
        let t0 = std::time::Instant::now();
        let owners = self.movable_owners();
        let fills = self.heap.block_fills();
        let free_total: u64 = fills.iter().map(|f| f.size_bytes - f.used_bytes).sum();
        let mut chosen: Vec<BlockId> = Vec::new();
        let mut movers: Vec<Owner> = Vec::new();
        let (mut freeing, mut moving, mut chosen_free) = (0u64, 0u64, 0u64);
        for f in &fills {
            if freeing >= bytes {
                break;
            }
            let ids = self.heap.allocations_in(f.block);
            let Some(own): Option<Vec<Owner>> =
                ids.iter().map(|id| owners.get(id).copied()).collect()
            else {
                tracing::trace!(
                    block = f.block.0,
                    used = f.used_bytes,
                    size = f.size_bytes,
                    unmovable = ids.iter().filter(|id| !owners.contains_key(id)).count(),
                    "block not drainable"
                );
                continue;
            };
            // What it holds must fit the free space of the blocks that stay.
            let free_left = free_total - chosen_free - (f.size_bytes - f.used_bytes);
            if (moving + f.used_bytes) as f64 > free_left as f64 * USABLE_FREE {
                break;
            }
            chosen.push(f.block);
            movers.extend(own);
            freeing += f.size_bytes;
            moving += f.used_bytes;
            chosen_free += f.size_bytes - f.used_bytes;
        }
        if chosen.is_empty() {
            return Ok(Drained::default());
        }
        let before = self.heap.report().budget_block_bytes;
        self.heap.set_draining(&chosen, true);
        let moved = self.move_out(&movers);
        self.heap.set_draining(&[], false);
        let mut drained = moved?;
        let freed = before.saturating_sub(self.heap.report().budget_block_bytes);
        drained.freed_bytes = freed;
        let moved = drained.blases + drained.meshes + drained.textures;
        let st = self.frame.stats_mut();
        st.defrag_moves += moved;
        st.defrag_freed_bytes += freed;
        st.defrag_ms += t0.elapsed().as_secs_f64() * 1e3;
        tracing::debug!(
            blocks = chosen.len(),
            moved,
            moving,
            freed,
            wanted = bytes,
            "defragmented"
        );
        Ok(drained)
    }

    /// Allocations a drain may move: resident streamed BLASes (not those a persistent TLAS
    /// references: its records are patched on residency changes only), meshes and textures.
    fn movable_owners(&self) -> HashMap<AllocationId, Owner> {
        let mut owners = HashMap::new();
        for (b, a) in self.res.blases().iter().enumerate() {
            let Some(a) = a else { continue };
            if !self.topo.buildable(b)
                || self
                    .topo
                    .parents(b)
                    .iter()
                    .any(|&t| self.tlases.is_persistent(t))
            {
                continue;
            }
            if let Some(id) = a.allocation_id() {
                owners.insert(id, Owner::Blas(b));
            }
        }
        for (m, g) in self.res.meshes().iter().enumerate() {
            if let Some(g) = g {
                owners.insert(g.buffer.id(), Owner::Mesh(m));
            }
        }
        for (t, b) in self.shading.resident() {
            owners.insert(b.id(), Owner::Texture(t));
        }
        owners
    }

    /// Copies `movers` into new allocations (placed outside the draining blocks, in existing
    /// free space only) and frees the originals; stops at the first that does not fit (the
    /// rest stay). Returns how many moved, by kind.
    fn move_out(&mut self, movers: &[Owner]) -> Result<Drained> {
        let ctx = self.ctx.clone();
        // Uploads still queued into a mesh must land before it is copied.
        self.up_mut()?.flush(&ctx)?;
        let mut blas_new: Vec<(usize, AccelStruct)> = Vec::new();
        let mut mesh_new: Vec<(usize, HeapBuffer)> = Vec::new();
        let mut texture_new: Vec<(usize, HeapBuffer)> = Vec::new();
        for &o in movers {
            let placed = match o {
                Owner::Blas(b) => {
                    let size = self.res.blas(b).map_or(0, |a| a.size_bytes);
                    AccelStruct::new(
                        &ctx,
                        &mut self.heap,
                        &format!("blas-{b}-moved"),
                        size,
                        motu_vk::AsLevel::Bottom,
                    )
                    .map(|a| blas_new.push((b, a)))
                    .map_err(Into::into)
                }
                Owner::Mesh(m) => match self.res.mesh(m) {
                    Some(g) => g
                        .alloc_move_target(&mut self.heap, m)
                        .map(|buf| mesh_new.push((m, buf))),
                    None => Ok(()),
                },
                Owner::Texture(t) => match self.shading.texture(t).map(|b| b.size_bytes()) {
                    Some(size) => {
                        crate::scene::shading::alloc_texture_move_target(&mut self.heap, size)
                            .map(|buf| texture_new.push((t, buf)))
                    }
                    None => Ok(()),
                },
            };
            if placed.is_err() {
                break;
            }
        }
        let copied = (|| -> Result<()> {
            let mut rec = ctx.record("defragment")?;
            for (m, buf) in &mesh_new {
                if let Some(g) = self.res.mesh(*m) {
                    rec.copy_buffer(&g.buffer, 0, buf, 0, g.buffer.size_bytes())?;
                }
            }
            for (t, buf) in &texture_new {
                if let Some(old) = self.shading.texture(*t) {
                    rec.copy_buffer(old, 0, buf, 0, old.size_bytes())?;
                }
            }
            for (b, dst) in &blas_new {
                if let Some(src) = self.res.blas(*b) {
                    // Both structures live until the fenced submission returns; dst was
                    // created with src's size and level.
                    rec.copy_acceleration_structure(
                        src.target(),
                        dst.target(),
                        motu_vk::AsCopyMode::Clone,
                    )?;
                }
            }
            rec.submit_and_wait().map_err(Into::into)
        })();
        if let Err(e) = copied {
            blas_new
                .into_iter()
                .for_each(|(_, a)| a.release(&mut self.heap));
            mesh_new
                .into_iter()
                .chain(texture_new)
                .for_each(|(_, b)| self.heap.free(b));
            return Err(e);
        }
        let moved = Drained {
            blases: blas_new.len() as u32,
            meshes: mesh_new.len() as u32,
            textures: texture_new.len() as u32,
            freed_bytes: 0,
        };
        for (b, a) in blas_new {
            if let Some(old) = self.res.moved_blas(b, a) {
                old.release(&mut self.heap);
            }
            // Its instance records hold the old address.
            self.dirty_parents(b);
        }
        for (t, buf) in texture_new {
            let old = self.shading.moved_to(t, buf);
            self.heap.free(old);
        }
        for (m, buf) in mesh_new {
            if let Some(g) = self.res.mesh_to_move(m) {
                let old = g.moved_to(buf)?;
                self.heap.free(old);
            } else {
                self.heap.free(buf);
            }
        }
        Ok(moved)
    }
}
