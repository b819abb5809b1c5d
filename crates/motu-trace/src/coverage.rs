//! Alpha coverage of a triangle hit (opacity × alpha texture): what traversal asks before it
//! accepts a non-opaque hit, so it sits below both traversal and shading.

use motu_abi::shade::sample_texture;
use motu_abi::{FLAG_HAS_UVS, NONE_U32};

/// Coverage of triangle slot `slot` of `mesh` (record `rec`) at barycentrics `b` (weights of
/// its vertices 0, 1, 2): the material's constant opacity times its alpha texture at level 0
/// (`texture.glsl`'s `alpha_passes`).
pub fn coverage(
    view: &motu_abi::HierarchyView<'_>,
    mesh: &crate::mesh::MeshBvh,
    rec: &motu_abi::MeshRecord,
    slot: u32,
    b: [f32; 3],
) -> f32 {
    let Some(mat) = view.materials.get(rec.material as usize) else {
        return 1.0;
    };
    let mut a = mat.opacity;
    let tex = (mat.alpha_texture != NONE_U32)
        .then(|| view.textures.get(mat.alpha_texture as usize))
        .flatten();
    let uvs = mesh
        .attributes
        .as_deref()
        .filter(|_| rec.flags & FLAG_HAS_UVS != 0)
        .and_then(|at| at.uvs.as_ref().map(|u| (&at.indices, u)));
    if let (Some(tex), Some((indices, uvs))) = (tex, uvs) {
        let prim = mesh.tri_local[slot as usize] as usize;
        if let Some(tri) = indices.get(3 * prim..3 * prim + 3) {
            let t = [
                uvs[tri[0] as usize],
                uvs[tri[1] as usize],
                uvs[tri[2] as usize],
            ];
            let uv = std::array::from_fn(|k| b[0] * t[0][k] + b[1] * t[1][k] + b[2] * t[2][k]);
            a *= sample_texture(tex, view.texels, uv, 0)[3];
        }
    }
    a
}
