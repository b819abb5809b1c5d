//! A package's meshes, straight from its chunks, for the CPU tracer and the GPU builds.

use motu_pack::ScenePackage;

/// Mesh data for the tracers, straight from the package's chunks.
pub struct PackageMeshes<'a>(pub &'a ScenePackage);

impl motu_trace::MeshSource for PackageMeshes<'_> {
    fn load(&self, mesh_record: u32) -> Result<motu_trace::MeshGeometry, String> {
        let g = self
            .0
            .mesh_geometry(mesh_record)
            .map_err(|e| e.to_string())?;
        Ok(motu_trace::MeshGeometry {
            positions: g.positions,
            indices: g.indices,
            normals: g.normals,
            primitive_map: g.primitive_map,
            uvs: g.uvs,
        })
    }
}

impl motu_gpu::MeshBlobSource for PackageMeshes<'_> {
    fn mesh_data(
        &self,
        mesh_record: u32,
    ) -> Result<
        (
            std::borrow::Cow<'_, [[f32; 3]]>,
            std::borrow::Cow<'_, [u32]>,
        ),
        String,
    > {
        self.0.mesh_slices(mesh_record).map_err(|e| e.to_string())
    }

    fn primitive_map(
        &self,
        mesh_record: u32,
    ) -> Result<Option<std::borrow::Cow<'_, [u32]>>, String> {
        self.0
            .primitive_map_slice(mesh_record)
            .map_err(|e| e.to_string())
    }
    fn mesh_shading(
        &self,
        mesh_record: u32,
    ) -> Result<
        (
            Option<std::borrow::Cow<'_, [[f32; 3]]>>,
            Option<std::borrow::Cow<'_, [[f32; 2]]>>,
        ),
        String,
    > {
        self.0
            .mesh_shading_slices(mesh_record)
            .map_err(|e| e.to_string())
    }
}
