//! The mesh blob: how one mesh's data sits in a chunk.

use motu_scene::MeshData;

/// Alignment of a blob and of each array inside it (16: GPU-friendly, `Pod`-castable).
pub const MESH_BLOB_ALIGN: u64 = 16;

fn align16(v: u64) -> u64 {
    v.div_ceil(MESH_BLOB_ALIGN) * MESH_BLOB_ALIGN
}

/// Byte offsets of the arrays inside a blob, derived from the counts alone. Order: positions,
/// indices, normals, texture coordinates, primitive map; each present array starts 16-aligned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MeshBlobLayout {
    pub vertex_count: u64,
    pub triangle_count: u64,
    pub has_normals: bool,
    pub has_uvs: bool,
    pub has_primitive_map: bool,
    pub positions: u64,
    pub indices: u64,
    /// Equal to the end of the indices (16-aligned) when there are no normals.
    pub normals: u64,
    /// `[f32; 2]` per vertex after the normals; meaningful only with `has_uvs`.
    pub uvs: u64,
    /// The primitive map (`u32` per triangle) of a cluster: at the next 16-byte boundary after
    /// the arrays before it; equal to `len` when there is none.
    pub primitive_map: u64,
    pub len: u64,
}

impl MeshBlobLayout {
    pub fn new(vertex_count: u64, triangle_count: u64, has_normals: bool) -> Self {
        Self::full(vertex_count, triangle_count, has_normals, false, false)
    }

    /// The layout of a blob that may carry a primitive map (a partitioned mesh's cluster).
    pub fn with_map(
        vertex_count: u64,
        triangle_count: u64,
        has_normals: bool,
        has_primitive_map: bool,
    ) -> Self {
        Self::full(
            vertex_count,
            triangle_count,
            has_normals,
            false,
            has_primitive_map,
        )
    }

    /// The same layout with texture coordinates after the normals (or not).
    pub fn with_uvs(self, has_uvs: bool) -> Self {
        Self::full(
            self.vertex_count,
            self.triangle_count,
            self.has_normals,
            has_uvs,
            self.has_primitive_map,
        )
    }

    fn full(
        vertex_count: u64,
        triangle_count: u64,
        has_normals: bool,
        has_uvs: bool,
        has_primitive_map: bool,
    ) -> Self {
        let positions = 0;
        let indices = align16(vertex_count * 12);
        let normals = align16(indices + triangle_count * 12);
        let normals_end = if has_normals {
            normals + vertex_count * 12
        } else {
            normals
        };
        let uvs = align16(normals_end);
        let uvs_end = if has_uvs {
            uvs + vertex_count * 8
        } else {
            normals_end
        };
        let (primitive_map, len) = if has_primitive_map {
            let at = align16(uvs_end);
            (at, at + triangle_count * 4)
        } else {
            (uvs_end, uvs_end)
        };
        Self {
            vertex_count,
            triangle_count,
            has_normals,
            has_uvs,
            has_primitive_map,
            positions,
            indices,
            normals,
            uvs,
            primitive_map,
            len,
        }
    }

    fn mesh_has_uvs(mesh: &MeshData) -> bool {
        mesh.uvs
            .as_ref()
            .is_some_and(|u| u.len() == mesh.positions.len())
    }

    pub fn of(mesh: &MeshData) -> Self {
        Self::of_mapped(mesh, None)
    }

    /// The layout of `mesh` with `primitive_map` (one `u32` per triangle) after its arrays.
    pub fn of_mapped(mesh: &MeshData, primitive_map: Option<&[u32]>) -> Self {
        Self::full(
            mesh.positions.len() as u64,
            mesh.triangle_count() as u64,
            mesh.normals.is_some(),
            Self::mesh_has_uvs(mesh),
            primitive_map.is_some(),
        )
    }

    /// Serialises `mesh` and its primitive map (must match this layout).
    pub fn encode_mapped(&self, mesh: &MeshData, primitive_map: Option<&[u32]>) -> Vec<u8> {
        let mut out = vec![0u8; self.len as usize];
        self.encode_mapped_into(mesh, primitive_map, &mut out);
        out
    }

