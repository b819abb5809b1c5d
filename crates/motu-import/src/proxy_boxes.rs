//! The boxes inside every triangle BLAS (`motu_compile::proxy_boxes`), made once at import and
//! stored in the package's `proxy_boxes` section (FORMAT.md), so a streamed render's cold start
//! does not read every mesh for them (about 6 s of island 0.63's on the H200 host).
//!
//! Each chunk is read back whole once (a batch of chunks at a time, on all cores), its meshes'
//! triangles boxed ([`push_triangle_boxes`]), and each BLAS's boxes made as soon as every
//! chunk it reads was seen; a mesh's triangle boxes are dropped when its last BLAS is done, so
//! memory stays about a batch of chunks.

use std::collections::HashMap;

use motu_abi::HierarchyView;
use motu_compile::proxy_boxes::{
    blas_boxes, blas_hash, boxes_from_triangles, encode_section, fan, has_boxes,
    push_triangle_boxes, MeshSlices, StoredProxyBoxes, TriangleBox,
};
use motu_package::{ChunkId, PackageWriter};
use rayon::prelude::*;

use crate::ImportError;

/// Makes the table for `view` from the meshes `writer` holds and adds it as the package's
/// `proxy_boxes` section.
pub(crate) fn write_proxy_boxes(
    writer: &mut PackageWriter,
    view: &HierarchyView<'_>,
) -> Result<(), ImportError> {
    // Chunks read at once: one per core, at most 16 (64 MiB each by default, and about as much
    // again of triangle boxes while their BLASes wait).
    let batch = rayon::current_num_threads().clamp(2, 16);
    crate::split::add_timed_section(
        writer,
        motu_pack::SECTION_PROXY_BOXES,
        "proxy_boxes",
        |writer| {
            let table = make_table(view, batch, |c| writer.read_back_chunk(c))?;
            let counts = format!("blases={} boxes={}", table.entries.len(), table.boxes.len());
            Ok((encode_section(&table), counts))
        },
    )
}

