//! The package's texel store: every scene texture read (several at a time) and written to the
//! `texels` section as soon as it is decoded. Image files become capped mip chains; Ptex files
//! their faces, each resampled to at most `--ptex-max` texels an edge, with the triangle → face
//! tables of the meshes that sample them (`motu_abi::ptex`).

use std::collections::HashMap;

use motu_abi::ptex::MeshFaces;
use motu_package::PackageWriter;
use motu_scene::{PtexFaces, Scene};

use crate::ImportError;

/// `--ptex-max`'s default: 16 texels a face edge, at most 1 KiB a face; on a generated
/// Moana-like file the store was ~5% of level 0's texels (docs/shading.md "Ptex textures" has
/// the measurement).
pub const DEFAULT_PTEX_MAX: u32 = 16;

/// The import's caps: image textures' largest side, Ptex faces' largest edge.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Caps {
    pub image_max: u32,
    pub ptex_max: u32,
}

/// What a texture file gave.
enum Read {
    Chain(motu_texture::MipChain),
    Faces(Vec<motu_abi::ptex::PtexFace>),
}

/// What one texture becomes in the texel store.
enum Texels {
    Chain(motu_texture::MipChain),
    /// A Ptex texture's words and face count.
    Ptex(Vec<u32>, usize),
}

fn le_bytes(words: &[u32]) -> Vec<u8> {
    words.iter().flat_map(|t| t.to_le_bytes()).collect()
}

/// The triangle → face tables per Ptex texture: the meshes whose material samples it.
fn ptex_meshes(scene: &Scene) -> HashMap<u32, Vec<(u32, MeshFaces)>> {
    let mut out: HashMap<u32, Vec<(u32, MeshFaces)>> = HashMap::new();
    for (mesh, faces) in scene.ptex_faces() {
        let material = &scene.materials()[scene.mesh(*mesh).material.0 as usize];
        let Some(t) = material.base_color_texture else {
            continue;
        };
        let f = match faces {
            PtexFaces::Quads => MeshFaces::Quads,
            PtexFaces::Table(t) => MeshFaces::Table(t.clone()),
        };
        out.entry(t).or_default().push((mesh.0, f));
    }
    out
}

/// Reads every scene texture, in scene order so materials' texture indices hold, and writes
/// its texels to the package's texels section as soon as it is decoded: at most one batch of
/// textures is in memory, whatever the scene's total texture size. An image that cannot be
/// read becomes a neutral 1×1 texture (white, opaque: the material's constant colour shows), a
/// Ptex file one without faces (the material's colour replaces it), each with a warning naming
/// the file. Returns the texture records.
pub(crate) fn write_textures(
    writer: &mut PackageWriter,
    scene: &Scene,
    caps: Caps,
    warnings: &mut Vec<String>,
) -> Result<Vec<motu_abi::TextureRecord>, ImportError> {
    use rayon::prelude::*;
    let list = scene.textures();
    let mut tables = ptex_meshes(scene);
    let mut records = Vec::with_capacity(list.len());
    let mut texels = motu_pack::begin_texels(writer)?;
    // Texels written so far (the next texture's offset).
    let mut texel_count = 0u64;
    // A bounded batch keeps at most this many decoded textures in memory at once.
    const BATCH: usize = 8;
    for (b, batch) in list.chunks(BATCH).enumerate() {
        let read: Vec<_> = batch
            .par_iter()
            .map(|t| {
                if t.ptex {
                    motu_texture::ptex::load(&t.path, caps.ptex_max).map(Read::Faces)
                } else {
                    motu_texture::load(&t.path, caps.image_max, t.is_alpha).map(Read::Chain)
                }
            })
            .collect();
        for (i, (t, got)) in batch.iter().zip(read).enumerate() {
            let index = (b * BATCH + i) as u32;
            let got = match got {
                Ok(Read::Faces(faces)) => {
                    let meshes = tables.remove(&index).unwrap_or_default();
                    Texels::Ptex(motu_abi::ptex::encode(&faces, &meshes), faces.len())
                }
                Ok(Read::Chain(c)) => Texels::Chain(c),
                Err(e) => {
                    let msg = if t.ptex {
                        format!(
                            "Ptex texture not read ({e}); the material's constant colour is used"
                        )
                    } else {
                        format!("texture not read ({e}); the material's constant colour is used")
                    };
                    tracing::warn!("{msg}");
                    warnings.push(msg);
                    if t.ptex {
                        Texels::Ptex(motu_abi::ptex::encode(&[], &[]), 0)
                    } else {
                        Texels::Chain(motu_texture::MipChain {
                            width: 1,
                            height: 1,
                            levels: vec![vec![u32::MAX]],
                        })
                    }
                }
            };
            let count = match &got {
                Texels::Chain(c) => c.texel_count() as u64,
                Texels::Ptex(w, _) => w.len() as u64,
            };
            let texel_offset = u32::try_from(texel_count)
                .ok()
                .filter(|&o| u64::from(o) + count <= u64::from(u32::MAX))
                .ok_or_else(|| ImportError::TooManyTexels {
                    path: t.path.clone(),
                })?;
            match got {
                Texels::Chain(chain) => {
                    records.push(motu_abi::TextureRecord {
                        texel_offset,
                        width: chain.width,
                        height: chain.height,
                        mip_count: chain.levels.len() as u32,
                    });
                    for level in chain.levels {
                        texels.write(&le_bytes(&level))?;
                    }
                }
                Texels::Ptex(words, faces) => {
                    records.push(motu_abi::ptex::record(texel_offset, words.len(), faces));
                    texels.write(&le_bytes(&words))?;
                }
            }
            texel_count += count;
        }
    }
    texels.finish()?;
    Ok(records)
}
