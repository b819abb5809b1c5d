//! Reading a scene package: the meta, a zero-copy hierarchy view, mesh data by chunk.

use crate::blob::MeshBlobLayout;
use crate::meta::{PackageMeta, SCHEMA};
use crate::sections::*;
use crate::PackError;
use motu_abi::{HierarchyView, MeshRecord, FLAG_PRIMITIVE_MAP, NONE_U64};
use motu_package::{ChunkId, Package};
use std::path::Path;

/// One compiled mesh's data, copied out of its chunk.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshGeometry {
    pub positions: Vec<[f32; 3]>,
    pub indices: Vec<u32>,
    pub normals: Option<Vec<[f32; 3]>>,
    /// A cluster's source primitive per triangle (`FLAG_PRIMITIVE_MAP`), else `None`.
    pub primitive_map: Option<Vec<u32>>,
    pub uvs: Option<Vec<[f32; 2]>>,
}

/// An opened scene package.
#[derive(Debug)]
pub struct ScenePackage {
    package: Package,
    meta: PackageMeta,
    path: String,
}

impl ScenePackage {
    /// Maps the package, checks the container and the schema, and checks every cross-table
    /// reference so later traversal can index without panics. O(manifest + tables).
    pub fn open(path: &Path) -> Result<Self, PackError> {
        let _span = tracing::info_span!("open_package", path = %path.display()).entered();
        let package = Package::open(path)?;
        let shown = path.display().to_string();
        let meta_bytes = package.section_bytes(SECTION_META)?;
        let meta = crate::meta::parse_meta(meta_bytes).map_err(|source| PackError::Meta {
            path: shown.clone(),
            source,
        })?;
        let me = Self {
            package,
            meta,
            path: shown.clone(),
        };
        let view = me.view()?;
        view.check_references()
            .map_err(|source| PackError::References {
                path: shown.clone(),
                source,
            })?;
        let clusters_allowed = me.meta.schema == SCHEMA;
        for (i, m) in view.meshes.iter().enumerate() {
            if !clusters_allowed && m.flags & FLAG_PRIMITIVE_MAP != 0 {
                return Err(PackError::Mesh {
                    mesh: i as u32,
                    reason: format!("a primitive map in a '{}' package", me.meta.schema),
                });
            }
            me.check_mesh(i as u32, m)?;
        }
        Ok(me)
    }

    pub fn package(&self) -> &Package {
        &self.package
    }

    pub fn meta(&self) -> &PackageMeta {
        &self.meta
    }

    pub fn path(&self) -> &str {
        &self.path
    }

