//! The boxes inside every triangle BLAS (`motu_compile::proxy_boxes`), made once at import and
//! stored in the package's `proxy_boxes` section (FORMAT.md), so a streamed render's cold start
//! does not read every mesh for them (about 6 s of island 0.63's on the H200 host).
//!
//! A BLAS of one cluster cut while parsing takes the boxes made from the cluster in memory
//! then (`precut.rs`, [`ClusterBoxes`]: the same maths on the same data, so the same bits);
//! the island 0.0127 set read its 285 MB of chunks back for them. For the other BLASes,
//! each chunk is read back whole once (a batch of chunks at a time, on all cores), and each
//! BLAS's boxes made from its meshes in place (`boxes_from_meshes`) as soon as every chunk it
//! reads was seen; a chunk's bytes are dropped when its last BLAS is done, so memory stays
//! about a batch of chunks.

use std::borrow::Cow;
use std::collections::HashMap;

use motu_abi::HierarchyView;
use motu_compile::proxy_boxes::{
    blas_boxes, blas_hash, box_count, encode_section, fan, has_boxes, MeshSlices, StoredProxyBoxes,
};
use motu_package::{ChunkId, PackageWriter};
use rayon::prelude::*;

use crate::precut::ClusterBoxes;
use crate::ImportError;

/// Chunk bytes read back at once by default ([`crate::ImportOptions::proxy_readback_bytes`]):
/// four 64 MiB chunks. Before this bound the batch was one chunk per pool thread, so a
/// 16-thread host held 1 GiB of chunk bytes (and about as much again of triangle boxes while
/// their BLASes waited) whenever many BLASes needed read-back.
pub const DEFAULT_PROXY_READBACK_BYTES: u64 = 256 << 20;

/// Chunks read back at once: one per pool thread (2 to 16), at most `readback_bytes` of
/// `chunk_bytes` chunks, never fewer than two (one chunk alone would leave a BLAS whose meshes
/// span two chunks waiting, and the pool with one read at a time).
pub(crate) fn readback_batch(threads: usize, readback_bytes: u64, chunk_bytes: u64) -> usize {
    let by_bytes = readback_bytes / chunk_bytes.max(1);
    threads
        .clamp(2, 16)
        .min(usize::try_from(by_bytes).unwrap_or(usize::MAX))
        .max(2)
}

/// Makes the table for `view` from the meshes `writer` holds (and the boxes of clusters made
/// as they were cut, by mesh record) and adds it as the package's `proxy_boxes` section,
/// reading back at most [`readback_batch`] chunks (of the writer's target size `chunk_bytes`)
/// at once.
pub(crate) fn write_proxy_boxes(
    writer: &mut PackageWriter,
    view: &HierarchyView<'_>,
    cut_boxes: &HashMap<u32, ClusterBoxes>,
    readback_bytes: u64,
    chunk_bytes: u64,
) -> Result<(), ImportError> {
    let batch = readback_batch(rayon::current_num_threads(), readback_bytes, chunk_bytes);
    crate::split::add_timed_section(
        writer,
        motu_pack::SECTION_PROXY_BOXES,
        "proxy_boxes",
        |writer| {
            let table = make_table(view, batch, cut_boxes, |c, buf| {
                writer.read_back_chunk_into(c, buf)
            })?;
            let counts = format!("blases={} boxes={}", table.entries.len(), table.boxes.len());
            Ok((encode_section(&table), counts))
        },
    )
}

