//! The streaming floor: the least `--vram-budget` under which every frame completes, identical
//! to the full build (carried hits need one BLAS resident at a time next to the skeleton).
//!
//! One function, [`streaming_floor`], serves the renderer (sizes from the device; a budget
//! below the floor is refused up front) and `motu report` (`streaming.min_resident_bytes`,
//! sizes from its size source, the same driver query on a device), so the two cannot drift.

use motu_abi::{HierarchyView, BLAS_AABBS, FLAG_NEEDS_ANY_HIT};
use motu_alloc::MIB;
use motu_vk::BlasGeometry;

use super::buffers::frame_buffer_bytes;
use super::persistent::{persistent_estimate, persistent_flags, PersistentEstimate};
use super::proxy_boxes;
use crate::error::Result;
use crate::scene::{allocator_slack_bytes, staging_bytes_for_budget};

/// Acceleration-structure sizes (as built, before compaction; build scratch) the floor needs.
pub trait FloorSizes {
    fn blas(&self, geometry: &[BlasGeometry]) -> Result<(u64, u64)>;
    fn tlas(&self, instance_count: u32) -> Result<(u64, u64)>;
    /// (structure, update scratch) of a TLAS built to be updated (a persistent TLAS,
    /// `StreamOptions::tlas_update`); `None` where the source cannot size one (a model fitted
    /// on plain builds).
    fn tlas_updatable(&self, _instance_count: u32) -> Result<Option<(u64, u64)>> {
        Ok(None)
    }
}

impl FloorSizes for motu_vk::Context {
    fn blas(&self, geometry: &[BlasGeometry]) -> Result<(u64, u64)> {
        let s = self.blas_build_sizes(geometry, motu_vk::AsBuildFlags::default())?;
        Ok((
            s.acceleration_structure_size_bytes,
            s.build_scratch_size_bytes,
        ))
    }

    fn tlas(&self, instance_count: u32) -> Result<(u64, u64)> {
        let s = self.tlas_build_sizes(instance_count, motu_vk::AsBuildFlags::default())?;
        Ok((
            s.acceleration_structure_size_bytes,
            s.build_scratch_size_bytes,
        ))
    }

    fn tlas_updatable(&self, instance_count: u32) -> Result<Option<(u64, u64)>> {
        let s = self.tlas_build_sizes(instance_count, persistent_flags())?;
        Ok(Some((
            s.acceleration_structure_size_bytes,
            s.update_scratch_size_bytes,
        )))
    }
}

/// The parts of the floor (bytes), for reports and error messages.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct StreamFloor {
    /// Node tables (with the proxies' records and the clusters' member table), stamps and
    /// walked tables.
    pub tables_bytes: u64,
    /// PI BLASes, every TLAS and every proxy BLAS (no triangle instance resident: TLASes hold
    /// their PI instances and one proxy of clustered boxes): the resident skeleton besides the
    /// tables.
    pub skeleton_structures_bytes: u64,
    /// The triangle BLAS with the largest build working set (meshes, structure, scratch;
    /// compaction is skipped when its copy does not fit).
    pub largest_blas: Option<u32>,
    pub largest_blas_build_bytes: u64,
    /// Rebuilding every TLAS with its proxy and marks BLASes (structures, instance buffer,
    /// boxes, scratch) with the most instanced BLAS resident, next to the largest BLAS.
    pub tlas_rebuild_bytes: u64,
    /// Frame buffers at the image size (carried hits, lists, AOV, colour, readback).
    pub frame_bytes: u64,
    /// Shading tables kept resident: texture records, the per-texture address table, the
    /// per-mesh attribute table.
    pub shading_tables_bytes: u64,
    /// The most shading-attribute bytes (normals, texture coordinates) the meshes of one
    /// triangle BLAS stream with (they are resident with its geometry).
    pub shading_attributes_bytes: u64,
    /// The most texture bytes (whole mip chains) the materials of one triangle BLAS's meshes
    /// sample: textures stream with the meshes that use them.
    pub shading_textures_bytes: u64,
    pub width: u32,
    pub height: u32,
    /// Trace pipeline and shader binding tables (allowance).
    pub pipeline_bytes: u64,
    /// Staging ring at the floor (a 32nd of the budget, at most the default ring).
    pub staging_bytes: u64,
    /// Partly used allocator blocks (block size is a 64th of the budget; two classes, two
    /// blocks each).
    pub allocator_slack_bytes: u64,
    /// The floor: a budget at or above it completes every frame.
    pub min_resident_bytes: u64,
}