    /// The hierarchy tables, borrowed from the map.
    pub fn view(&self) -> Result<HierarchyView<'_>, PackError> {
        let p = &self.package;
        Ok(HierarchyView {
            root_tlas: self.meta.root_tlas,
            tlases: p.section_as(SECTION_TLASES)?,
            instances: p.section_as(SECTION_INSTANCES)?,
            blases: p.section_as(SECTION_BLASES)?,
            geometries: p.section_as(SECTION_GEOMETRIES)?,
            pis: p.section_as(SECTION_PIS)?,
            lod_selectors: p.section_as(SECTION_LOD_SELECTORS)?,
            lod_levels: p.section_as(SECTION_LOD_LEVELS)?,
            meshes: p.section_as(SECTION_MESHES)?,
            materials: p.section_as(SECTION_MATERIALS)?,
            textures: p.section_as(SECTION_TEXTURES)?,
            texels: p.section_as(SECTION_TEXELS)?,
        })
    }

    /// The stream split stored at import for `cap_instances`: `Ok(None)` when the package
    /// stores none for that cap (written before it was stored, or split for another cap;
    /// the caller splits itself), `Ok(Some(None))` when no TLAS is over the cap, else the
    /// tables, borrowed from the map.
    #[allow(clippy::type_complexity)]
    pub fn stored_stream_split(
        &self,
        cap_instances: u32,
    ) -> Result<Option<Option<crate::StreamSplitTables<'_>>>, PackError> {
        let Some(m) = &self.meta.stream_split else {
            return Ok(None);
        };
        if m.cap_instances != cap_instances {
            return Ok(None);
        }
        if m.tlases_split == 0 {
            return Ok(Some(None));
        }
        let p = &self.package;
        Ok(Some(Some(crate::StreamSplitTables {
            tlases: p.section_as(SECTION_SPLIT_TLASES)?,
            blases: p.section_as(SECTION_SPLIT_BLASES)?,
            pis: p.section_as(SECTION_SPLIT_PIS)?,
            instance_source: p.section_as(SECTION_SPLIT_INSTANCE_SOURCE)?,
            extra_instances: p.section_as(SECTION_SPLIT_EXTRA_INSTANCES)?,
        })))
    }

    /// The `proxy_boxes` section's bytes (`motu_compile::proxy_boxes::decode_section` reads
    /// them): `Ok(None)` in a package written without it, an error when its checksum fails.
    pub fn stored_proxy_boxes(&self) -> Result<Option<&[u8]>, PackError> {
        if self.package.section_info(SECTION_PROXY_BOXES).is_none() {
            return Ok(None);
        }
        Ok(Some(self.package.section_bytes(SECTION_PROXY_BOXES)?))
    }

    /// The `proxy_clusters` section's bytes (`motu_compile::proxy_clusters::decode_section`
    /// reads them): `Ok(None)` in a package written without it, an error when its checksum
    /// fails.
    pub fn stored_proxy_clusters(&self) -> Result<Option<&[u8]>, PackError> {
        if self.package.section_info(SECTION_PROXY_CLUSTERS).is_none() {
            return Ok(None);
        }
        Ok(Some(self.package.section_bytes(SECTION_PROXY_CLUSTERS)?))
    }

    /// The `blas_counts` section's bytes (`motu_compile::blas_counts::decode_section` reads
    /// them): `Ok(None)` in a package written without it, an error when its checksum fails.
    pub fn stored_blas_counts(&self) -> Result<Option<&[u8]>, PackError> {
        if self.package.section_info(SECTION_BLAS_COUNTS).is_none() {
            return Ok(None);
        }
        Ok(Some(self.package.section_bytes(SECTION_BLAS_COUNTS)?))
    }

    fn layout(m: &MeshRecord) -> MeshBlobLayout {
        MeshBlobLayout::with_map(
            m.vertex_count as u64,
            m.triangle_count as u64,
            m.normals_offset != NONE_U64,
            m.flags & FLAG_PRIMITIVE_MAP != 0,
        )
        .with_uvs(m.flags & motu_abi::FLAG_HAS_UVS != 0)
    }

    /// Mesh records must point inside their chunk with the blob layout's offsets.
    fn check_mesh(&self, index: u32, m: &MeshRecord) -> Result<(), PackError> {
        let err = |reason: String| PackError::Mesh {
            mesh: index,
            reason,
        };
        let info = self
            .package
            .chunk_info(ChunkId(m.chunk))
            .map_err(|source| PackError::MeshChunk {
                mesh: index,
                source,
            })?;
        let l = Self::layout(m);
        let base = m.positions_offset;
        let ok = m.indices_offset == base + l.indices
            && (m.normals_offset == NONE_U64 || m.normals_offset == base + l.normals)
            && (!l.has_primitive_map || m.primitive_map_offset == base + l.primitive_map)
            && (!l.has_uvs || m.uvs_offset == base + l.uvs)
            && base
                .checked_add(l.len)
                .is_some_and(|end| end <= info.raw_len);
        if ok {
            Ok(())
        } else {
            Err(err(format!(
                "offsets {}/{}/{} do not fit chunk {} ({} bytes)",
                m.positions_offset, m.indices_offset, m.normals_offset, m.chunk, info.raw_len
            )))
        }
    }

    /// Copies a compiled mesh's data out of its chunk (decompressing it if needed).
    pub fn mesh_geometry(&self, mesh_record: u32) -> Result<MeshGeometry, PackError> {
        let meshes: &[MeshRecord] = self.package.section_as(SECTION_MESHES)?;
        let m = meshes
            .get(mesh_record as usize)
            .ok_or_else(|| PackError::Mesh {
                mesh: mesh_record,
                reason: format!("only {} meshes", meshes.len()),
            })?;
        let chunk = self.package.chunk(ChunkId(m.chunk))?;
        let l = Self::layout(m);
        let start = m.positions_offset as usize;
        let blob = chunk
            .get(start..start + l.len as usize)
            .ok_or_else(|| PackError::Mesh {
                mesh: mesh_record,
                reason: "blob outside its chunk".into(),
            })?;
        let err = |reason| PackError::Mesh {
            mesh: mesh_record,
            reason,
        };
        let data = l.decode(blob).map_err(err)?;
        let primitive_map = l.decode_primitive_map(blob).map_err(err)?;
        Ok(MeshGeometry {
            positions: data.positions,
            indices: data.indices,
            normals: data.normals,
            primitive_map,
            uvs: data.uvs,
        })
    }
}

