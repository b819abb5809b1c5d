//! The scene's shading tables on the GPU (`shade.glsl`'s `ShadingRef`): per-vertex normals and
//! texture coordinates of the meshes a render reaches, the texture records and every texture's
//! mip chain of RGBA8 texels (sampled in software by device address, so both backends and the
//! CPU sample alike). Allocated as `AllocKind::Texture` under the scene's budget.

use bytemuck::{cast_slice, Pod, Zeroable};
use motu_abi::{HierarchyView, FLAG_HAS_NORMALS, FLAG_HAS_UVS};
use motu_alloc::{AllocKind, MemoryClass};
use motu_vk::{Context, GpuHeap, HeapBuffer};

use crate::error::Result;
use crate::scene::{table_usage, MeshBlobSource, Uploader};

/// `ShadingRef` of `shade.glsl`.
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
#[repr(C)]
struct ShadingHeader {
    mesh_attrs: u64,
    textures: u64,
    texels: u64,
    /// Streaming: per texture, its own chain's address (0: not resident).
    texel_addresses: u64,
}

/// How texels reach the GPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Texels {
    /// Every chain in one resident array (a full build).
    Resident,
    /// Each texture in its own buffer, made resident with the meshes that use it (streaming):
    /// the records' texel offsets are 0 and a per-texture address table says where each is.
    Streamed,
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
    /// [`Texels::Streamed`]: index in `buffers` of the per-texture address table.
    pub(crate) texel_addresses: Option<usize>,
}

/// Bytes [`upload`] allocates besides the per-mesh attributes (the attribute-address table,
/// texture records, texels or the per-texture address table, header; 16-byte aligned each):
/// with [`Texels::Streamed`], what streaming keeps resident for shading (the floor's
/// `shading_tables_bytes`).
pub(crate) fn table_bytes(view: &HierarchyView<'_>, texels: Texels) -> u64 {
    let sized = |n: usize| if n == 0 { 0 } else { align16(n as u64) };
    let texel_bytes = match texels {
        Texels::Resident => sized(std::mem::size_of_val(view.texels)),
        Texels::Streamed => sized(8 * view.textures.len()),
    };
    sized(16 * view.meshes.len())
        + sized(std::mem::size_of_val(view.textures))
        + texel_bytes
        + align16(std::mem::size_of::<ShadingHeader>() as u64)
}

fn align16(n: u64) -> u64 {
    n.max(16).div_ceil(16) * 16
}

/// The textures the materials of `mesh` sample (base colour, alpha), without repeats.
pub(crate) fn mesh_textures(view: &HierarchyView<'_>, mesh: usize) -> Vec<usize> {
    let mut out = Vec::new();
    let Some(mat) = view
        .meshes
        .get(mesh)
        .and_then(|m| view.materials.get(m.material as usize))
    else {
        return out;
    };
    for t in [mat.base_color_texture, mat.alpha_texture] {
        if (t as usize) < view.textures.len() && !out.contains(&(t as usize)) {
            out.push(t as usize);
        }
    }
    out
}

/// The texels of texture `t` (its whole mip chain) in the package's texel array.
pub(crate) fn texture_texels<'v>(view: &HierarchyView<'v>, t: usize) -> Option<&'v [u32]> {
    let rec = view.textures.get(t)?;
    let start = rec.texel_offset as usize;
    view.texels.get(start..start + rec.texel_count() as usize)
}

/// Bytes texture `t` takes on the GPU when streamed (its own buffer).
pub(crate) fn streamed_texture_bytes(view: &HierarchyView<'_>, t: usize) -> u64 {
    view.textures
        .get(t)
        .map_or(0, |r| align16(4 * r.texel_count()))
}