/// Allowance for the trace pipeline (shader binding table, small buffers).
const PIPELINE_BYTES: u64 = MIB;

fn align(v: u64, a: u64) -> u64 {
    v.div_ceil(a) * a
}

/// The floor of streaming `view` at `width × height` with a staging ring of at most
/// `staging_cap_bytes` (see the module docs).
pub fn streaming_floor(
    view: &HierarchyView<'_>,
    sizes: &dyn FloorSizes,
    width: u32,
    height: u32,
    staging_cap_bytes: u64,
) -> Result<StreamFloor> {
    let plan = super::StreamPlan::new(view);
    streaming_floor_planned(view, &plan, sizes, width, height, staging_cap_bytes)
}

/// [`streaming_floor`] with the proxy clusters already made (`plan`, of this `view`): a
/// render derives them once for the floor and the renderer.
pub fn streaming_floor_planned(
    view: &HierarchyView<'_>,
    plan: &super::StreamPlan,
    sizes: &dyn FloorSizes,
    width: u32,
    height: u32,
    staging_cap_bytes: u64,
) -> Result<StreamFloor> {
    plan.check(view)?;
    let nb = view.blases.len() as u64;
    let nt = view.tlases.len() as u64;
    let tl = TlasFloor::of(view, plan, sizes)?;
    let skeleton = tl.skeleton_bytes + pi_blas_bytes(view, sizes)?;
    let tables = table_bytes(view, tl.proxies, tl.members);
    let largest = LargestBuild::of(view, sizes)?;
    let pixels = u64::from(width) * u64::from(height);
    let guard = u64::from(width + 16) * u64::from(height + 16) / 4;
    let frame = frame_buffer_bytes(pixels, guard, nb + nt);
    let shading_tables = crate::shading::table_bytes(view, crate::shading::Texels::Streamed);
    let shading_attributes = largest_blas_attribute_bytes(view);
    let shading_textures = largest_blas_texture_bytes(view);
    let base = tables
        + skeleton
        + frame
        + PIPELINE_BYTES
        + shading_tables
        + shading_attributes
        + shading_textures;
    // Budget-dependent parts: staging (an eighth), TLAS rebuild scratch batches (an eighth),
    // allocator slack (four blocks of a 64th): iterate to the fixed point.
    let mut floor = base + largest.build_bytes;
    let mut parts = (0, 0, 0);
    for _ in 0..64 {
        let staging = staging_bytes_for_budget(floor, staging_cap_bytes);
        let rebuild_scratch = tl
            .rebuild_scratch_max
            .max(tl.rebuild_scratch_sum.min(floor / 8));
        let rebuild = tl.rebuild_structures + tl.rebuild_inputs + rebuild_scratch;
        let slack = allocator_slack_bytes(floor);
        let next =
            base + staging + slack + largest.build_bytes.max(largest.resident_bytes + rebuild);
        parts = (staging, rebuild, slack);
        if next <= floor {
            break;
        }
        floor = next;
    }
    Ok(StreamFloor {
        tables_bytes: tables,
        skeleton_structures_bytes: skeleton,
        largest_blas: largest.blas,
        largest_blas_build_bytes: largest.build_bytes,
        tlas_rebuild_bytes: parts.1,
        frame_bytes: frame,
        shading_tables_bytes: shading_tables,
        shading_attributes_bytes: shading_attributes,
        shading_textures_bytes: shading_textures,
        width,
        height,
        pipeline_bytes: PIPELINE_BYTES,
        staging_bytes: parts.0,
        allocator_slack_bytes: parts.2,
        min_resident_bytes: floor,
    })
}

fn as_align(v: u64) -> u64 {
    align(v, 256)
}

/// What the TLASes bring to the floor: their skeleton (each TLAS over its PI instances and
/// proxy, and the proxy), and rebuilding them with the most instanced BLAS resident.
#[derive(Default)]
struct TlasFloor {
    /// Proxy boxes (clusters) and their members over all TLASes.
    proxies: u64,
    members: u64,
    /// The TLASes and proxies of the skeleton.
    skeleton_bytes: u64,
    /// A rebuild of every TLAS: structures, inputs (records and boxes), and the largest and
    /// summed scratch of one TLAS's builds.
    rebuild_structures: u64,
    rebuild_inputs: u64,
    rebuild_scratch_max: u64,
    rebuild_scratch_sum: u64,
}