/// Reads the mesh blob a [`crate::PackageGeometry`] stored at `at` from a finished package
/// (used to copy a subset's meshes into a new package).
pub fn read_mesh_blob(
    package: &Package,
    at: motu_scene::MeshLocation,
    vertex_count: u32,
    triangle_count: u32,
    has_normals: bool,
    has_uvs: bool,
) -> Result<motu_scene::MeshData, PackError> {
    let l = MeshBlobLayout::new(vertex_count as u64, triangle_count as u64, has_normals)
        .with_uvs(has_uvs);
    let chunk = package.chunk(ChunkId(at.a as u32))?;
    let start = at.b as usize;
    let blob = chunk
        .get(start..start + l.len as usize)
        .ok_or_else(|| PackError::Mesh {
            mesh: u32::MAX,
            reason: format!(
                "blob at chunk {} offset {} is outside its chunk",
                at.a, at.b
            ),
        })?;
    l.decode(blob).map_err(|reason| PackError::Mesh {
        mesh: u32::MAX,
        reason,
    })
}

/// `bytes` as a slice of `T`: borrowed where `borrowed` (the chunk lives in the map) and the
/// bytes are aligned for `T`, else copied.
fn borrow_or_copy<T: bytemuck::Pod>(bytes: &[u8], borrowed: bool) -> std::borrow::Cow<'_, [T]> {
    match bytemuck::try_cast_slice(bytes) {
        Ok(values) if borrowed => std::borrow::Cow::Borrowed(values),
        _ => std::borrow::Cow::Owned(bytemuck::pod_collect_to_vec(bytes)),
    }
}

/// A mesh's normals and texture coordinates (where `m` has them) in `chunk`, its chunk's raw
/// bytes: borrowed where `borrowed` and aligned ([`borrow_or_copy`]).
#[allow(clippy::type_complexity)]
fn shading_slices<'c>(
    chunk: &'c [u8],
    borrowed: bool,
    m: &MeshRecord,
    mesh_record: u32,
) -> Result<
    (
        Option<std::borrow::Cow<'c, [[f32; 3]]>>,
        Option<std::borrow::Cow<'c, [[f32; 2]]>>,
    ),
    PackError,
> {
    let get = |at: u64, n: u64| -> Result<&'c [u8], PackError> {
        chunk
            .get(at as usize..(at + n) as usize)
            .ok_or_else(|| PackError::Mesh {
                mesh: mesh_record,
                reason: "blob outside its chunk".into(),
            })
    };
    let vc = m.vertex_count as u64;
    let normals = match m.normals_offset != NONE_U64 {
        true => Some(borrow_or_copy(get(m.normals_offset, vc * 12)?, borrowed)),
        false => None,
    };
    let uvs = match m.flags & motu_abi::FLAG_HAS_UVS != 0 {
        true => Some(borrow_or_copy(get(m.uvs_offset, vc * 8)?, borrowed)),
        false => None,
    };
    Ok((normals, uvs))
}

