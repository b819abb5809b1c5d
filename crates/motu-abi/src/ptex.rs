//! Ptex textures in the package's texel store, and how every backend samples them
//! (`shaders/texture.glsl` `sample_ptex` mirrors [`sample_ptex`] line by line).
//!
//! A Ptex texture is a [`TextureRecord`] with `mip_count == 0` ([`is_ptex`]): `width` is the
//! number of `u32` words it takes in the texel store from `texel_offset`, `height` its face
//! count. The words, offsets relative to `texel_offset`:
//!
//! ```text
//! [0]                      M: meshes with a face table
//! [1 + 2i], [2 + 2i]       mesh i (ascending source mesh id), its table: the offset of one
//!                          u32 per source triangle (face id | PTEX_SECOND_HALF), or
//!                          PTEX_QUADS (triangle t is face t / 2, odd t the quad's second half)
//! [1 + 2M + 2f], [+1]      face f: offset of its texels, ulog2 | vlog2 << 8
//! ...                      triangle tables and texels (RGBA8, colour sRGB-encoded, row 0 at
//!                          v = 0, 2^ulog2 texels a row)
//! ```
//!
//! A source mesh without an entry maps triangle `t` to face `t` (a Ptex triangle mesh's own
//! numbering). The face uv is the mesh's interpolated texture coordinates where it has them
//! (pbrt's rule), else the triangle's default parameterisation: (0,0), (1,0), (1,1) at its
//! vertices, or (0,0), (1,1), (0,1) for the second half of a split quad (v0 v2 v3 of v0..v3).

use crate::shade::{srgb_to_linear, TextureRecord};

/// Set in a triangle-table entry: the triangle is the second half (v0 v2 v3) of a quad.
pub const PTEX_SECOND_HALF: u32 = 1 << 31;
/// A mesh table entry meaning "triangle t is face t / 2, the odd ones second halves".
pub const PTEX_QUADS: u32 = u32::MAX;

/// Whether `tex` is a Ptex texture (its texels are the words above, not a mip chain).
pub fn is_ptex(tex: &TextureRecord) -> bool {
    tex.mip_count == 0
}

