//! A package's meshes, straight from its chunks, for the CPU tracer and the GPU builds.

use motu_gpu::MeshSourceError;
use motu_pack::ScenePackage;
use std::borrow::Cow;

/// Mesh data for the tracers, straight from the package's chunks.
pub struct PackageMeshes<'a>(pub &'a ScenePackage);

impl motu_trace::MeshSource for PackageMeshes<'_> {
    fn load(&self, mesh_record: u32) -> Result<motu_trace::MeshGeometry, motu_trace::LoadError> {
        let g = self.0.mesh_geometry(mesh_record)?;
        Ok(motu_trace::MeshGeometry {
            positions: g.positions,
            indices: g.indices,
            normals: g.normals,
            primitive_map: g.primitive_map,
            uvs: g.uvs,
        })
    }
}

/// A package's positions, indices and primitive maps only, for GPU builds that need no shading
/// attributes (`motu report`'s compaction measurement): its shading tables stay empty.
pub struct PackageGeometry<'a>(pub &'a ScenePackage);

impl motu_gpu::MeshBlobSource for PackageGeometry<'_> {
    fn mesh_data(&self, mesh_record: u32) -> Result<Geometry<'_>, MeshSourceError> {
        mesh_data(self.0, mesh_record)
    }

    fn primitive_map(&self, mesh_record: u32) -> Result<Option<Cow<'_, [u32]>>, MeshSourceError> {
        primitive_map(self.0, mesh_record)
    }
}

/// A mesh's positions and indices.
type Geometry<'a> = (Cow<'a, [[f32; 3]]>, Cow<'a, [u32]>);

/// Positions and indices of a mesh record, borrowed from the package's chunks.
fn mesh_data(pkg: &ScenePackage, mesh_record: u32) -> Result<Geometry<'_>, MeshSourceError> {
    pkg.mesh_slices(mesh_record).map_err(MeshSourceError::from)
}

/// A cluster's primitive map (source triangle ids), where the record has one.
fn primitive_map(
    pkg: &ScenePackage,
    mesh_record: u32,
) -> Result<Option<Cow<'_, [u32]>>, MeshSourceError> {
    pkg.primitive_map_slice(mesh_record)
        .map_err(MeshSourceError::from)
}

/// The package's geometry ([`PackageGeometry`]) and its normals and texture coordinates.
impl motu_gpu::MeshBlobSource for PackageMeshes<'_> {
    fn mesh_data(&self, mesh_record: u32) -> Result<Geometry<'_>, MeshSourceError> {
        mesh_data(self.0, mesh_record)
    }

    fn primitive_map(&self, mesh_record: u32) -> Result<Option<Cow<'_, [u32]>>, MeshSourceError> {
        primitive_map(self.0, mesh_record)
    }

    fn mesh_shading(
        &self,
        mesh_record: u32,
    ) -> Result<
        (
            Option<std::borrow::Cow<'_, [[f32; 3]]>>,
            Option<std::borrow::Cow<'_, [[f32; 2]]>>,
        ),
        MeshSourceError,
    > {
        self.0
            .mesh_shading_slices(mesh_record)
            .map_err(MeshSourceError::from)
    }

    /// Starts reading the chunks of a build group's meshes: the kernel is told to read them
    /// ahead, then their first-touch checksums run on rayon threads (one chunk per thread,
    /// instead of whichever mesh touches it first checking it alone), and compressed chunks
    /// are decoded there once (before, each mesh read decoded its whole chunk, three times).
    fn prepare(&self, mesh_records: &[u32]) {
        use rayon::prelude::*;
        let chunks = self.0.mesh_chunks(mesh_records);
        for &c in &chunks {
            self.0.prefetch_chunk(c);
        }
        chunks.par_iter().for_each(|&c| self.0.verify_chunk(c));
        let ahead = self.0.chunks_to_decode_ahead(&chunks);
        ahead.par_iter().for_each(|&c| self.0.decode_chunk_ahead(c));
    }

    fn chunk_reads(&self) -> motu_gpu::ChunkReads {
        let (checks, checked_bytes) = self.0.chunk_checks();
        motu_gpu::ChunkReads {
            decodes: self.0.chunk_decodes(),
            checks,
            checked_bytes,
        }
    }

    /// The package's `proxy_boxes` section; one that cannot be read (its checksum fails) is a
    /// warning, and the streamer makes the boxes from the meshes.
    fn stored_proxy_boxes(&self) -> Option<&[u8]> {
        match self.0.stored_proxy_boxes() {
            Ok(bytes) => bytes,
            Err(e) => {
                tracing::warn!(
                    error = %e,
                    "the package's proxy-box table cannot be read; the boxes are made from the meshes"
                );
                None
            }
        }
    }

    fn stored_proxy_clusters(&self) -> Option<&[u8]> {
        stored_proxy_clusters(self.0)
    }
}

/// The package's `proxy_clusters` section (`motu_gpu::StreamPlan::load` reads it); one that
/// cannot be read (its checksum fails) is a warning, and the clusters are made again.
pub fn stored_proxy_clusters(pkg: &ScenePackage) -> Option<&[u8]> {
    match pkg.stored_proxy_clusters() {
        Ok(bytes) => bytes,
        Err(e) => {
            tracing::warn!(
                error = %e,
                "the package's proxy-cluster table cannot be read; the clusters are made again"
            );
            None
        }
    }
}