impl ScenePackage {
    /// The distinct chunks holding mesh records `mesh_records`, in first-seen order (a record
    /// out of range is skipped: reading it reports the error).
    pub fn mesh_chunks(&self, mesh_records: &[u32]) -> Vec<ChunkId> {
        let Ok(meshes) = self.package.section_as::<MeshRecord>(SECTION_MESHES) else {
            return Vec::new();
        };
        let mut seen = std::collections::HashSet::new();
        mesh_records
            .iter()
            .filter_map(|&m| meshes.get(m as usize))
            .map(|r| ChunkId(r.chunk))
            .filter(|c| seen.insert(c.0))
            .collect()
    }

    /// Hints the kernel to read chunk `id` ahead ([`motu_package::Package::prefetch_chunk`]);
    /// advice only.
    pub fn prefetch_chunk(&self, id: ChunkId) {
        let _ = self.package.prefetch_chunk(id);
    }

    /// Of `ids`, the compressed chunks worth decoding ahead of a group's reads (each once, on
    /// threads of their own: [`ScenePackage::decode_chunk_ahead`]), in order, as many as the
    /// package's cache of decoded chunks holds ([`motu_package::DECODED_CACHE_BYTES`]).
    pub fn chunks_to_decode_ahead(&self, ids: &[ChunkId]) -> Vec<ChunkId> {
        let mut held = 0u64;
        ids.iter()
            .copied()
            .filter(|&c| {
                self.package.chunk_info(c).is_ok_and(|i| {
                    let zstd = i.codec == motu_package::Codec::Zstd;
                    held += if zstd { i.raw_len } else { 0 };
                    zstd && held <= motu_package::DECODED_CACHE_BYTES
                })
            })
            .collect()
    }

    /// Decodes chunk `id` into the package's cache of decoded chunks (the mesh reads then take
    /// their pieces from it); a failure is left for the read, which reports it.
    pub fn decode_chunk_ahead(&self, id: ChunkId) {
        let _ = self.package.chunk_shared(id);
    }

    /// Chunks decompressed so far ([`motu_package::Package::chunk_decodes`]).
    pub fn chunk_decodes(&self) -> u64 {
        self.package.chunk_decodes()
    }

    /// First-touch chunk checksums so far and their bytes
    /// ([`motu_package::Package::chunk_checks`]).
    pub fn chunk_checks(&self) -> (u64, u64) {
        self.package.chunk_checks()
    }

    /// Checks chunk `id`'s checksum now, if no read has yet (its first touch: callers
    /// verify several chunks in parallel before reading meshes from them). A failure is left
    /// for the read, which reports it.
    pub fn verify_chunk(&self, id: ChunkId) {
        let _ = self.package.chunk_stored(id);
    }

    /// A compiled mesh's positions and indices: borrowed from the map for raw chunks (zero
    /// copy, straight into a staging buffer), decoded copies for compressed ones.
    #[allow(clippy::type_complexity)]
    pub fn mesh_slices(
        &self,
        mesh_record: u32,
    ) -> Result<
        (
            std::borrow::Cow<'_, [[f32; 3]]>,
            std::borrow::Cow<'_, [u32]>,
        ),
        PackError,
    > {
        use std::borrow::Cow;
        let meshes: &[MeshRecord] = self.package.section_as(SECTION_MESHES)?;
        let err = |reason: String| PackError::Mesh {
            mesh: mesh_record,
            reason,
        };
        let m = meshes
            .get(mesh_record as usize)
            .ok_or_else(|| err(format!("only {} meshes", meshes.len())))?;
        let (vb, ib) = (m.vertex_count as u64 * 12, m.triangle_count as u64 * 12);
        match self.package.chunk_shared(ChunkId(m.chunk))? {
            motu_package::ChunkBytes::Borrowed(bytes) => {
                let slice = |at: u64, n: u64| -> Result<&[u8], PackError> {
                    bytes
                        .get(at as usize..(at + n) as usize)
                        .ok_or_else(|| err("blob outside its chunk".into()))
                };
                let p: &[[f32; 3]] = bytemuck::try_cast_slice(slice(m.positions_offset, vb)?)
                    .map_err(|cast| PackError::MeshCast {
                        mesh: mesh_record,
                        what: "positions",
                        cast,
                    })?;
                let i: &[u32] =
                    bytemuck::try_cast_slice(slice(m.indices_offset, ib)?).map_err(|cast| {
                        PackError::MeshCast {
                            mesh: mesh_record,
                            what: "indices",
                            cast,
                        }
                    })?;
                Ok((Cow::Borrowed(p), Cow::Borrowed(i)))
            }
            owned => {
                let get = |at: u64, n: u64| {
                    owned
                        .get(at as usize..(at + n) as usize)
                        .ok_or_else(|| err("blob outside its chunk".into()))
                };
                let p: Vec<[f32; 3]> = bytemuck::pod_collect_to_vec(get(m.positions_offset, vb)?);
                let i: Vec<u32> = bytemuck::pod_collect_to_vec(get(m.indices_offset, ib)?);
                Ok((Cow::Owned(p), Cow::Owned(i)))
            }
        }
    }

