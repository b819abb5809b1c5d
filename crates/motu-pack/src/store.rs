//! A [`GeometryStore`] that streams mesh blobs straight into the package being written, so an
//! import never holds the scene's geometry in memory.

use crate::blob::{MeshBlobLayout, MESH_BLOB_ALIGN};
use motu_package::{ChunkId, PackageWriter, StreamId};
use motu_scene::{GeometryStore, MeshData, MeshId, MeshLocation};
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
}

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
            })),
        }
    }

    fn lock(&self) -> Result<std::sync::MutexGuard<'_, Inner>, String> {
        self.inner
            .lock()
            .map_err(|_| "package writer lock poisoned".to_string())
    }

    /// Appends an arbitrary mesh (e.g. a LOD level the compiler made) to `group`'s stream.
    pub fn append_mesh(&self, group: u32, data: &MeshData) -> Result<MeshLocation, String> {
        let layout = MeshBlobLayout::of(data);
        let blob = layout.encode(data);
        let mut inner = self.lock()?;
        let Inner {
            writer,
            streams,
            layouts,
        } = &mut *inner;
        let writer = writer.as_mut().ok_or("package writer already finished")?;
        let stream = *streams
            .entry(group)
            .or_insert_with(|| writer.open_stream(0, group));
        let loc = writer
            .append(stream, &blob, MESH_BLOB_ALIGN)
            .map_err(|e| e.to_string())?;
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
            writer.seal_chunk(s).map_err(|e| e.to_string())?;
            total -= bytes;
        }
        Ok(at)
    }

    /// Seals every open stream and hands the writer back (for sections and `finish`).
    pub fn take_writer(&self) -> Result<PackageWriter, String> {
        let mut inner = self.lock()?;
        let mut writer = inner.writer.take().ok_or("package writer already taken")?;
        for (_, s) in inner.streams.drain() {
            writer.close_stream(s).map_err(|e| e.to_string())?;
        }
        Ok(writer)
    }
}

impl GeometryStore for PackageGeometry {
    fn store(&mut self, _id: MeshId, group: u32, data: &MeshData) -> Result<MeshLocation, String> {
        self.append_mesh(group, data)
    }

    fn load(&self, id: MeshId, at: MeshLocation) -> Result<MeshData, String> {
        let mut inner = self.lock()?;
        let layout = *inner
            .layouts
            .get(&(at.a, at.b))
            .ok_or_else(|| format!("{id} was not stored in this package"))?;
        let writer = inner
            .writer
            .as_mut()
            .ok_or("package writer already finished")?;
        let bytes = writer
            .read_back(ChunkId(at.a as u32), at.b, layout.len)
            .map_err(|e| e.to_string())?;
        layout.decode(&bytes)
    }
}

/// Points a mesh record at the blob stored at `at` (offsets follow [`MeshBlobLayout`]).
pub fn place_mesh_record(rec: &mut motu_abi::MeshRecord, at: MeshLocation) {
    let l = MeshBlobLayout::new(
        rec.vertex_count as u64,
        rec.triangle_count as u64,
        rec.flags & motu_abi::FLAG_HAS_NORMALS != 0,
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
    rec.uvs_offset = if l.has_uvs {
        at.b + l.uvs
    } else {
        motu_abi::NONE_U64
    };
}
