//! LOD chains with meshoptimizer: each level aims at 4× fewer triangles than the one before
//! (half the linear resolution, matching the screen-size rule of `motu_abi::lod`). Borders are
//! locked so open edges, which is where one material's mesh meets another's, do not move; a
//! mesh has one material, so no attribute boundary runs through it. Each level is simplified
//! from the previous one and handed on at once: at most two levels are in memory.

use crate::CompileError;
use meshopt::{SimplifyOptions, VertexDataAdapter};
use motu_scene::{MeshData, MeshId};

/// Levels stop early when a step removes less than this fraction of triangles (the simplifier
/// hit its error bound or locked borders): a level that is not coarser is not worth a TLAS.
const MIN_REDUCTION: f64 = 0.1;

/// Calls `emit(lod, data)` for levels `1..levels` of `source`'s chain, finest first.
pub(crate) fn build_chain(
    mesh: MeshId,
    source: MeshData,
    levels: u32,
    emit: &mut dyn FnMut(u32, &MeshData) -> Result<(), CompileError>,
) -> Result<(), CompileError> {
    let _span =
        tracing::debug_span!("lod", mesh = mesh.0, triangles = source.triangle_count()).entered();
    source.validate().map_err(|reason| CompileError::Mesh {
        mesh: mesh.0,
        reason,
    })?;
    let source_tris = source.triangle_count() as u64;
    let mut prev = source;
    for lod in 1..levels {
        let target_tris = source_tris >> (2 * lod.min(31));
        if target_tris == 0 {
            break;
        }
        // Relative error allowed grows with the level: coarser levels are seen smaller.
        let target_error = (0.01 * f32::powi(2.0, lod as i32)).min(1.0);
        let next = simplify(mesh, &prev, target_tris as usize * 3, target_error)?;
        let (had, has) = (prev.triangle_count() as f64, next.triangle_count() as f64);
        if has == 0.0 || has > had * (1.0 - MIN_REDUCTION) {
            break;
        }
        emit(lod, &next)?;
        prev = next;
    }
    Ok(())
}

fn simplify(
    mesh: MeshId,
    data: &MeshData,
    target_index_count: usize,
    target_error: f32,
) -> Result<MeshData, CompileError> {
    let bytes: &[u8] = bytemuck::cast_slice(&data.positions);
    let adapter =
        VertexDataAdapter::new(bytes, 12, 0).map_err(|source| CompileError::Simplifier {
            mesh: mesh.0,
            source,
        })?;
    let indices = meshopt::simplify(
        &data.indices,
        &adapter,
        target_index_count,
        target_error,
        SimplifyOptions::LockBorder,
        None,
    );
    Ok(compact(data, indices))
}

/// Keeps only the vertices `indices` use (and their attributes), renumbered in first-use order.
fn compact(data: &MeshData, indices: Vec<u32>) -> MeshData {
    let mut remap = vec![u32::MAX; data.positions.len()];
    let mut order: Vec<u32> = Vec::new();
    let mut out_indices = indices;
    for i in out_indices.iter_mut() {
        let slot = &mut remap[*i as usize];
        if *slot == u32::MAX {
            *slot = order.len() as u32;
            order.push(*i);
        }
        *i = *slot;
    }
    let pick = |v: &Vec<[f32; 3]>| order.iter().map(|&o| v[o as usize]).collect::<Vec<_>>();
    MeshData {
        positions: pick(&data.positions),
        normals: data.normals.as_ref().map(pick),
        uvs: data
            .uvs
            .as_ref()
            .map(|uv| order.iter().map(|&o| uv[o as usize]).collect()),
        indices: out_indices,
    }
}

#[cfg(test)]
mod tests;
