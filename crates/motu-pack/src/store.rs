//! A [`GeometryStore`] that streams mesh blobs straight into the package being written, so an
//! import never holds the scene's geometry in memory.

use crate::blob::{MeshBlobLayout, MESH_BLOB_ALIGN};
use crate::PackError;
use motu_package::{ChunkId, PackageWriter, StreamId};
use motu_scene::{GeometryStore, MeshData, MeshId, MeshLocation, StoreError};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// Shares the package writer with the import pipeline: the scene builder stores meshes through
/// it while parsing, and the pipeline takes the writer back to add the sections and finish.
/// One chunk stream per group (element), so an element's meshes share chunks.
#[derive(Clone)]
pub struct PackageGeometry {
    inner: Arc<Mutex<Inner>>,
}

struct Inner {
    writer: Option<PackageWriter>,
    streams: HashMap<u32, StreamId>,
    /// Blob layout per stored blob, keyed by location, for read-back.
    layouts: HashMap<(u64, u64), MeshBlobLayout>,
    spill: Option<Spill>,
}

/// Where meshes the compiler will partition go instead of the package (see
/// [`PackageGeometry::with_spill`]): a writer that is never finished, so its temp file is
/// removed when it is dropped.
struct Spill {
    writer: PackageWriter,
    stream: Option<StreamId>,
    over_triangles: u64,
    /// `(after_triangles, bound)`: see [`PackageGeometry::raise_spill_bound_after`].
    raise: Option<(u64, u64)>,
    /// Triangles of every mesh stored so far (spilled or not).
    stored_triangles: u64,
}

/// Marks a [`MeshLocation`] in the spill writer.
const SPILL_BIT: u64 = 1 << 63;

impl std::fmt::Debug for PackageGeometry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("PackageGeometry")
    }
}

/// Memory all element streams' open chunks may hold together during an import.
pub const OPEN_CHUNK_BUDGET_BYTES: u64 = 128 << 20;

/// Packs a chunk id and an offset into the scene's opaque location.
pub(crate) fn location(chunk: ChunkId, offset: u64) -> MeshLocation {
    MeshLocation {
        a: chunk.0 as u64,
        b: offset,
    }
}

impl PackageGeometry {
    pub fn new(writer: PackageWriter) -> Self {
        Self {
            inner: Arc::new(Mutex::new(Inner {
                writer: Some(writer),
                streams: HashMap::new(),
                layouts: HashMap::new(),
                spill: None,
            })),
        }
    }

    /// Meshes of more than `over_triangles` triangles (those the partitioner will replace by
    /// clusters, so the package never references them whole) are stored through `spill`
    /// instead, a writer that is never finished: its temp file goes when this store's writer
    /// is taken. Each spilled blob is sealed at once, so it costs no memory.
    pub fn with_spill(self, spill: PackageWriter, over_triangles: u64) -> Self {
        if let Ok(mut inner) = self.inner.lock() {
            inner.spill = Some(Spill {
                writer: spill,
                stream: None,
                over_triangles,
                raise: None,
                stored_triangles: 0,
            });
        }
        self
    }

    /// Raises the spill bound to `bound` once meshes of `after_triangles` triangles in all
    /// have been stored. For a partition bound chosen from the scene's size: past that count
    /// the choice is known to be `bound` (`motu_compile::auto_bound_settles_at_triangles`), so
    /// meshes under it need not take the detour through the spill file and back (those
    /// stored before stay spilled; the import copies the ones kept whole into the package).
    pub fn raise_spill_bound_after(self, after_triangles: u64, bound: u64) -> Self {
        if let Ok(mut inner) = self.inner.lock() {
            if let Some(sp) = inner.spill.as_mut() {
                sp.raise = Some((after_triangles, bound));
            }
        }
        self
    }

    /// Raises the spill bound to `bound` now (a caller that counts stored triangles itself
    /// and knows the partition bound; see [`Self::raise_spill_bound_after`]).
    pub fn raise_spill_bound(&self, bound: u64) {
        if let Ok(mut inner) = self.inner.lock() {
            if let Some(sp) = inner.spill.as_mut() {
                sp.over_triangles = sp.over_triangles.max(bound);
            }
        }
    }

    /// Whether `at` is in the spill writer (not in the package).
    pub fn is_spilled(at: MeshLocation) -> bool {
        at.a & SPILL_BIT != 0
    }

    fn spill_mesh(&self, data: &MeshData) -> Result<Option<MeshLocation>, PackError> {
        let mut inner = self.lock()?;
        let Inner { spill, layouts, .. } = &mut *inner;
        let Some(sp) = spill.as_mut() else {
            return Ok(None);
        };
        let triangles = data.triangle_count() as u64;
        sp.stored_triangles += triangles;
        if let Some((after, bound)) = sp.raise {
            if sp.stored_triangles >= after {
                sp.over_triangles = sp.over_triangles.max(bound);
            }
        }
        if triangles <= sp.over_triangles {
            return Ok(None);
        }
        let layout = MeshBlobLayout::of(data);
        let stream = *sp
            .stream
            .get_or_insert_with(|| sp.writer.open_stream(0, u32::MAX));
        let loc = sp
            .writer
            .append_with(stream, layout.len, MESH_BLOB_ALIGN, &mut |out| {
                layout.encode_mapped_onto(data, None, out)
            })?;
        sp.writer.seal_chunk(stream)?;
        let at = location(loc.chunk, loc.offset_in_chunk);
        let at = MeshLocation {
            a: at.a | SPILL_BIT,
            b: at.b,
        };
        layouts.insert((at.a, at.b), layout);
        Ok(Some(at))
    }

