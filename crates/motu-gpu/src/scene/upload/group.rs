//! A build group's meshes uploaded together: read and checked on rayon threads, then copied
//! from several threads at once, into their buffers where those are host-mapped (the
//! streamer's default on a discrete GPU) or through the staging ring's regions.
//!
//! One mesh at a time on one thread, a streamed first frame copied 2.6 GB/s on an H100 host
//! (`mesh_ms` 3.3 s for 8.6 GB at island 0.63, 8 GiB): page faults on the package's map, the
//! index check and the copies all ran in turn.

use std::borrow::Cow;
use std::time::Instant;

use motu_vk::{with_mapped_ranges_mut, BufferCopy, Context, HeapBuffer, MappedRange};
use rayon::prelude::*;

use super::{MeshGpu, Uploader};
use crate::error::{GpuError, Result};
use crate::scene::MeshBlobSource;

/// Most bytes one parallel copy task takes: a large mesh is cut so threads share it.
pub(crate) const PIECE_BYTES: usize = 1 << 20;

/// Indices from which the range check runs on several threads.
const PARALLEL_CHECK_INDICES: usize = 1 << 18;

/// One copy: `src` to `dst` at `dst_offset`.
#[derive(Clone, Copy)]
pub(crate) struct Piece<'a> {
    pub(crate) dst: &'a HeapBuffer,
    pub(crate) dst_offset: u64,
    pub(crate) src: &'a [u8],
}

/// `pieces` cut to at most `max_bytes` each, empty ones dropped, in order.
pub(crate) fn cut<'a>(pieces: &[Piece<'a>], max_bytes: usize) -> Vec<Piece<'a>> {
    let mut out = Vec::with_capacity(pieces.len());
    for p in pieces {
        for (k, src) in p.src.chunks(max_bytes.max(1)).enumerate() {
            out.push(Piece {
                dst: p.dst,
                dst_offset: p.dst_offset + (k * max_bytes.max(1)) as u64,
                src,
            });
        }
    }
    out
}