/// The table of every BLAS with boxes ([`has_boxes`]): a BLAS of one mesh record that
/// `cut_boxes` has (made for that record's chunk and counts) takes those; the others read
/// each chunk their meshes lie in once through `read_chunk` (whole raw bytes, into the buffer
/// it is given, replacing what it held), `batch` chunks at a time. A chunk's bytes are kept
/// until the last BLAS that reads them is made (the meshes are read in place), then its buffer
/// takes a later chunk.
pub(crate) fn make_table<E: Send>(
    view: &HierarchyView<'_>,
    batch: usize,
    cut_boxes: &HashMap<u32, ClusterBoxes>,
    read_chunk: impl Fn(ChunkId, &mut Vec<u8>) -> Result<(), E> + Sync,
) -> Result<StoredProxyBoxes, E> {
    let meshes_of = |b: usize| {
        let r = &view.blases[b];
        view.geometries[r.item_base as usize..][..r.item_count as usize]
            .iter()
            .map(|g| g.mesh)
    };
    let chunk_of = |m: u32| view.meshes.get(m as usize).map_or(u32::MAX, |r| r.chunk);
    let chunks_of = |b: usize| {
        let mut mine: Vec<u32> = meshes_of(b).map(chunk_of).collect();
        mine.sort_unstable();
        mine.dedup();
        mine
    };
    let mut made: Vec<(usize, Vec<[f32; 6]>)> = Vec::new();
    let blases: Vec<usize> = (0..view.blases.len())
        .filter(|&b| has_boxes(&view.blases[b]))
        .filter(|&b| match known_boxes(view, b, cut_boxes) {
            Some(boxes) => {
                made.push((b, boxes.to_vec()));
                false
            }
            None => true,
        })
        .collect();
    // Per chunk, the BLASes still to make that read it.
    let mut users: HashMap<u32, u32> = HashMap::new();
    for &b in &blases {
        for c in chunks_of(b) {
            *users.entry(c).or_insert(0) += 1;
        }
    }
    let mut chunks: Vec<u32> = users.keys().copied().collect();
    chunks.sort_unstable();
    // BLASes in the order their last chunk is read.
    let last_chunk = |b: usize| meshes_of(b).map(chunk_of).max().unwrap_or(0);
    let mut pending: Vec<(u32, usize)> = blases.iter().map(|&b| (last_chunk(b), b)).collect();
    pending.sort_unstable();
    let mut pending = pending.into_iter().peekable();
    // Raw bytes of the chunks read so far whose BLASes are not all made.
    let mut raw: HashMap<u32, Vec<u8>> = HashMap::new();
    // Buffers of chunks no BLAS reads any more.
    let mut free: Vec<Vec<u8>> = Vec::new();
    made.reserve(blases.len());
    for group in chunks.chunks(batch.max(1)) {
        let buffers: Vec<Vec<u8>> = group
            .iter()
            .map(|_| free.pop().unwrap_or_default())
            .collect();
        let read: Vec<(u32, Vec<u8>)> = group
            .par_iter()
            .zip(buffers)
            .map(|(&c, mut bytes)| {
                // A mesh record naming no chunk (u32::MAX) reads as unreadable. A read
                // replaces the buffer's bytes: not cleared first, so the reader zeroes only
                // room the buffer never had.
                if c == u32::MAX {
                    bytes.clear();
                } else {
                    read_chunk(ChunkId(c), &mut bytes)?;
                }
                Ok((c, bytes))
            })
            .collect::<Result<_, E>>()?;
        raw.extend(read);
        let seen = *group.last().expect("a batch is never empty");
        let mut ready = Vec::new();
        while let Some((_, b)) = pending.next_if(|&(last, _)| last <= seen) {
            ready.push(b);
        }
        let raw_ref = &raw;
        let boxes: Vec<(usize, Vec<[f32; 6]>)> = ready
            .par_iter()
            .map(|&b| {
                let f = fan(view.blases[b].primitive_count) as usize;
                // A mesh that does not lie in its chunk's bytes reads as the streamer's
                // unreadable mesh does.
                let boxes = blas_boxes(view, b, f, |m| {
                    raw_ref
                        .get(&chunk_of(m))
                        .and_then(|bytes| mesh_slices(view, m, bytes))
                        .ok_or(())
                });
                (b, boxes)
            })
            .collect();
        for &b in &ready {
            for c in chunks_of(b) {
                let n = users.get_mut(&c).expect("counted");
                *n -= 1;
                if *n == 0 {
                    free.extend(raw.remove(&c));
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

/// BLAS `b`'s boxes from `cut_boxes`: when it is one mesh record's, made for that record's
/// chunk and counts, and as many as its fan gives.
fn known_boxes<'a>(
    view: &HierarchyView<'_>,
    b: usize,
    cut_boxes: &'a HashMap<u32, ClusterBoxes>,
) -> Option<&'a [[f32; 6]]> {
    let r = &view.blases[b];
    if r.item_count != 1 {
        return None;
    }
    let m = view.geometries.get(r.item_base as usize)?.mesh;
    let rec = view.meshes.get(m as usize)?;
    let k = cut_boxes.get(&m)?;
    let same = (k.chunk, k.vertex_count, k.triangle_count)
        == (rec.chunk, rec.vertex_count, rec.triangle_count)
        && rec.triangle_count == r.primitive_count
        && k.boxes.len() == box_count(fan(r.primitive_count));
    same.then_some(&k.boxes[..])
}

/// Mesh `m`'s positions and indices in its chunk's raw bytes; `None` when its arrays do not
/// lie in them. Read in place where they are aligned (they are: the writer aligns them to 16
/// bytes), else copied out.
fn mesh_slices<'a>(view: &HierarchyView<'_>, m: u32, raw: &'a [u8]) -> Option<MeshSlices<'a>> {
    let r = view.meshes.get(m as usize)?;
    let bytes = |offset: u64, count: u64| -> Option<&'a [u8]> {
        let start = usize::try_from(offset).ok()?;
        let end = start.checked_add(usize::try_from(count.checked_mul(4)?).ok()?)?;
        raw.get(start..end)
    };
    let positions = bytes(r.positions_offset, 3 * u64::from(r.vertex_count))?;
    let indices = bytes(r.indices_offset, 3 * u64::from(r.triangle_count))?;
    let in_place = (
        bytemuck::try_cast_slice::<u8, [f32; 3]>(positions),
        bytemuck::try_cast_slice::<u8, u32>(indices),
    );
    match in_place {
        (Ok(p), Ok(i)) if cfg!(target_endian = "little") => {
            Some((Cow::Borrowed(p), Cow::Borrowed(i)))
        }
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
            Some((Cow::Owned(p), Cow::Owned(words(indices))))
        }
    }
}

#[cfg(test)]
mod tests;
