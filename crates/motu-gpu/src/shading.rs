//! The scene's shading tables on the GPU (`shade.glsl`'s `ShadingRef`): per-vertex normals and
//! texture coordinates of the meshes a render reaches, the texture records and every texture's
//! mip chain of RGBA8 texels (sampled in software by device address, so both backends and the
//! CPU sample alike). Allocated as `AllocKind::Texture` under the scene's budget.

use bytemuck::{cast_slice, Pod, Zeroable};
use motu_abi::{HierarchyView, FLAG_HAS_NORMALS, FLAG_HAS_UVS};
use motu_alloc::{AllocKind, MemoryClass};

use crate::context::Context;
use crate::error::Result;
use crate::heap::{GpuHeap, HeapBuffer};
use crate::scene::{table_usage, MeshBlobSource, Uploader};

/// `ShadingRef` of `shade.glsl`.
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
#[repr(C)]
struct ShadingHeader {
    mesh_attrs: u64,
    textures: u64,
    texels: u64,
    _pad: u64,
}

/// What [`upload`] made: the buffers (freed with the scene's tables) and the header address.
pub(crate) struct ShadingTables {
    pub(crate) buffers: Vec<HeapBuffer>,
    pub(crate) address: u64,
    /// Texture records and texels.
    pub(crate) texture_bytes: u64,
    /// Normals and texture coordinates.
    pub(crate) attribute_bytes: u64,
    /// Index in `buffers` of the per-mesh attribute-address table (the streaming renderer
    /// rewrites it as meshes come and go).
    pub(crate) mesh_attrs: Option<usize>,
}

/// Bytes [`upload`] allocates besides the per-mesh attributes (the attribute-address table,
/// texture records, texels, header; 16-byte aligned each): what streaming keeps resident for
/// shading (the floor's `shading_tables_bytes`).
pub(crate) fn table_bytes(view: &HierarchyView<'_>) -> u64 {
    let a = |n: u64| n.max(16).div_ceil(16) * 16;
    let sized = |n: usize| if n == 0 { 0 } else { a(n as u64) };
    sized(16 * view.meshes.len())
        + sized(std::mem::size_of_val(view.textures))
        + sized(std::mem::size_of_val(view.texels))
        + a(std::mem::size_of::<ShadingHeader>() as u64)
}

fn alloc(heap: &mut GpuHeap, label: &str, size: u64) -> Result<HeapBuffer> {
    heap.alloc_buffer(
        label,
        size.max(16),
        table_usage(),
        AllocKind::Texture,
        MemoryClass::DeviceLocal,
        16,
    )
}

/// Uploads the shading tables for the meshes marked in `used`. On error the buffers made so
/// far are freed.
pub(crate) fn upload(
    ctx: &Context,
    heap: &mut GpuHeap,
    up: &mut Uploader,
    view: &HierarchyView<'_>,
    source: &dyn MeshBlobSource,
    used: &[bool],
) -> Result<ShadingTables> {
    let mut out = ShadingTables {
        buffers: Vec::new(),
        address: 0,
        texture_bytes: 0,
        attribute_bytes: 0,
        mesh_attrs: None,
    };
    match fill(ctx, heap, up, view, source, used, &mut out) {
        Ok(()) => Ok(out),
        Err(e) => {
            for b in out.buffers.drain(..) {
                heap.free(b);
            }
            Err(e)
        }
    }
}

fn fill(
    ctx: &Context,
    heap: &mut GpuHeap,
    up: &mut Uploader,
    view: &HierarchyView<'_>,
    source: &dyn MeshBlobSource,
    used: &[bool],
    out: &mut ShadingTables,
) -> Result<()> {
    let mut header = ShadingHeader::default();
    // Per mesh: normals and uvs addresses (0: none).
    let mut attrs = vec![0u64; 2 * view.meshes.len()];
    for (m, rec) in view.meshes.iter().enumerate() {
        let wants = rec.flags & (FLAG_HAS_NORMALS | FLAG_HAS_UVS) != 0;
        if !used.get(m).copied().unwrap_or(false) || !wants {
            continue;
        }
        let (normals, uvs) = source
            .mesh_shading(m as u32)
            .map_err(|e| crate::error::GpuError::InvalidRequest(format!("mesh {m}: {e}")))?;
        let vc = rec.vertex_count as usize;
        let arrays: [(Option<&[u8]>, usize); 2] = [
            (
                normals
                    .as_deref()
                    .filter(|n| n.len() == vc && rec.flags & FLAG_HAS_NORMALS != 0)
                    .map(cast_slice),
                0,
            ),
            (
                uvs.as_deref()
                    .filter(|u| u.len() == vc && rec.flags & FLAG_HAS_UVS != 0)
                    .map(cast_slice),
                1,
            ),
        ];
        for (bytes, k) in arrays {
            let Some(bytes) = bytes else { continue };
            let buf = alloc(heap, "shading-attributes", bytes.len() as u64)?;
            attrs[2 * m + k] = buf.device_address()?.0;
            up.upload(ctx, &buf, 0, bytes)?;
            out.attribute_bytes += bytes.len() as u64;
            out.buffers.push(buf);
        }
    }
    let tables: [(&[u8], usize); 3] = [
        (cast_slice(&attrs), 0),
        (cast_slice(view.textures), 1),
        (cast_slice(view.texels), 2),
    ];
    for (bytes, k) in tables {
        if bytes.is_empty() {
            continue;
        }
        let buf = alloc(
            heap,
            ["shading-mesh-attrs", "textures", "texels"][k],
            bytes.len() as u64,
        )?;
        let a = buf.device_address()?.0;
        match k {
            0 => {
                header.mesh_attrs = a;
                out.mesh_attrs = Some(out.buffers.len());
            }
            1 => header.textures = a,
            _ => header.texels = a,
        }
        up.upload(ctx, &buf, 0, bytes)?;
        if k > 0 {
            out.texture_bytes += bytes.len() as u64;
        }
        out.buffers.push(buf);
    }
    let buf = alloc(
        heap,
        "shading-header",
        std::mem::size_of::<ShadingHeader>() as u64,
    )?;
    out.address = buf.device_address()?.0;
    up.upload(ctx, &buf, 0, bytemuck::bytes_of(&header))?;
    out.buffers.push(buf);
    Ok(())
}