impl TlasFloor {
    fn of(
        view: &HierarchyView<'_>,
        plan: &super::StreamPlan,
        sizes: &dyn FloorSizes,
    ) -> Result<TlasFloor> {
        // A streamed TLAS holds its PI instances, the proxy and the resident BLASes'
        // instances: at the floor one BLAS is resident (the most instanced one bounds its
        // instances). Counted in parallel over TLASes (millions of instances).
        let most = most_instanced(view);
        let mut out = TlasFloor::default();
        for (t, &(other, most_blas, most)) in most.iter().enumerate() {
            let cl = &plan.clusters[t];
            out.members += cl.iter().map(|c| c.members.len() as u64).sum::<u64>();
            let clusters = cl.len() as u32;
            let proxy = u32::from(clusters > 0);
            let (t_bytes, _) = sizes.tlas((other + proxy).max(1))?;
            out.skeleton_bytes += as_align(t_bytes);
            // Rebuilt with the resident BLAS's instances and its clusters in the marks BLAS.
            let count = (other + 2 * proxy + most).max(1);
            let (r_bytes, r_scratch) = sizes.tlas(count)?;
            out.rebuild_structures += as_align(r_bytes);
            out.rebuild_inputs += u64::from(count) * 64;
            let mut scratch = r_scratch;
            if clusters > 0 {
                out.proxies += u64::from(clusters);
                let (p_bytes, p_scratch) = sizes.blas(&[BlasGeometry::Aabbs {
                    aabb_count: clusters,
                    opaque: false,
                }])?;
                out.skeleton_bytes += as_align(p_bytes);
                // Rebuilt next to the old one's release: counted again (conservative).
                out.rebuild_structures += as_align(p_bytes);
                out.rebuild_inputs += align(u64::from(clusters) * 24, 16);
                scratch = scratch.max(p_scratch);
                // The marks BLAS: the resident BLAS's clusters (also counted in the proxy).
                let resident = cl.iter().filter(|c| c.blas == most_blas).count() as u32;
                if resident > 0 {
                    let (m_bytes, m_scratch) = sizes.blas(&[BlasGeometry::Aabbs {
                        aabb_count: resident,
                        opaque: false,
                    }])?;
                    out.rebuild_structures += as_align(m_bytes);
                    scratch = scratch.max(m_scratch);
                }
            }
            out.rebuild_scratch_max = out.rebuild_scratch_max.max(scratch);
            out.rebuild_scratch_sum += align(scratch, 256);
        }
        Ok(out)
    }
}

/// Per TLAS: its instances of BLASes that are not streamed (PI and empty BLASes), and the
/// streamed BLAS most of its instances place (the lowest id among equals; `u32::MAX` if none)
/// with that count. Parallel over TLASes, a dense counter per task.
fn most_instanced(view: &HierarchyView<'_>) -> Vec<(u32, u32, u32)> {
    use rayon::prelude::*;
    let buildable: Vec<bool> = view.blases.iter().map(super::streamable).collect();
    view.tlases
        .par_iter()
        .map_init(
            || vec![0u32; view.blases.len()],
            |per_blas, rec| {
                let mut other = 0u32;
                let mut touched = Vec::new();
                for i in &view.instances[rec.instance_range()] {
                    let b = i.blas as usize;
                    if buildable[b] {
                        if per_blas[b] == 0 {
                            touched.push(i.blas);
                        }
                        per_blas[b] += 1;
                    } else {
                        other += 1;
                    }
                }
                let (most_blas, most) = touched
                    .iter()
                    .map(|&b| (b, per_blas[b as usize]))
                    .max_by_key(|&(b, n)| (n, std::cmp::Reverse(b)))
                    .unwrap_or((u32::MAX, 0));
                for &b in &touched {
                    per_blas[b as usize] = 0;
                }
                (other, most_blas, most)
            },
        )
        .collect()
}