/// Copies every piece into its host-mapped destination, from rayon threads (the ranges are
/// checked disjoint by [`with_mapped_ranges_mut`]).
pub(crate) fn write_mapped_parallel(pieces: &[Piece<'_>]) -> Result<()> {
    if pieces.is_empty() {
        return Ok(());
    }
    let ranges: Vec<MappedRange<'_>> = pieces
        .iter()
        .map(|p| MappedRange {
            buffer: p.dst,
            offset: p.dst_offset,
            len: p.src.len(),
        })
        .collect();
    with_mapped_ranges_mut(&ranges, |slices| {
        slices
            .par_iter_mut()
            .zip(pieces.par_iter())
            .for_each(|(dst, p)| dst.copy_from_slice(p.src));
    })?;
    Ok(())
}

impl Uploader {
    /// Queues every piece like [`Uploader::upload`] (a piece may straddle regions), each
    /// region's share written from several threads; flushes whenever the region fills.
    pub(crate) fn upload_pieces(&mut self, ctx: &Context, pieces: &[Piece<'_>]) -> Result<()> {
        let (mut i, mut done) = (0usize, 0usize);
        let pieces: Vec<Piece<'_>> = pieces
            .iter()
            .copied()
            .filter(|p| !p.src.is_empty())
            .collect();
        while i < pieces.len() {
            let (_, end) = self.region();
            if self.cursor >= end {
                self.flush(ctx)?;
                continue;
            }
            // (ring offset, piece part) of this region fill.
            let mut batch: Vec<(u64, Piece<'_>)> = Vec::new();
            while i < pieces.len() && self.cursor < end {
                let p = pieces[i];
                let n = ((end - self.cursor) as usize).min(p.src.len() - done);
                batch.push((
                    self.cursor,
                    Piece {
                        dst: p.dst,
                        dst_offset: p.dst_offset + done as u64,
                        src: &p.src[done..done + n],
                    },
                ));
                self.cursor = (self.cursor + n as u64).div_ceil(16) * 16;
                done += n;
                if done == p.src.len() {
                    (i, done) = (i + 1, 0);
                }
            }
            let staged: Vec<Piece<'_>> = batch
                .iter()
                .map(|&(at, p)| Piece {
                    dst: &self.staging,
                    dst_offset: at,
                    src: p.src,
                })
                .collect();
            write_mapped_parallel(&staged)?;
            self.pending.extend(batch.iter().map(|&(at, p)| BufferCopy {
                dst: p.dst.target(),
                src_offset: at,
                dst_offset: p.dst_offset,
                size_bytes: p.src.len() as u64,
            }));
        }
        Ok(())
    }
}

/// A mesh's bytes as the source gives them, checked against its record.
pub(super) struct MeshBytes<'s> {
    pub(super) positions: Cow<'s, [[f32; 3]]>,
    pub(super) indices: Cow<'s, [u32]>,
    pub(super) map: Option<Cow<'s, [u32]>>,
    /// Shading attributes (streamed meshes with room for them): absent, or of the vertex count.
    pub(super) normals: Option<Cow<'s, [[f32; 3]]>>,
    pub(super) uvs: Option<Cow<'s, [[f32; 2]]>>,
}

impl MeshBytes<'_> {
    /// Bytes of what is copied.
    pub(super) fn len_bytes(&self) -> u64 {
        (self.positions.len() * 12
            + self.indices.len() * 4
            + self.map.as_ref().map_or(0, |m| m.len() * 4)
            + self.normals.as_ref().map_or(0, |n| n.len() * 12)
            + self.uvs.as_ref().map_or(0, |u| u.len() * 8)) as u64
    }
}

impl MeshGpu {
    /// Reads mesh record `m` from `source` and checks it against the record (counts, index
    /// range, primitive map); its shading attributes too where the buffer has room for them
    /// (one the source lacks, or gives at the wrong length, is left out).
    pub(super) fn read_bytes<'s>(
        &self,
        source: &'s dyn MeshBlobSource,
        m: usize,
    ) -> Result<MeshBytes<'s>> {
        let (positions, indices) = source
            .mesh_data(m as u32)
            .map_err(GpuError::mesh_source(m))?;
        if positions.len() != self.vertex_count as usize
            || indices.len() != 3 * self.triangle_count as usize
        {
            return Err(GpuError::InvalidRequest(format!(
                "mesh record {m}: {} positions and {} indices, the record says {} and {}",
                positions.len(),
                indices.len(),
                self.vertex_count,
                3 * self.triangle_count
            )));
        }
        let vc = self.vertex_count;
        let bad = if indices.len() >= PARALLEL_CHECK_INDICES {
            indices.par_iter().find_first(|&&i| i >= vc).copied()
        } else {
            indices.iter().find(|&&i| i >= vc).copied()
        };
        if let Some(bad) = bad {
            return Err(GpuError::InvalidRequest(format!(
                "mesh record {m}: index {bad} >= vertex count {vc}"
            )));
        }
        let map = source
            .primitive_map(m as u32)
            .map_err(GpuError::mesh_source(m))?;
        match (&map, self.has_primitive_map) {
            (Some(map), true) if map.len() == self.triangle_count as usize => {}
            (None, false) => {}
            (got, _) => {
                return Err(GpuError::InvalidRequest(format!(
                    "mesh record {m}: the record {} a primitive map of {} entries, the source \
                     gave {}",
                    if self.has_primitive_map {
                        "needs"
                    } else {
                        "has no"
                    },
                    self.triangle_count,
                    got.as_ref()
                        .map_or("none".to_string(), |g| g.len().to_string())
                )))
            }
        }
        let (mut normals, mut uvs) = (None, None);
        if self.normals_address != 0 || self.uvs_address != 0 {
            let (n, u) = source
                .mesh_shading(m as u32)
                .map_err(GpuError::mesh_source(m))?;
            let vc = vc as usize;
            normals = n.filter(|n| n.len() == vc && self.normals_address != 0);
            uvs = u.filter(|u| u.len() == vc && self.uvs_address != 0);
        }
        Ok(MeshBytes {
            positions,
            indices,
            map,
            normals,
            uvs,
        })
    }

    /// Forgets the attributes `bytes` lacks (shading then uses geometric normals and constant
    /// texture coordinates, as the full build's tables do).
    pub(super) fn keep_attributes_of(&mut self, bytes: &MeshBytes<'_>) {
        if bytes.normals.is_none() {
            self.normals_address = 0;
        }
        if bytes.uvs.is_none() {
            self.uvs_address = 0;
        }
    }

    /// The copies that put `bytes` in this mesh's buffer.
    pub(super) fn pieces<'a>(&'a self, bytes: &'a MeshBytes<'_>, out: &mut Vec<Piece<'a>>) {
        use bytemuck::cast_slice;
        let base = self.positions_address;
        let idx_off = self.indices_address - base;
        let mut put = |dst_offset: u64, src: &'a [u8]| {
            out.push(Piece {
                dst: &self.buffer,
                dst_offset,
                src,
            })
        };
        put(0, cast_slice(&bytes.positions[..]));
        put(idx_off, cast_slice(&bytes.indices[..]));
        if let Some(map) = &bytes.map {
            put(
                idx_off + u64::from(self.triangle_count) * 12,
                cast_slice(&map[..]),
            );
        }
        if let Some(n) = &bytes.normals {
            put(self.normals_address - base, cast_slice(&n[..]));
        }
        if let Some(u) = &bytes.uvs {
            put(self.uvs_address - base, cast_slice(&u[..]));
        }
    }
}