    /// Pushes [`Self::encode_mapped`]'s `len` bytes onto `out`: the arrays in offset order
    /// with zeros between them, each byte written once (no zeroing pass before the copies).
    pub fn encode_mapped_onto(
        &self,
        mesh: &MeshData,
        primitive_map: Option<&[u32]>,
        out: &mut Vec<u8>,
    ) {
        let uvs = mesh.uvs.as_ref().filter(|_| self.has_uvs);
        let pieces: [Option<(u64, &[u8])>; 5] = [
            Some((self.positions, bytemuck::cast_slice(&mesh.positions))),
            Some((self.indices, bytemuck::cast_slice(&mesh.indices))),
            mesh.normals
                .as_ref()
                .map(|n| (self.normals, bytemuck::cast_slice(n))),
            uvs.map(|uv| (self.uvs, bytemuck::cast_slice(uv))),
            primitive_map.map(|m| (self.primitive_map, bytemuck::cast_slice(m))),
        ];
        let start = out.len();
        let mut end = 0u64;
        let in_order = pieces.iter().flatten().all(|&(at, bytes)| {
            let ok = at >= end && at + bytes.len() as u64 <= self.len;
            end = at + bytes.len() as u64;
            ok
        });
        if !in_order {
            // A layout that does not fit the mesh: the indexed writes (and their checks).
            out.resize(start + self.len as usize, 0);
            self.encode_mapped_into(mesh, primitive_map, &mut out[start..]);
            return;
        }
        for (at, bytes) in pieces.into_iter().flatten() {
            out.resize(start + at as usize, 0);
            out.extend_from_slice(bytes);
        }
        out.resize(start + self.len as usize, 0);
    }

    /// [`Self::encode_mapped`] into `out` (this layout's `len` bytes, zeroed: the gaps
    /// between the arrays are left as they are).
    pub fn encode_mapped_into(
        &self,
        mesh: &MeshData,
        primitive_map: Option<&[u32]>,
        out: &mut [u8],
    ) {
        self.encode_into(mesh, out);
        if let Some(map) = primitive_map {
            let at = self.primitive_map as usize;
            out[at..at + map.len() * 4].copy_from_slice(bytemuck::cast_slice(map));
        }
    }

    /// Reads a cluster's primitive map back from a blob (`None` when the layout has none).
    pub fn decode_primitive_map(&self, blob: &[u8]) -> Result<Option<Vec<u32>>, String> {
        if !self.has_primitive_map {
            return Ok(None);
        }
        let end = self.primitive_map + self.triangle_count * 4;
        let bytes = blob
            .get(self.primitive_map as usize..end as usize)
            .ok_or_else(|| {
                format!(
                    "blob is {} bytes, its primitive map ends at {end}",
                    blob.len()
                )
            })?;
        Ok(Some(bytemuck::pod_collect_to_vec(bytes)))
    }

    /// Serialises `mesh` (must match this layout).
    pub fn encode(&self, mesh: &MeshData) -> Vec<u8> {
        let mut out = vec![0u8; self.len as usize];
        self.encode_into(mesh, &mut out);
        out
    }

    /// [`Self::encode`] into `out` (this layout's `len` bytes, zeroed).
    pub fn encode_into(&self, mesh: &MeshData, out: &mut [u8]) {
        let put = |out: &mut [u8], at: u64, bytes: &[u8]| {
            out[at as usize..at as usize + bytes.len()].copy_from_slice(bytes);
        };
        put(out, self.positions, bytemuck::cast_slice(&mesh.positions));
        put(out, self.indices, bytemuck::cast_slice(&mesh.indices));
        if let Some(n) = &mesh.normals {
            put(out, self.normals, bytemuck::cast_slice(n));
        }
        if let (true, Some(uv)) = (self.has_uvs, &mesh.uvs) {
            put(out, self.uvs, bytemuck::cast_slice(uv));
        }
    }

    /// Reads a mesh back from a blob (copies; readers that want zero-copy slice the chunk).
    pub fn decode(&self, blob: &[u8]) -> Result<MeshData, String> {
        if (blob.len() as u64) < self.len {
            return Err(format!(
                "blob is {} bytes, layout needs {}",
                blob.len(),
                self.len
            ));
        }
        let slice = |at: u64, n: u64| &blob[at as usize..(at + n) as usize];
        let positions: Vec<[f32; 3]> =
            bytemuck::pod_collect_to_vec(slice(self.positions, self.vertex_count * 12));
        let indices: Vec<u32> =
            bytemuck::pod_collect_to_vec(slice(self.indices, self.triangle_count * 12));
        let normals = self
            .has_normals
            .then(|| bytemuck::pod_collect_to_vec(slice(self.normals, self.vertex_count * 12)));
        let uvs = self
            .has_uvs
            .then(|| bytemuck::pod_collect_to_vec(slice(self.uvs, self.vertex_count * 8)));
        Ok(MeshData {
            positions,
            normals,
            uvs,
            indices,
        })
    }
}

#[cfg(test)]
mod tests;