/// The PI BLASes of the skeleton.
fn pi_blas_bytes(view: &HierarchyView<'_>, sizes: &dyn FloorSizes) -> Result<u64> {
    let mut bytes = 0;
    for r in view.blases {
        if r.kind == BLAS_AABBS && r.item_count > 0 {
            let (b, _) = sizes.blas(&[BlasGeometry::Aabbs {
                aabb_count: r.item_count,
                opaque: false,
            }])?;
            bytes += as_align(b);
        }
    }
    Ok(bytes)
}

/// The GPU tables as the renderer uploads them: the node tables with `proxies` proxy PI
/// records, the member table of `members` instances, the boxes inside streamable BLASes, the
/// address and stamp tables.
fn table_bytes(view: &HierarchyView<'_>, proxies: u64, members: u64) -> u64 {
    let nb = view.blases.len() as u64;
    let nt = view.tlases.len() as u64;
    let buildable = |b: usize| super::streamable(&view.blases[b]);
    let rec_bytes = |n: u64, size: u64| align(n * size, 16);
    let proxy_box_bytes = {
        let (index, boxes) = proxy_boxes::layout(view, buildable);
        if boxes == 0 {
            0
        } else {
            rec_bytes(index.len() as u64, 8)
                + rec_bytes(
                    boxes as u64,
                    std::mem::size_of::<proxy_boxes::Box6>() as u64,
                )
        }
    };
    rec_bytes(nt, std::mem::size_of::<motu_abi::TlasRecord>() as u64)
        + rec_bytes(
            view.instances.len() as u64 + 2 * nt,
            std::mem::size_of::<motu_abi::InstanceRecord>() as u64,
        )
        + rec_bytes(nb + 2 * nt, std::mem::size_of::<motu_abi::BlasRecord>() as u64)
        + rec_bytes(
            view.geometries.len() as u64,
            std::mem::size_of::<motu_abi::GeometryRecord>() as u64,
        )
        + rec_bytes(
            view.pis.len() as u64 + proxies,
            std::mem::size_of::<motu_abi::PiRecord>() as u64,
        )
        + rec_bytes(
            view.lod_selectors.len() as u64,
            std::mem::size_of::<motu_abi::LodSelectorRecord>() as u64,
        )
        + rec_bytes(view.lod_levels.len() as u64, 4)
        + rec_bytes(
            view.meshes.len() as u64,
            std::mem::size_of::<motu_abi::MeshRecord>() as u64,
        )
        + rec_bytes(
            view.materials.len() as u64,
            std::mem::size_of::<motu_abi::MaterialRecord>() as u64,
        )
        + rec_bytes(view.meshes.len() as u64, 16)
        + rec_bytes(nt, 8)
        // The proxy clusters' member table (a quantised box and an index a member).
        + rec_bytes(members, 4 * super::member_boxes::MEMBER_WORDS as u64)
        // The boxes inside streamable BLASes and their index.
        + proxy_box_bytes
        + 2 * rec_bytes(nb.max(1), 4)
}

/// The triangle BLAS with the largest build: meshes, structure, scratch.
/// The build shape of triangle BLAS record `r` (one indexed triangle geometry per mesh), for
/// the device's size query.
pub(super) fn triangle_shape(
    view: &HierarchyView<'_>,
    r: &motu_abi::BlasRecord,
) -> Vec<BlasGeometry> {
    let range = r.item_base as usize..(r.item_base + r.item_count) as usize;
    view.geometries[range]
        .iter()
        .map(|g| {
            let m = &view.meshes[g.mesh as usize];
            BlasGeometry::Triangles {
                vertex_count: m.vertex_count,
                triangle_count: m.triangle_count,
                indexed: true,
                opaque: m.flags & FLAG_NEEDS_ANY_HIT == 0,
            }
        })
        .collect()
}

struct LargestBuild {
    blas: Option<u32>,
    /// Its build's bytes, and what stays resident after (meshes and structure).
    build_bytes: u64,
    resident_bytes: u64,
}

