//! Shading under streaming: the texture tables stay resident (counted in the budget and in the
//! floor's `shading_tables_bytes`); each mesh's normals and texture coordinates stream with
//! its geometry (`MeshGpu::alloc_streamed`), and the per-mesh attribute table the shaders read
//! is rewritten as meshes come and go, next to the mesh-geometry table.

use super::StreamingRenderer;
use crate::error::{GpuError, Result};

/// The renderer's shading tables.
#[derive(Debug, Default)]
pub(super) struct StreamShading {
    /// `FrameParams::shading` (the `ShadingRef` header), 0 before [`init_shading`].
    ///
    /// [`init_shading`]: StreamingRenderer::init_shading
    pub(super) address: u64,
    /// Index in the renderer's `tables` of the per-mesh attribute-address table.
    mesh_attrs_table: Option<usize>,
}

impl<'a> StreamingRenderer<'a> {
    /// Uploads the texture records and texels and an empty attribute table (no mesh resident).
    pub(super) fn init_shading(&mut self) -> Result<()> {
        let ctx = self.ctx.clone();
        let used = vec![false; self.view.meshes.len()];
        let up = self
            .up
            .as_mut()
            .ok_or_else(|| GpuError::InvalidRequest("streaming: staging ring released".into()))?;
        let t = crate::shading::upload(&ctx, &mut self.heap, up, &self.view, self.source, &used)?;
        self.shading = StreamShading {
            address: t.address,
            mesh_attrs_table: t.mesh_attrs.map(|i| self.tables.len() + i),
        };
        self.tables.extend(t.buffers);
        Ok(())
    }

    /// Queues the attribute addresses of the resident meshes (flushed by the caller).
    pub(super) fn queue_mesh_attrs(&mut self) -> Result<()> {
        let Some(table) = self.shading.mesh_attrs_table else {
            return Ok(());
        };
        let mut attrs = vec![0u64; 2 * self.meshes.len()];
        for (m, g) in self.meshes.iter().enumerate() {
            if let Some(g) = g {
                attrs[2 * m] = g.normals_address;
                attrs[2 * m + 1] = g.uvs_address;
            }
        }
        let ctx = self.ctx.clone();
        let up = self
            .up
            .as_mut()
            .ok_or_else(|| GpuError::InvalidRequest("streaming: staging ring released".into()))?;
        up.upload(&ctx, &self.tables[table], 0, bytemuck::cast_slice(&attrs))
    }
}