/// The table of every BLAS with boxes ([`has_boxes`]), reading each chunk its meshes lie in
/// once through `read_chunk` (whole raw bytes), `batch` chunks at a time.
pub(crate) fn make_table<E: Send>(
    view: &HierarchyView<'_>,
    batch: usize,
    read_chunk: impl Fn(ChunkId) -> Result<Vec<u8>, E> + Sync,
) -> Result<StoredProxyBoxes, E> {
    let meshes_of = |b: usize| {
        let r = &view.blases[b];
        view.geometries[r.item_base as usize..][..r.item_count as usize]
            .iter()
            .map(|g| g.mesh)
    };
    let chunk_of = |m: u32| view.meshes.get(m as usize).map_or(u32::MAX, |r| r.chunk);
    let blases: Vec<usize> = (0..view.blases.len())
        .filter(|&b| has_boxes(&view.blases[b]))
        .collect();
    // Per mesh, the BLASes still to make that read it; per chunk, its meshes.
    let mut users: HashMap<u32, u32> = HashMap::new();
    let mut by_chunk: HashMap<u32, Vec<u32>> = HashMap::new();
    for &b in &blases {
        let mut mine: Vec<u32> = meshes_of(b).collect();
        mine.sort_unstable();
        mine.dedup();
        for m in mine {
            let n = users.entry(m).or_insert(0);
            if *n == 0 {
                by_chunk.entry(chunk_of(m)).or_default().push(m);
            }
            *n += 1;
        }
    }
    let mut chunks: Vec<u32> = by_chunk.keys().copied().collect();
    chunks.sort_unstable();
    // BLASes in the order their last chunk is read.
    let last_chunk = |b: usize| meshes_of(b).map(chunk_of).max().unwrap_or(0);
    let mut pending: Vec<(u32, usize)> = blases.iter().map(|&b| (last_chunk(b), b)).collect();
    pending.sort_unstable();
    let mut pending = pending.into_iter().peekable();
    // Triangle boxes per mesh read so far (`None`: its record does not fit its chunk).
    let mut tris: HashMap<u32, Option<Vec<TriangleBox>>> = HashMap::new();
    let mut made: Vec<(usize, Vec<[f32; 6]>)> = Vec::with_capacity(blases.len());
    for group in chunks.chunks(batch.max(1)) {
        let read: Vec<Vec<(u32, Option<Vec<TriangleBox>>)>> = group
            .par_iter()
            .map(|&c| {
                // A mesh record naming no chunk (u32::MAX) reads as unreadable.
                let raw = if c == u32::MAX {
                    Vec::new()
                } else {
                    read_chunk(ChunkId(c))?
                };
                Ok(by_chunk[&c]
                    .par_iter()
                    .map(|&m| (m, mesh_triangles(view, m, &raw)))
                    .collect())
            })
            .collect::<Result<_, E>>()?;
        tris.extend(read.into_iter().flatten());
        let seen = *group.last().expect("a batch is never empty");
        let mut ready = Vec::new();
        while let Some((_, b)) = pending.next_if(|&(last, _)| last <= seen) {
            ready.push(b);
        }
        let boxes: Vec<(usize, Vec<[f32; 6]>)> = ready
            .par_iter()
            .map(|&b| {
                let f = fan(view.blases[b].primitive_count) as usize;
                let mut parts: Vec<&[TriangleBox]> = Vec::new();
                for m in meshes_of(b) {
                    match tris.get(&m) {
                        Some(Some(t)) => parts.push(t),
                        // As the streamer does for a mesh it cannot read.
                        _ => return (b, blas_boxes(view, b, f, |_| Err::<MeshSlices<'_>, _>(()))),
                    }
                }
                // One mesh's triangles are split where they lie; several are joined first.
                let boxes = match parts[..] {
                    [one] => boxes_from_triangles(one, f),
                    _ => boxes_from_triangles(&parts.concat(), f),
                };
                (b, boxes)
            })
            .collect();
        for &b in &ready {
            let mut mine: Vec<u32> = meshes_of(b).collect();
            mine.sort_unstable();
            mine.dedup();
            for m in mine {
                let n = users.get_mut(&m).expect("counted");
                *n -= 1;
                if *n == 0 {
                    tris.remove(&m);
                }
            }
        }
        made.extend(boxes);
    }
    made.sort_unstable_by_key(|m| m.0);
    let mut table = StoredProxyBoxes::default();
    for (b, boxes) in made {
        let f = fan(view.blases[b].primitive_count);
        table.push(b as u32, f, blas_hash(view, b), &boxes);
    }
    Ok(table)
}

/// Mesh `m`'s triangle boxes from its chunk's raw bytes; `None` when its arrays do not lie in
/// them. The arrays are read in place where they are aligned (they are: the writer aligns
/// them to 16 bytes), else copied out.
fn mesh_triangles(view: &HierarchyView<'_>, m: u32, raw: &[u8]) -> Option<Vec<TriangleBox>> {
    let r = view.meshes.get(m as usize)?;
    let bytes = |offset: u64, count: u64| -> Option<&[u8]> {
        let start = usize::try_from(offset).ok()?;
        let end = start.checked_add(usize::try_from(count.checked_mul(4)?).ok()?)?;
        raw.get(start..end)
    };
    let positions = bytes(r.positions_offset, 3 * u64::from(r.vertex_count))?;
    let indices = bytes(r.indices_offset, 3 * u64::from(r.triangle_count))?;
    let mut out = Vec::with_capacity(r.triangle_count as usize);
    let in_place = (
        bytemuck::try_cast_slice::<u8, [f32; 3]>(positions),
        bytemuck::try_cast_slice::<u8, u32>(indices),
    );
    match in_place {
        (Ok(p), Ok(i)) if cfg!(target_endian = "little") => push_triangle_boxes(p, i, &mut out),
        _ => {
            let words = |b: &[u8]| -> Vec<u32> {
                b.chunks_exact(4)
                    .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
                    .collect()
            };
            let p: Vec<[f32; 3]> = words(positions)
                .chunks_exact(3)
                .map(|p| std::array::from_fn(|a| f32::from_bits(p[a])))
                .collect();
            push_triangle_boxes(&p, &words(indices), &mut out);
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests;
