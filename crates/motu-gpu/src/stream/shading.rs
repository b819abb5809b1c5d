//! Shading under streaming: the texture records and the per-texture address table stay
//! resident (counted in the budget and in the floor's `shading_tables_bytes`); each mesh's
//! normals and texture coordinates stream with its geometry (`MeshGpu::alloc_streamed`), and
//! each texture's mip chain streams with the meshes whose materials sample it (a reference per
//! resident mesh: loaded with the first, freed with the last). The per-mesh attribute table
//! and the per-texture address table the shaders read are rewritten as meshes come and go.
//!
//! Invariants ([`StreamShading`], fields private to this file): a texture's chain is resident
//! exactly while its reference count (the resident meshes that sample it) is above 0; the
//! per-texture address table is queued again whenever a chain came, went or moved since it
//! was last queued; `address` and the two table indices are set once, by `init_shading`.

use motu_vk::HeapBuffer;

use super::StreamingRenderer;
use crate::error::{GpuError, Result};
use crate::shading::{mesh_textures, upload_streamed_texture, Texels};

/// The renderer's shading tables and resident textures.
#[derive(Debug, Default)]
pub(super) struct StreamShading {
    /// `FrameParams::shading` (the `ShadingRef` header), 0 before [`init_shading`].
    ///
    /// [`init_shading`]: StreamingRenderer::init_shading
    address: u64,
    /// Index in the renderer's `tables` of the per-mesh attribute-address table.
    mesh_attrs_table: Option<usize>,
    /// Index in the renderer's `tables` of the per-texture address table.
    texel_addresses_table: Option<usize>,
    /// Per texture: its chain while a resident mesh samples it.
    textures: Vec<Option<HeapBuffer>>,
    /// Per texture: resident meshes that sample it.
    texture_refs: Vec<u32>,
    /// Textures came or went since the address table was last queued.
    textures_changed: bool,
}

impl StreamShading {
    /// `FrameParams::shading`: the address of the `ShadingRef` header (0 before
    /// [`init_shading`](StreamingRenderer::init_shading)).
    pub(super) fn address(&self) -> u64 {
        self.address
    }

    /// Textures resident now.
    pub(super) fn resident_textures(&self) -> u32 {
        self.textures.iter().filter(|t| t.is_some()).count() as u32
    }

    /// Texture `t`'s buffer while resident.
    pub(super) fn texture(&self, t: usize) -> Option<&HeapBuffer> {
        self.textures.get(t).and_then(Option::as_ref)
    }

    /// Resident textures: (texture, its buffer).
    pub(super) fn resident(&self) -> impl Iterator<Item = (usize, &HeapBuffer)> {
        self.textures
            .iter()
            .enumerate()
            .filter_map(|(t, b)| Some((t, b.as_ref()?)))
    }

    /// Puts `buffer` (a copy of texture `t`'s texels) in its place, its address rewritten with
    /// the next tables; returns the old buffer (or `buffer` itself when `t` is not resident).
    pub(super) fn moved_to(&mut self, t: usize, buffer: HeapBuffer) -> HeapBuffer {
        match self.textures.get_mut(t).and_then(Option::as_mut) {
            Some(slot) => {
                self.textures_changed = true;
                std::mem::replace(slot, buffer)
            }
            None => buffer,
        }
    }
}

impl<'a> StreamingRenderer<'a> {
    /// Uploads the texture records, an empty per-texture address table and an empty attribute
    /// table (no mesh resident).
    pub(super) fn init_shading(&mut self) -> Result<()> {
        let ctx = self.ctx.clone();
        let used = vec![false; self.view.meshes.len()];
        let up = self
            .up
            .as_mut()
            .ok_or_else(|| GpuError::InvalidRequest("streaming: staging ring released".into()))?;
        let t = crate::shading::upload(
            &ctx,
            &mut self.heap,
            up,
            &self.view,
            self.source,
            &used,
            Texels::Streamed,
        )?;
        let n = self.view.textures.len();
        let first = self.gpu.keep_tables(t.buffers);
        self.shading = StreamShading {
            address: t.address,
            mesh_attrs_table: t.mesh_attrs.map(|i| first + i),
            texel_addresses_table: t.texel_addresses.map(|i| first + i),
            textures: (0..n).map(|_| None).collect(),
            texture_refs: vec![0; n],
            textures_changed: false,
        };
        Ok(())
    }