    /// A compiled mesh's per-vertex normals and texture coordinates, where it has them
    /// (borrowed from raw chunks where aligned, else copied).
    #[allow(clippy::type_complexity)]
    pub fn mesh_shading_slices(
        &self,
        mesh_record: u32,
    ) -> Result<
        (
            Option<std::borrow::Cow<'_, [[f32; 3]]>>,
            Option<std::borrow::Cow<'_, [[f32; 2]]>>,
        ),
        PackError,
    > {
        let meshes: &[MeshRecord] = self.package.section_as(SECTION_MESHES)?;
        let err = |reason: String| PackError::Mesh {
            mesh: mesh_record,
            reason,
        };
        let m = meshes
            .get(mesh_record as usize)
            .ok_or_else(|| err(format!("only {} meshes", meshes.len())))?;
        let has_n = m.normals_offset != NONE_U64;
        let has_uv = m.flags & motu_abi::FLAG_HAS_UVS != 0;
        if !has_n && !has_uv {
            return Ok((None, None));
        }
        // Borrowed from the map where the chunk is raw; else from the decoded copy, copied.
        match self.package.chunk_shared(ChunkId(m.chunk))? {
            motu_package::ChunkBytes::Borrowed(bytes) => {
                shading_slices(bytes, true, m, mesh_record)
            }
            owned => {
                let (n, u) = shading_slices(&owned, false, m, mesh_record)?;
                fn own<T: Clone>(c: std::borrow::Cow<'_, [T]>) -> std::borrow::Cow<'static, [T]> {
                    std::borrow::Cow::Owned(c.into_owned())
                }
                Ok((n.map(own), u.map(own)))
            }
        }
    }

    /// A cluster's primitive map (`FLAG_PRIMITIVE_MAP`): borrowed from raw chunks, copied from
    /// compressed ones; `None` for a mesh without one.
    pub fn primitive_map_slice(
        &self,
        mesh_record: u32,
    ) -> Result<Option<std::borrow::Cow<'_, [u32]>>, PackError> {
        use std::borrow::Cow;
        let meshes: &[MeshRecord] = self.package.section_as(SECTION_MESHES)?;
        let err = |reason: String| PackError::Mesh {
            mesh: mesh_record,
            reason,
        };
        let m = meshes
            .get(mesh_record as usize)
            .ok_or_else(|| err(format!("only {} meshes", meshes.len())))?;
        if m.flags & FLAG_PRIMITIVE_MAP == 0 {
            return Ok(None);
        }
        let (at, n) = (m.primitive_map_offset, m.triangle_count as u64 * 4);
        let range = at as usize..(at + n) as usize;
        match self.package.chunk_shared(ChunkId(m.chunk))? {
            motu_package::ChunkBytes::Borrowed(b) => {
                let bytes = b
                    .get(range)
                    .ok_or_else(|| err("primitive map outside its chunk".into()))?;
                let map: &[u32] =
                    bytemuck::try_cast_slice(bytes).map_err(|cast| PackError::MeshCast {
                        mesh: mesh_record,
                        what: "primitive map",
                        cast,
                    })?;
                Ok(Some(Cow::Borrowed(map)))
            }
            owned => {
                let bytes = owned
                    .get(range)
                    .ok_or_else(|| err("primitive map outside its chunk".into()))?;
                Ok(Some(Cow::Owned(bytemuck::pod_collect_to_vec(bytes))))
            }
        }
    }
}