    fn lock(&self) -> Result<std::sync::MutexGuard<'_, Inner>, PackError> {
        self.inner
            .lock()
            .map_err(|_| store_err("package writer lock poisoned"))
    }

    /// Appends an arbitrary mesh (e.g. a LOD level the compiler made) to `group`'s stream.
    pub fn append_mesh(&self, group: u32, data: &MeshData) -> Result<MeshLocation, PackError> {
        self.append_mesh_mapped(group, data, None)
    }

    /// Appends a compiled mesh with an optional primitive map (a partitioned mesh's cluster;
    /// see [`MeshBlobLayout::with_map`]).
    pub fn append_mesh_mapped(
        &self,
        group: u32,
        data: &MeshData,
        primitive_map: Option<&[u32]>,
    ) -> Result<MeshLocation, PackError> {
        if let Some(map) = primitive_map {
            if map.len() != data.triangle_count() {
                return Err(store_err(format!(
                    "primitive map has {} entries for {} triangles",
                    map.len(),
                    data.triangle_count()
                )));
            }
        }
        let layout = MeshBlobLayout::of_mapped(data, primitive_map);
        let mut inner = self.lock()?;
        let Inner {
            writer,
            streams,
            layouts,
            ..
        } = &mut *inner;
        let writer = writer
            .as_mut()
            .ok_or_else(|| store_err("package writer already finished"))?;
        let stream = *streams
            .entry(group)
            .or_insert_with(|| writer.open_stream(0, group));
        // Encoded straight into the open chunk (no blob buffer zeroed, filled and copied).
        let loc = writer.append_with(stream, layout.len, MESH_BLOB_ALIGN, &mut |out| {
            layout.encode_mapped_onto(data, primitive_map, out)
        })?;
        let at = location(loc.chunk, loc.offset_in_chunk);
        layouts.insert((at.a, at.b), layout);
        // One open chunk per element could hold elements × 64 MiB in memory: past the budget,
        // write out the fullest open chunk early (a smaller chunk, same data).
        let mut open: Vec<(u64, StreamId)> = streams
            .values()
            .map(|&s| (writer.open_chunk_bytes(s), s))
            .collect();
        let mut total: u64 = open.iter().map(|o| o.0).sum();
        open.sort_unstable_by_key(|o| std::cmp::Reverse(o.0));
        for (bytes, s) in open {
            if total <= OPEN_CHUNK_BUDGET_BYTES {
                break;
            }
            writer.seal_chunk(s)?;
            total -= bytes;
        }
        Ok(at)
    }

    /// Seals every open stream and hands the writer back (for sections and `finish`); drops
    /// the spill writer (its temp file).
    pub fn take_writer(&self) -> Result<PackageWriter, PackError> {
        let mut inner = self.lock()?;
        inner.spill = None;
        let mut writer = inner
            .writer
            .take()
            .ok_or_else(|| store_err("package writer already taken"))?;
        // Closing a stream writes its open chunk: in group order, so the chunks lie where they
        // lay in the last run (a map's order differs from process to process, and so did the
        // package's bytes: island 0.05 put 16 of its 33 chunks at other offsets each run).
        let mut streams: Vec<(u32, StreamId)> = inner.streams.drain().collect();
        streams.sort_unstable_by_key(|&(group, _)| group);
        for (_, s) in streams {
            writer.close_stream(s)?;
        }
        Ok(writer)
    }
}

impl GeometryStore for PackageGeometry {
    fn store(
        &mut self,
        _id: MeshId,
        group: u32,
        data: &MeshData,
    ) -> Result<MeshLocation, StoreError> {
        if let Some(at) = self.spill_mesh(data)? {
            return Ok(at);
        }
        Ok(self.append_mesh(group, data)?)
    }

    fn load(&self, id: MeshId, at: MeshLocation) -> Result<MeshData, StoreError> {
        let mut inner = self.lock()?;
        let layout = *inner
            .layouts
            .get(&(at.a, at.b))
            .ok_or_else(|| store_err(format!("{id} was not stored in this package")))?;
        let writer = if Self::is_spilled(at) {
            &mut inner
                .spill
                .as_mut()
                .ok_or_else(|| store_err("the spill store was already dropped"))?
                .writer
        } else {
            inner
                .writer
                .as_mut()
                .ok_or_else(|| store_err("package writer already finished"))?
        };
        let bytes = writer.read_back(ChunkId((at.a & !SPILL_BIT) as u32), at.b, layout.len)?;
        Ok(layout.decode(&bytes)?)
    }
}

fn store_err(what: impl Into<String>) -> PackError {
    PackError::Store(what.into())
}

/// Points a mesh record at the blob stored at `at` (offsets follow [`MeshBlobLayout`]; the
/// record's flags say whether the blob has normals and a primitive map).
pub fn place_mesh_record(rec: &mut motu_abi::MeshRecord, at: MeshLocation) {
    let l = MeshBlobLayout::with_map(
        rec.vertex_count as u64,
        rec.triangle_count as u64,
        rec.flags & motu_abi::FLAG_HAS_NORMALS != 0,
        rec.flags & motu_abi::FLAG_PRIMITIVE_MAP != 0,
    )
    .with_uvs(rec.flags & motu_abi::FLAG_HAS_UVS != 0);
    rec.chunk = at.a as u32;
    rec.positions_offset = at.b + l.positions;
    rec.indices_offset = at.b + l.indices;
    rec.normals_offset = if l.has_normals {
        at.b + l.normals
    } else {
        motu_abi::NONE_U64
    };
    rec.primitive_map_offset = if l.has_primitive_map {
        at.b + l.primitive_map
    } else {
        motu_abi::NONE_U64
    };
    rec.uvs_offset = if l.has_uvs {
        at.b + l.uvs
    } else {
        motu_abi::NONE_U64
    };
}

#[cfg(test)]
mod tests;