/// Where one build group's upload went ([`upload_streamed_group`]), for the frame's
/// `mesh_*` stats: nobody knew why an H100 host uploaded 60–80 MB a frame at ~1.3 GB/s.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct UploadSplit {
    /// [`MeshBlobSource::prepare`]: read-ahead advice and first-touch chunk checksums.
    pub(crate) prepare_ms: f64,
    /// The meshes read and checked on rayon threads: page faults on the package's map,
    /// decompression and the copies out of decompressed chunks, the index checks.
    pub(crate) read_ms: f64,
    /// Copies into host-mapped buffers (first touches of fresh memory fault here).
    pub(crate) copy_ms: f64,
    /// Copies through the staging ring (device-local buffers), flushes when it fills.
    pub(crate) staged_ms: f64,
    /// Bytes copied.
    pub(crate) bytes: u64,
    /// The process's page faults (minor and major) while reading and while copying.
    pub(crate) read_faults: u64,
    pub(crate) copy_faults: u64,
    /// Chunks the source decompressed, and first-touch chunk checksums with their bytes
    /// ([`MeshBlobSource::chunk_reads`]).
    pub(crate) chunk_decodes: u64,
    pub(crate) chunk_checks: u64,
    pub(crate) chunk_checked_bytes: u64,
}

/// The process's page faults so far (minor and major, every thread's, from
/// `/proc/self/stat`): 0 where unknown (not Linux).
pub(crate) fn page_faults() -> u64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0;
    };
    // Fields after the command's closing parenthesis: state is field 3, minflt 10, majflt 12.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let field = |n: usize| -> u64 {
        rest.split_whitespace()
            .nth(n - 3)
            .and_then(|v| v.parse().ok())
            .unwrap_or(0)
    };
    field(10) + field(12)
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Uploads the meshes `(record, mesh)` of one build group (buffers from
/// [`MeshGpu::alloc_streamed`], nothing queued into them yet): the source is told what comes
/// ([`MeshBlobSource::prepare`]), each mesh is read and checked on rayon threads, then every
/// mesh is copied from several threads; an attribute the source lacks is dropped. Returns the
/// bytes copied per mesh and where the time went. On an error, copies may be queued in `up`
/// for some of the buffers: flush before freeing them.
pub(crate) fn upload_streamed_group(
    ctx: &Context,
    up: &mut Uploader,
    source: &dyn MeshBlobSource,
    meshes: &mut [(usize, MeshGpu)],
) -> Result<(Vec<u64>, UploadSplit)> {
    let mut split = UploadSplit::default();
    if meshes.is_empty() {
        return Ok((Vec::new(), split));
    }
    let _span = tracing::debug_span!("upload_streamed_group", meshes = meshes.len()).entered();
    let records: Vec<u32> = meshes.iter().map(|&(m, _)| m as u32).collect();
    let (t, reads) = (Instant::now(), source.chunk_reads());
    tracing::debug_span!("mesh_prepare").in_scope(|| source.prepare(&records));
    split.prepare_ms = ms_since(t);
    let (t, faults) = (Instant::now(), page_faults());
    let loaded = tracing::debug_span!("mesh_read").in_scope(|| {
        meshes
            .par_iter()
            .map(|(m, g)| g.read_bytes(source, *m))
            .collect::<Result<Vec<_>>>()
    })?;
    split.read_ms = ms_since(t);
    split.read_faults = page_faults().saturating_sub(faults);
    let after = source.chunk_reads();
    split.chunk_decodes = after.decodes.saturating_sub(reads.decodes);
    split.chunk_checks = after.checks.saturating_sub(reads.checks);
    split.chunk_checked_bytes = after.checked_bytes.saturating_sub(reads.checked_bytes);
    for ((_, g), b) in meshes.iter_mut().zip(&loaded) {
        g.keep_attributes_of(b);
    }
    let mut pieces = Vec::new();
    for ((_, g), b) in meshes.iter().zip(&loaded) {
        g.pieces(b, &mut pieces);
    }
    let (mapped, staged): (Vec<Piece<'_>>, Vec<Piece<'_>>) = cut(&pieces, PIECE_BYTES)
        .into_iter()
        .partition(|p| p.dst.is_host_mapped());
    let (t, faults) = (Instant::now(), page_faults());
    tracing::debug_span!("mesh_copy").in_scope(|| write_mapped_parallel(&mapped))?;
    split.copy_ms = ms_since(t);
    split.copy_faults = page_faults().saturating_sub(faults);
    let t = Instant::now();
    tracing::debug_span!("mesh_staged").in_scope(|| up.upload_pieces(ctx, &staged))?;
    split.staged_ms = ms_since(t);
    let sizes: Vec<u64> = loaded.iter().map(MeshBytes::len_bytes).collect();
    split.bytes = sizes.iter().sum();
    Ok((sizes, split))
}