/// The face (and whether the triangle is a quad's second half) of source triangle `prim` of
/// `source_mesh`.
pub fn ptex_face(tex: &TextureRecord, words: &[u32], source_mesh: u32, prim: u32) -> (u32, bool) {
    let base = tex.texel_offset as usize;
    let w = |i: u32| words.get(base + i as usize).copied().unwrap_or(0);
    let m = w(0);
    // Binary search of the ascending mesh ids.
    let (mut lo, mut hi) = (0u32, m);
    while lo < hi {
        let mid = (lo + hi) / 2;
        let id = w(1 + 2 * mid);
        if id == source_mesh {
            let table = w(2 + 2 * mid);
            if table == PTEX_QUADS {
                return (prim / 2, prim % 2 == 1);
            }
            let e = w(table + prim);
            return (e & !PTEX_SECOND_HALF, e & PTEX_SECOND_HALF != 0);
        }
        if id < source_mesh {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    (prim, false)
}

/// The face uv at barycentrics `b` (weights of the triangle's vertices 0, 1, 2) without mesh
/// texture coordinates.
pub fn default_face_uv(b: [f32; 3], second_half: bool) -> [f32; 2] {
    if second_half {
        [b[1], b[1] + b[2]]
    } else {
        [b[1] + b[2], b[2]]
    }
}

/// Bilinear sample of face `face` at face uv `uv` (clamped to the face: Ptex faces do not
/// wrap), linear RGBA; `None` for a face the texture does not have (the material's colour
/// then shows).
pub fn sample_ptex(
    tex: &TextureRecord,
    words: &[u32],
    face: u32,
    uv: [f32; 2],
) -> Option<[f32; 4]> {
    if face >= tex.height {
        return None;
    }
    let base = tex.texel_offset as usize;
    let w = |i: u32| words.get(base + i as usize).copied().unwrap_or(0);
    let m = w(0);
    let entry = 1 + 2 * m + 2 * face;
    let at = w(entry);
    let res = w(entry + 1);
    let (fw, fh) = (
        1i64 << (res & 0xff).min(15),
        1i64 << ((res >> 8) & 0xff).min(15),
    );
    let uv = if uv.iter().all(|c| c.is_finite()) {
        uv
    } else {
        [0.0; 2]
    };
    let x = uv[0].clamp(0.0, 1.0) * fw as f32 - 0.5;
    let y = uv[1].clamp(0.0, 1.0) * fh as f32 - 0.5;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let fetch = |xi: i64, yi: i64| -> [f32; 4] {
        let (xc, yc) = (xi.clamp(0, fw - 1), yi.clamp(0, fh - 1));
        let t = w(at + (yc * fw + xc) as u32);
        let c = |s: u32| ((t >> s) & 0xff) as f32 / 255.0;
        [
            srgb_to_linear(c(0)),
            srgb_to_linear(c(8)),
            srgb_to_linear(c(16)),
            c(24),
        ]
    };
    let (xi, yi) = (x0 as i64, y0 as i64);
    let (a, b, c, d) = (
        fetch(xi, yi),
        fetch(xi + 1, yi),
        fetch(xi, yi + 1),
        fetch(xi + 1, yi + 1),
    );
    Some(std::array::from_fn(|i| {
        let top = a[i] + (b[i] - a[i]) * fx;
        let bottom = c[i] + (d[i] - c[i]) * fx;
        top + (bottom - top) * fy
    }))
}

/// One face's texels for [`encode`]: `2^ulog2 × 2^vlog2` RGBA8 texels, row 0 at v = 0.
#[derive(Clone, Debug, PartialEq)]
pub struct PtexFace {
    pub ulog2: u8,
    pub vlog2: u8,
    pub texels: Vec<u32>,
}

/// How a mesh's triangles map to faces, for [`encode`].
#[derive(Clone, Debug, PartialEq)]
pub enum MeshFaces {
    /// Triangle t is face t / 2 (every face a quad split in two).
    Quads,
    /// Per triangle: face id | [`PTEX_SECOND_HALF`].
    Table(Vec<u32>),
}

/// The texel-store words of a Ptex texture (module docs); `meshes` in any order, one entry
/// per source mesh.
pub fn encode(faces: &[PtexFace], meshes: &[(u32, MeshFaces)]) -> Vec<u32> {
    let mut meshes: Vec<&(u32, MeshFaces)> = meshes.iter().collect();
    meshes.sort_by_key(|(id, _)| *id);
    meshes.dedup_by_key(|(id, _)| *id);
    let m = meshes.len();
    let mut out = vec![0u32; 1 + 2 * m + 2 * faces.len()];
    out[0] = m as u32;
    for (i, (id, f)) in meshes.iter().enumerate() {
        out[1 + 2 * i] = *id;
        out[2 + 2 * i] = match f {
            MeshFaces::Quads => PTEX_QUADS,
            MeshFaces::Table(t) => {
                let at = out.len() as u32;
                out.extend_from_slice(t);
                at
            }
        };
    }
    for (f, face) in faces.iter().enumerate() {
        let at = 1 + 2 * m + 2 * f;
        out[at] = out.len() as u32;
        out[at + 1] = u32::from(face.ulog2) | u32::from(face.vlog2) << 8;
        out.extend_from_slice(&face.texels);
    }
    out
}

/// The record of words from [`encode`] placed at `texel_offset`.
pub fn record(texel_offset: u32, words: usize, faces: usize) -> TextureRecord {
    TextureRecord {
        texel_offset,
        width: words as u32,
        height: faces as u32,
        mip_count: 0,
    }
}

#[cfg(test)]
mod tests;