/// Allocates and uploads texture `t`'s own chain (streaming); its address goes into the
/// per-texture address table.
pub(crate) fn upload_streamed_texture(
    ctx: &Context,
    heap: &mut GpuHeap,
    up: &mut Uploader,
    view: &HierarchyView<'_>,
    t: usize,
) -> Result<HeapBuffer> {
    let texels = texture_texels(view, t).ok_or_else(|| {
        crate::error::GpuError::InvalidRequest(format!(
            "texture {t}: its texels lie outside the package's texel array"
        ))
    })?;
    let bytes: &[u8] = cast_slice(texels);
    let buf = alloc(heap, "texture", bytes.len() as u64)?;
    if let Err(e) = up.upload(ctx, &buf, 0, bytes) {
        // Queued copies into it must land before it is destroyed.
        let _ = up.flush(ctx);
        heap.free(buf);
        return Err(e);
    }
    Ok(buf)
}

/// A new buffer for a streamed texture's `size` bytes (a streamer emptying a memory block
/// copies the texels into it).
pub(crate) fn alloc_texture_move_target(heap: &mut GpuHeap, size: u64) -> Result<HeapBuffer> {
    alloc(heap, "texture-moved", size)
}

fn alloc(heap: &mut GpuHeap, label: &str, size: u64) -> Result<HeapBuffer> {
    heap.alloc_buffer(
        label,
        size.max(16),
        // Copied from when a streamer moves it.
        table_usage() | motu_vk::BufferUsage::TRANSFER_SRC,
        AllocKind::Texture,
        MemoryClass::DeviceLocal,
        16,
    )
    .map_err(Into::into)
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
    texels: Texels,
) -> Result<ShadingTables> {
    let mut out = ShadingTables {
        buffers: Vec::new(),
        address: 0,
        texture_bytes: 0,
        attribute_bytes: 0,
        mesh_attrs: None,
        texel_addresses: None,
    };
    let input = FillInput {
        view,
        source,
        used,
        texels,
    };
    match fill(ctx, heap, up, &input, &mut out) {
        Ok(()) => Ok(out),
        Err(e) => {
            for b in out.buffers.drain(..) {
                heap.free(b);
            }
            Err(e)
        }
    }
}

/// What [`fill`] uploads: the view's tables, the attributes of the `used` meshes.
struct FillInput<'a, 'v> {
    view: &'a HierarchyView<'v>,
    source: &'a dyn MeshBlobSource,
    used: &'a [bool],
    texels: Texels,
}

fn fill(
    ctx: &Context,
    heap: &mut GpuHeap,
    up: &mut Uploader,
    input: &FillInput<'_, '_>,
    out: &mut ShadingTables,
) -> Result<()> {
    let FillInput {
        view,
        source,
        used,
        texels,
    } = *input;
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
            .map_err(crate::error::GpuError::mesh_source(m))?;
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
    // Streamed: records addressed from their own chains (offset 0), and an address table
    // that starts empty (nothing resident).
    let streamed_records: Vec<motu_abi::shade::TextureRecord> = view
        .textures
        .iter()
        .map(|r| motu_abi::shade::TextureRecord {
            texel_offset: 0,
            ..*r
        })
        .collect();
    let no_addresses = vec![0u64; view.textures.len()];
    let (records, texel_bytes, texel_label): (&[u8], &[u8], &str) = match texels {
        Texels::Resident => (cast_slice(view.textures), cast_slice(view.texels), "texels"),
        Texels::Streamed => (
            cast_slice(&streamed_records),
            cast_slice(&no_addresses),
            "texture-addresses",
        ),
    };
    let tables: [(&[u8], usize); 3] = [(cast_slice(&attrs), 0), (records, 1), (texel_bytes, 2)];
    for (bytes, k) in tables {
        if bytes.is_empty() {
            continue;
        }
        let buf = alloc(
            heap,
            ["shading-mesh-attrs", "textures", texel_label][k],
            bytes.len() as u64,
        )?;
        let a = buf.device_address()?.0;
        match k {
            0 => {
                header.mesh_attrs = a;
                out.mesh_attrs = Some(out.buffers.len());
            }
            1 => header.textures = a,
            _ if texels == Texels::Streamed => {
                header.texel_addresses = a;
                out.texel_addresses = Some(out.buffers.len());
            }
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