    /// Takes mesh `m`'s references on the textures its material samples, streaming in those
    /// not resident (evicting for room when `evict`). Returns the bytes streamed. On failure
    /// the references taken here are dropped again.
    pub(super) fn acquire_mesh_textures(&mut self, m: usize, evict: bool) -> Result<u64> {
        let mut streamed = 0u64;
        let wanted = mesh_textures(&self.view, m);
        for (k, &t) in wanted.iter().enumerate() {
            self.shading.texture_refs[t] += 1;
            if self.shading.textures[t].is_some() {
                continue;
            }
            let loaded = self.maybe_evicting(evict, |s| {
                let ctx = s.ctx.clone();
                let up = s.up.as_mut().ok_or_else(|| {
                    GpuError::InvalidRequest("streaming: staging ring released".into())
                })?;
                upload_streamed_texture(&ctx, &mut s.heap, up, &s.view, t)
            });
            match loaded {
                Ok(buf) => {
                    streamed += buf.size_bytes();
                    self.shading.textures[t] = Some(buf);
                    self.shading.textures_changed = true;
                }
                Err(e) => {
                    for &u in &wanted[..=k] {
                        self.release_texture(u);
                    }
                    return Err(e);
                }
            }
        }
        Ok(streamed)
    }

    /// Drops mesh `m`'s references on its textures (the mesh left), freeing those no resident
    /// mesh samples any more.
    pub(super) fn release_mesh_textures(&mut self, m: usize) {
        for t in mesh_textures(&self.view, m) {
            self.release_texture(t);
        }
    }

    fn release_texture(&mut self, t: usize) {
        let refs = &mut self.shading.texture_refs[t];
        *refs = refs.saturating_sub(1);
        if *refs == 0 {
            if let Some(buf) = self.shading.textures[t].take() {
                // Copies still queued into it must land before it is destroyed.
                let ctx = self.ctx.clone();
                if let Some(up) = self.up.as_mut() {
                    let _ = up.flush(&ctx);
                }
                self.heap.free(buf);
                self.shading.textures_changed = true;
            }
        }
    }

    /// Queues the attribute addresses of the resident meshes and, when textures came or went,
    /// the per-texture addresses (flushed by the caller).
    pub(super) fn queue_mesh_attrs(&mut self) -> Result<()> {
        let ctx = self.ctx.clone();
        if let Some(table) = self.shading.mesh_attrs_table {
            let mut attrs = vec![0u64; 2 * self.res.meshes().len()];
            for (m, g) in self.res.meshes().iter().enumerate() {
                if let Some(g) = g {
                    attrs[2 * m] = g.normals_address;
                    attrs[2 * m + 1] = g.uvs_address;
                }
            }
            let up = self.up.as_mut().ok_or_else(|| {
                GpuError::InvalidRequest("streaming: staging ring released".into())
            })?;
            up.upload(&ctx, self.gpu.table(table), 0, bytemuck::cast_slice(&attrs))?;
        }
        if let (Some(table), true) = (
            self.shading.texel_addresses_table,
            self.shading.textures_changed,
        ) {
            let mut addrs = Vec::with_capacity(self.shading.textures.len());
            for t in &self.shading.textures {
                addrs.push(match t {
                    Some(b) => b.device_address()?.0,
                    None => 0,
                });
            }
            let up = self.up.as_mut().ok_or_else(|| {
                GpuError::InvalidRequest("streaming: staging ring released".into())
            })?;
            up.upload(&ctx, self.gpu.table(table), 0, bytemuck::cast_slice(&addrs))?;
            self.shading.textures_changed = false;
        }
        Ok(())
    }
}
