//! The mesh blob: how one mesh's data sits in a chunk.

use motu_scene::MeshData;

/// Alignment of a blob and of each array inside it (16: GPU-friendly, `Pod`-castable).
pub const MESH_BLOB_ALIGN: u64 = 16;

fn align16(v: u64) -> u64 {
    v.div_ceil(MESH_BLOB_ALIGN) * MESH_BLOB_ALIGN
}

/// Byte offsets of the arrays inside a blob, derived from the counts alone.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MeshBlobLayout {
    pub vertex_count: u64,
    pub triangle_count: u64,
    pub has_normals: bool,
    pub has_primitive_map: bool,
    pub positions: u64,
    pub indices: u64,
    /// Equal to the end of the indices (16-aligned) when there are no normals.
    pub normals: u64,
    /// The primitive map (`u32` per triangle) of a cluster: at the next 16-byte boundary after
    /// the normals (or indices); equal to `len` when there is none.
    pub primitive_map: u64,
    pub len: u64,
}

impl MeshBlobLayout {
    pub fn new(vertex_count: u64, triangle_count: u64, has_normals: bool) -> Self {
        Self::with_map(vertex_count, triangle_count, has_normals, false)
    }

    /// The layout of a blob that may carry a primitive map (a partitioned mesh's cluster).
    pub fn with_map(
        vertex_count: u64,
        triangle_count: u64,
        has_normals: bool,
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
        let (primitive_map, len) = if has_primitive_map {
            let at = align16(normals_end);
            (at, at + triangle_count * 4)
        } else {
            (normals_end, normals_end)
        };
        Self {
            vertex_count,
            triangle_count,
            has_normals,
            has_primitive_map,
            positions,
            indices,
            normals,
            primitive_map,
            len,
        }
    }

    pub fn of(mesh: &MeshData) -> Self {
        Self::new(
            mesh.positions.len() as u64,
            mesh.triangle_count() as u64,
            mesh.normals.is_some(),
        )
    }

    /// The layout of `mesh` with `primitive_map` (one `u32` per triangle) after its arrays.
    pub fn of_mapped(mesh: &MeshData, primitive_map: Option<&[u32]>) -> Self {
        Self::with_map(
            mesh.positions.len() as u64,
            mesh.triangle_count() as u64,
            mesh.normals.is_some(),
            primitive_map.is_some(),
        )
    }

    /// Serialises `mesh` and its primitive map (must match this layout).
    pub fn encode_mapped(&self, mesh: &MeshData, primitive_map: Option<&[u32]>) -> Vec<u8> {
        let mut out = self.encode(mesh);
        if let Some(map) = primitive_map {
            let at = self.primitive_map as usize;
            out[at..at + map.len() * 4].copy_from_slice(bytemuck::cast_slice(map));
        }
        out
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
        let put = |out: &mut Vec<u8>, at: u64, bytes: &[u8]| {
            out[at as usize..at as usize + bytes.len()].copy_from_slice(bytes);
        };
        put(
            &mut out,
            self.positions,
            bytemuck::cast_slice(&mesh.positions),
        );
        put(&mut out, self.indices, bytemuck::cast_slice(&mesh.indices));
        if let Some(n) = &mesh.normals {
            put(&mut out, self.normals, bytemuck::cast_slice(n));
        }
        out
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
        Ok(MeshData {
            positions,
            normals,
            uvs: None,
            indices,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blob_round_trip() {
        let m = MeshData {
            positions: vec![[0.0, 1.0, 2.0], [3.0, 4.0, 5.0], [6.0, 7.0, 8.0]],
            normals: Some(vec![[0.0, 0.0, 1.0]; 3]),
            uvs: None,
            indices: vec![0, 1, 2],
        };
        let l = MeshBlobLayout::of(&m);
        assert_eq!((l.indices, l.normals, l.len), (48, 64, 100));
        assert_eq!(l.decode(&l.encode(&m)).unwrap(), m);
        assert!(l.decode(&[0u8; 10]).is_err());
        assert_eq!(l.decode_primitive_map(&l.encode(&m)).unwrap(), None);
    }

    #[test]
    fn mapped_blob_round_trip() {
        let m = MeshData {
            positions: vec![[0.0, 1.0, 2.0], [3.0, 4.0, 5.0], [6.0, 7.0, 8.0]],
            normals: None,
            uvs: None,
            indices: vec![0, 1, 2, 2, 1, 0],
        };
        let map = [7u32, 3];
        let l = MeshBlobLayout::of_mapped(&m, Some(&map));
        // positions 36 → 48, indices 24 → 80 (normals: none) → map at 80, 8 bytes.
        assert_eq!(
            (l.indices, l.normals, l.primitive_map, l.len),
            (48, 80, 80, 88)
        );
        let blob = l.encode_mapped(&m, Some(&map));
        assert_eq!(l.decode(&blob).unwrap(), m);
        assert_eq!(l.decode_primitive_map(&blob).unwrap(), Some(map.to_vec()));
        assert!(l.decode_primitive_map(&blob[..84]).is_err());
    }
}
