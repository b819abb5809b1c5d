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
    pub has_uvs: bool,
    pub positions: u64,
    pub indices: u64,
    /// Equal to `uvs` when there are no normals.
    pub normals: u64,
    /// `[f32; 2]` per vertex after the normals; equal to `len` when there are none.
    pub uvs: u64,
    pub len: u64,
}

impl MeshBlobLayout {
    pub fn new(vertex_count: u64, triangle_count: u64, has_normals: bool) -> Self {
        let positions = 0;
        let indices = align16(vertex_count * 12);
        let normals = align16(indices + triangle_count * 12);
        let uvs = if has_normals {
            align16(normals + vertex_count * 12)
        } else {
            normals
        };
        Self {
            vertex_count,
            triangle_count,
            has_normals,
            has_uvs: false,
            positions,
            indices,
            normals,
            uvs,
            len: if has_normals {
                normals + vertex_count * 12
            } else {
                normals
            },
        }
    }

    /// The same layout with texture coordinates after the normals (or not).
    pub fn with_uvs(mut self, has_uvs: bool) -> Self {
        self.has_uvs = has_uvs;
        if has_uvs {
            self.len = self.uvs + self.vertex_count * 8;
        }
        self
    }

    pub fn of(mesh: &MeshData) -> Self {
        Self::new(
            mesh.positions.len() as u64,
            mesh.triangle_count() as u64,
            mesh.normals.is_some(),
        )
        .with_uvs(
            mesh.uvs
                .as_ref()
                .is_some_and(|u| u.len() == mesh.positions.len()),
        )
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
        if let (true, Some(uv)) = (self.has_uvs, &mesh.uvs) {
            put(&mut out, self.uvs, bytemuck::cast_slice(uv));
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
        let with_uvs = MeshData {
            uvs: Some(vec![[0.0, 1.0], [0.5, 0.5], [1.0, 0.0]]),
            ..m
        };
        let l = MeshBlobLayout::of(&with_uvs);
        assert_eq!((l.normals, l.uvs, l.len), (64, 112, 136));
        assert_eq!(l.decode(&l.encode(&with_uvs)).unwrap(), with_uvs);
    }
}
