//! Writing PLY (binary little-endian): tests, fuzz seeds and the pbrt writer.

use crate::events::Mesh;

/// Write a mesh as binary little-endian PLY (tests, fuzz seeds, the pbrt writer).
pub fn write_ply_binary_le(mesh: &Mesh) -> Vec<u8> {
    let mut out = Vec::new();
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\n",
        mesh.positions.len()
    );
    header.push_str("property float x\nproperty float y\nproperty float z\n");
    if mesh.normals.is_some() {
        header.push_str("property float nx\nproperty float ny\nproperty float nz\n");
    }
    if mesh.uvs.is_some() {
        header.push_str("property float u\nproperty float v\n");
    }
    header.push_str(&format!(
        "element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.indices.len() / 3
    ));
    out.extend_from_slice(header.as_bytes());
    for (i, p) in mesh.positions.iter().enumerate() {
        p.iter()
            .for_each(|c| out.extend_from_slice(&c.to_le_bytes()));
        if let Some(n) = mesh.normals.as_ref().and_then(|n| n.get(i)) {
            n.iter()
                .for_each(|c| out.extend_from_slice(&c.to_le_bytes()));
        }
        if let Some(uv) = mesh.uvs.as_ref().and_then(|u| u.get(i)) {
            uv.iter()
                .for_each(|c| out.extend_from_slice(&c.to_le_bytes()));
        }
    }
    for t in mesh.indices.chunks_exact(3) {
        out.push(3);
        t.iter()
            .for_each(|&i| out.extend_from_slice(&(i as i32).to_le_bytes()));
    }
    out
}
