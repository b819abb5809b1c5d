//! The report's streaming rows: what streaming needs at least by the cost model
//! ([`streaming_report`]), and the report's size source as the floor's size queries
//! ([`FloorAdapter`]) for `motu_gpu::streaming_floor_planned`.

use serde::Serialize;

use crate::cost::{Cost, Graph, Node};
use crate::owner::{Ownership, SHARED};
use crate::rows::ElementReport;
use crate::sizes::{BlasShape, SizeSource, TriangleGeometry};

/// What streaming would need at least.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StreamingReport {
    /// Always resident while rendering anything: every record table, the root TLAS and its
    /// instance buffer, and untagged items.
    pub always_resident_bytes: u64,
    /// The BLAS with the largest build working set (inputs + uncompacted + scratch).
    pub largest_blas_build_bytes: u64,
    pub largest_blas_compacted_bytes: u64,
    /// Its owner (an element name or `shared`).
    pub largest_blas_owner: String,
    /// The floor of `motu render --stream` (`floor.min_resident_bytes`): every budget at or
    /// above it completes every frame at `floor`'s image size.
    pub min_resident_bytes: u64,
    /// Its parts, as `motu_gpu::streaming_floor` computes them for the renderer.
    #[serde(serialize_with = "floor_json")]
    pub floor: motu_gpu::StreamFloor,
    /// The element with the largest `alone.peak_bytes` (the floor for per-element streaming).
    pub largest_element: Option<String>,
    pub largest_element_peak_bytes: u64,
    /// What persistent TLASes (`--stream-tlas update`) would keep resident and the least
    /// budget at which `--stream-tlas auto` (the default) updates them instead of rebuilding;
    /// `None` where the sizes come from a model (updatable TLAS sizes need a device's
    /// queries). Their instance records (64 bytes each) also count where host memory does
    /// (integrated GPUs, CPU drivers).
    #[serde(serialize_with = "persistent_json")]
    pub persistent_tlas: Option<motu_gpu::PersistentEstimate>,
    /// Bytes of every mesh `motu render --stream` streams (positions, indices, primitive maps,
    /// shading attributes, as it lays them out): on a discrete GPU they live in host memory
    /// (`--stream-mesh-memory auto`), the resident ones at most, so this bounds the host
    /// memory they take; in VRAM (`device`, unified memory) they come and go with their BLASes
    /// under the budget.
    pub mesh_bytes: u64,
    /// The TLASes `motu render --stream` splits into pieces when it loads the package (those
    /// over `cap_instances` instances, the default `--stream-split-instances`: the cap the
    /// import recorded, else 1,000,000); the floor and
    /// the persistent estimate above are those of the split hierarchy. `None`: no TLAS over
    /// the cap.
    pub stream_split: Option<StreamSplitReport>,
}

/// See [`StreamingReport::stream_split`].
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct StreamSplitReport {
    pub cap_instances: u32,
    pub tlases_split: u64,
    pub pieces: u64,
}

// The GPU crate's reports as `motu_render::stats` writes them (their JSON keys live there).
fn floor_json<S: serde::Serializer>(v: &motu_gpu::StreamFloor, s: S) -> Result<S::Ok, S::Error> {
    motu_render::stats::StreamFloor::from(v).serialize(s)
}

fn persistent_json<S: serde::Serializer>(
    v: &Option<motu_gpu::PersistentEstimate>,
    s: S,
) -> Result<S::Ok, S::Error> {
    v.as_ref()
        .map(motu_render::stats::PersistentEstimate::from)
        .serialize(s)
}

pub(crate) fn streaming_report(
    g: &Graph<'_>,
    own: &Ownership,
    elements: &[ElementReport],
    total: &Cost,
    root: &Cost,
    name_of: &dyn Fn(u32) -> String,
) -> StreamingReport {
    let untagged: u64 = elements
        .iter()
        .filter(|e| e.kind == "untagged")
        .map(|e| e.ml.resident_bytes)
        .sum();
    let root_instances: u64 = elements.iter().map(|e| e.root_instances).sum();
    let always = total.table_bytes
        + total.texture_bytes
        + root.tlas_bytes
        + root_instances * crate::sizes::INSTANCE_RECORD_SIZE_BYTES
        + untagged;
    let mut best: Option<(u64, u64, Node)> = None;
    for (n, _) in own.iter().filter(|(n, _)| matches!(n, Node::Blas(_))) {
        let c = g.cost(n);
        let inputs: u64 = {
            let mut kids = Vec::new();
            g.children(n, &mut kids);
            kids.iter()
                .filter(|k| matches!(k, Node::Mesh(_)))
                .map(|&k| g.cost(k).geometry_bytes)
                .sum()
        };
        let build = inputs + c.geometry_bytes + c.build_transient_peak_bytes;
        if best.is_none_or(|b| build > b.0) {
            best = Some((build, c.blas_compacted_bytes, n));
        }
    }
    let (build, compacted, owner) = match best {
        Some((b, c, n)) => {
            let o = own.get(n).unwrap_or(SHARED);
            (
                b,
                c,
                if o == SHARED {
                    "shared".into()
                } else {
                    name_of(o)
                },
            )
        }
        None => (0, 0, String::new()),
    };
    let largest = elements
        .iter()
        .filter_map(|e| e.alone.map(|a| (e.name.clone(), a.peak_bytes)))
        .max_by_key(|x| x.1);
    StreamingReport {
        always_resident_bytes: always,
        largest_blas_build_bytes: build,
        largest_blas_compacted_bytes: compacted,
        largest_blas_owner: owner,
        min_resident_bytes: always + build,
        floor: motu_gpu::StreamFloor::default(),
        largest_element: largest.as_ref().map(|l| l.0.clone()),
        largest_element_peak_bytes: largest.map_or(0, |l| l.1),
        persistent_tlas: None,
        mesh_bytes: 0,
        stream_split: None,
    }
}

/// A [`SizeSource`] as the floor's size queries.
pub(crate) struct FloorAdapter<'a>(pub &'a dyn SizeSource);

impl motu_gpu::FloorSizes for FloorAdapter<'_> {
    fn blas(&self, geometry: &[motu_gpu::BlasGeometry]) -> motu_gpu::Result<(u64, u64)> {
        let mut tris = Vec::new();
        let mut boxes = 0u32;
        for g in geometry {
            match *g {
                motu_gpu::BlasGeometry::Triangles {
                    vertex_count,
                    triangle_count,
                    opaque,
                    ..
                } => tris.push(TriangleGeometry {
                    vertex_count,
                    triangle_count,
                    opaque,
                }),
                motu_gpu::BlasGeometry::Aabbs { aabb_count, .. } => boxes += aabb_count,
            }
        }
        let shape = if tris.is_empty() {
            BlasShape::Aabbs { box_count: boxes }
        } else {
            BlasShape::Triangles(tris)
        };
        let s = self
            .0
            .blas_sizes(&shape)
            .map_err(motu_gpu::GpuError::size_source)?;
        Ok((s.size_bytes, s.build_scratch_bytes))
    }

    fn tlas(&self, instance_count: u32) -> motu_gpu::Result<(u64, u64)> {
        let s = self
            .0
            .tlas_sizes(u64::from(instance_count))
            .map_err(motu_gpu::GpuError::size_source)?;
        Ok((s.size_bytes, s.build_scratch_bytes))
    }

    fn tlas_updatable(&self, instance_count: u32) -> motu_gpu::Result<Option<(u64, u64)>> {
        self.0
            .tlas_updatable_sizes(instance_count)
            .map_err(motu_gpu::GpuError::size_source)
    }
}