impl LargestBuild {
    fn of(view: &HierarchyView<'_>, sizes: &dyn FloorSizes) -> Result<LargestBuild> {
        let mut largest = LargestBuild {
            blas: None,
            build_bytes: 0,
            resident_bytes: 0,
        };
        for (b, r) in view.blases.iter().enumerate() {
            if !super::streamable(r) {
                continue;
            }
            let range = r.item_base as usize..(r.item_base + r.item_count) as usize;
            let shape = triangle_shape(view, r);
            let mut mesh_bytes = 0u64;
            for g in &view.geometries[range] {
                let m = &view.meshes[g.mesh as usize];
                // As MeshGpu lays it out: positions, indices, the primitive map of a cluster.
                let map = if m.flags & motu_abi::FLAG_PRIMITIVE_MAP != 0 {
                    u64::from(m.triangle_count) * 4
                } else {
                    0
                };
                mesh_bytes += align(
                    align(u64::from(m.vertex_count) * 12, 16)
                        + u64::from(m.triangle_count) * 12
                        + map,
                    16,
                );
            }
            let (bytes, scratch) = sizes.blas(&shape)?;
            let build = mesh_bytes + as_align(bytes) + align(scratch, 256);
            if largest.blas.is_none() || build > largest.build_bytes {
                largest = LargestBuild {
                    blas: Some(b as u32),
                    build_bytes: build,
                    resident_bytes: mesh_bytes + as_align(bytes),
                };
            }
        }
        Ok(largest)
    }
}

/// Bytes of every mesh a streamer of `view` streams, as it lays them out
/// (`MeshGpu::alloc_streamed`): the most its meshes take at once, in host memory on a discrete
/// GPU ([`super::MeshMemory`]).
pub fn streamed_mesh_total_bytes(view: &HierarchyView<'_>) -> u64 {
    view.meshes
        .iter()
        .map(crate::scene::streamed_mesh_bytes)
        .sum()
}

/// Shading attributes of the triangle BLAS whose meshes have the most (see
/// `scene::streamed_attribute_bytes`).
fn largest_blas_attribute_bytes(view: &HierarchyView<'_>) -> u64 {
    view.blases
        .iter()
        .filter(|r| super::streamable(r))
        .map(|r| {
            let range = r.item_base as usize..(r.item_base + r.item_count) as usize;
            view.geometries[range]
                .iter()
                .map(|g| {
                    let (n, u) =
                        crate::scene::streamed_attribute_bytes(&view.meshes[g.mesh as usize]);
                    n + u
                })
                .sum::<u64>()
        })
        .max()
        .unwrap_or(0)
}

/// Texture bytes of the triangle BLAS whose meshes' materials sample the most (each texture
/// once; see `shading::streamed_texture_bytes`).
fn largest_blas_texture_bytes(view: &HierarchyView<'_>) -> u64 {
    view.blases
        .iter()
        .filter(|r| super::streamable(r))
        .map(|r| {
            let range = r.item_base as usize..(r.item_base + r.item_count) as usize;
            let mut textures: Vec<usize> = view.geometries[range]
                .iter()
                .flat_map(|g| crate::shading::mesh_textures(view, g.mesh as usize))
                .collect();
            textures.sort_unstable();
            textures.dedup();
            textures
                .into_iter()
                .map(|t| crate::shading::streamed_texture_bytes(view, t))
                .sum::<u64>()
        })
        .max()
        .unwrap_or(0)
}

/// What persistent TLASes would keep resident when streaming `view`, by `sizes` (a device's
/// size queries: [`FloorSizes::tlas_updatable`]), on a device whose TLASes hold at most
/// `max_instances` instances and whose host memory does not count against the budget; `None`
/// where `sizes` cannot size updatable TLASes. See [`PersistentEstimate`].
pub fn persistent_tlas_estimate(
    view: &HierarchyView<'_>,
    sizes: &dyn FloorSizes,
    max_instances: u64,
) -> Result<Option<PersistentEstimate>> {
    let buildable = |b: u32| super::streamable(&view.blases[b as usize]);
    let has_clusters: Vec<bool> = view
        .tlases
        .iter()
        .map(|rec| {
            view.instances[rec.instance_range()]
                .iter()
                .any(|i| buildable(i.blas))
        })
        .collect();
    if sizes.tlas_updatable(2)?.is_none() {
        return Ok(None);
    }
    let (placeholder, _) = sizes.blas(&[BlasGeometry::Aabbs {
        aabb_count: 1,
        opaque: true,
    }])?;
    let (_, estimate) = persistent_estimate(
        view,
        &has_clusters,
        max_instances,
        false,
        placeholder,
        |n| sizes.tlas_updatable(n),
    )?;
    Ok(Some(estimate))
}
