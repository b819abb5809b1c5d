//! Where the GPU layer's meshes come from: a package's chunks, or a hierarchy in memory.

use std::borrow::Cow;

use crate::error::MeshSourceError;

/// Counts of a [`MeshBlobSource`]'s chunk reads so far ([`MeshBlobSource::chunk_reads`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ChunkReads {
    /// Chunks decompressed (a compressed package's).
    pub decodes: u64,
    /// First-touch checksums of whole chunks, and the stored bytes they read.
    pub checks: u64,
    pub checked_bytes: u64,
}

/// Geometry of one compiled mesh, by its index in the hierarchy's mesh table (e.g. slices of a
/// mapped package chunk, borrowed). `Sync`: the streaming renderer reads meshes from several
/// threads when it starts (the boxes inside BLASes).
pub trait MeshBlobSource: Sync {
    /// Positions (`vertex_count` of them) and `3 × triangle_count` indices.
    #[allow(clippy::type_complexity)]
    fn mesh_data(
        &self,
        mesh_record: u32,
    ) -> std::result::Result<(Cow<'_, [[f32; 3]]>, Cow<'_, [u32]>), MeshSourceError>;

    /// The primitive map (`triangle_count` source triangle ids) of a mesh record with
    /// `FLAG_PRIMITIVE_MAP` (a cluster of a partitioned mesh). Sources without clusters keep
    /// the default; a record with the flag then fails to upload rather than report cluster
    /// primitive ids as source ones.
    fn primitive_map(
        &self,
        _mesh_record: u32,
    ) -> std::result::Result<Option<Cow<'_, [u32]>>, MeshSourceError> {
        Ok(None)
    }

    /// Per-vertex normals and texture coordinates for shading, where the mesh has them
    /// (default: none, so shading uses geometric normals and constant colours).
    #[allow(clippy::type_complexity)]
    fn mesh_shading(
        &self,
        _mesh_record: u32,
    ) -> std::result::Result<
        (Option<Cow<'_, [[f32; 3]]>>, Option<Cow<'_, [[f32; 2]]>>),
        MeshSourceError,
    > {
        Ok((None, None))
    }

    /// Mesh records `mesh_records` are read next (a build group's): a source may start
    /// reading them ahead (a package: the kernel reads their chunks ahead, and the chunks'
    /// first-touch checksums run in parallel, and compressed chunks are decoded, each once, on
    /// threads of their own). Advice only; errors surface when reading.
    fn prepare(&self, _mesh_records: &[u32]) {}

    /// What reading chunks cost so far (a package's: the frame's `mesh_chunk_*` count it;
    /// nothing for sources without chunks).
    fn chunk_reads(&self) -> ChunkReads {
        ChunkReads::default()
    }

    /// The boxes inside triangle BLASes stored with the meshes (a package's `proxy_boxes`
    /// section, `motu_compile::proxy_boxes::encode_section`), where the source has them. The
    /// streamer checks each BLAS's entry against its records before using it.
    fn stored_proxy_boxes(&self) -> Option<&[u8]> {
        None
    }

    /// The proxy clusters of every TLAS stored with the meshes (a package's `proxy_clusters`
    /// section, `motu_compile::proxy_clusters::encode_section`), where the source has them.
    /// [`crate::StreamPlan::load`] checks each TLAS's entry against the view before using it.
    fn stored_proxy_clusters(&self) -> Option<&[u8]> {
        None
    }
}
