//! Table encoding: BLAS geometry descriptions, TLAS instance records, programmable-instance
//! AABBs and what the root reaches.

use motu_abi::{
    HierarchyView, TlasRecord, BLAS_AABBS, BOX_LIST_CAPACITY, FLAG_NEEDS_ANY_HIT, PI_LOD_SELECTOR,
    PI_TLAS,
};
use motu_vk::{AsGeometry, BlasGeometry, InstanceHit};

use super::MeshGpu;
use crate::error::{GpuError, Result};

/// The build geometry of one BLAS: geometries, their primitive counts, their shapes (for the
/// size query).
pub(crate) type BlasDesc = (Vec<AsGeometry>, Vec<u32>, Vec<BlasGeometry>);

/// One geometry of boxes (24 bytes each) at `device_address`: programmable instances, proxy
/// boxes and placeholders (`opaque`: no any-hit; else each candidate once, as programmable
/// instances record them).
pub(crate) fn aabbs_geometry(device_address: u64, opaque: bool) -> AsGeometry {
    AsGeometry::Aabbs {
        address: device_address,
        opaque,
    }
}

/// Geometry of BLAS `i` of `view`: one triangle geometry per mesh (`mesh(m)` is mesh record
/// `m` on the GPU) or the AABBs of its programmable instances, read at `aabb_base + 24 × item`.
/// `None` for a BLAS without primitives.
pub(crate) fn blas_geometry<'m>(
    view: &HierarchyView<'_>,
    i: usize,
    mesh: impl Fn(usize) -> Option<&'m MeshGpu>,
    aabb_base: u64,
) -> Result<Option<BlasDesc>> {
    let b = &view.blases[i];
    let range = b.item_base as usize..(b.item_base + b.item_count) as usize;
    let (geoms, counts, shape): (Vec<_>, Vec<u32>, Vec<BlasGeometry>) = if b.kind == BLAS_AABBS {
        if b.item_count == 0 {
            (Vec::new(), Vec::new(), Vec::new())
        } else {
            (
                vec![aabbs_geometry(
                    aabb_base + u64::from(b.item_base) * 24,
                    false,
                )],
                vec![b.item_count],
                vec![BlasGeometry::Aabbs {
                    aabb_count: b.item_count,
                    opaque: false,
                }],
            )
        }
    } else {
        let mut g = Vec::new();
        let mut c = Vec::new();
        let mut s = Vec::new();
        for geo in &view.geometries[range] {
            let Some(m) = mesh(geo.mesh as usize) else {
                continue;
            };
            let opaque = view.meshes[geo.mesh as usize].flags & FLAG_NEEDS_ANY_HIT == 0;
            g.push(AsGeometry::Triangles {
                positions_address: m.positions_address,
                vertex_count: m.vertex_count,
                indices_address: m.indices_address,
                opaque,
            });
            c.push(m.triangle_count);
            s.push(BlasGeometry::Triangles {
                vertex_count: m.vertex_count,
                triangle_count: m.triangle_count,
                indexed: true,
                opaque,
            });
        }
        // A geometry index must equal its position in the record (gl_GeometryIndexEXT
        // resolves the mesh), so an empty mesh inside a BLAS is an error.
        if g.len() != b.item_count as usize {
            return Err(GpuError::InvalidRequest(format!(
                "BLAS {i}: {} of its {} meshes are empty",
                b.item_count as usize - g.len(),
                b.item_count
            )));
        }
        (g, c, s)
    };
    Ok(if geoms.is_empty() {
        None
    } else {
        Some((geoms, counts, shape))
    })
}

/// One TLAS instance record (64 bytes, motu-vk's [`motu_vk::encode_instance`]): triangles use
/// hit group 0 (opaque unless `needs_any_hit`), programmable instances (`aabbs`) hit group 1,
/// never opaque. A `blas_address` of 0 makes the instance inactive. The custom index is
/// `local_index`, the instance's index within its TLAS's record range (< 2^24, which
/// `max_instance_count` bounds): the shaders read it instead of the position in the built
/// TLAS, so a streamed TLAS may hold only its resident instances. Node ids never travel in 24
/// bits: only the local instance index does.
pub(crate) fn encode_instance(
    tlas_from_blas: &[f32; 12],
    aabbs: bool,
    needs_any_hit: bool,
    blas_address: u64,
    local_index: u32,
) -> [u8; 64] {
    let hit = if aabbs {
        InstanceHit::Procedural
    } else {
        InstanceHit::Triangles {
            any_hit: needs_any_hit,
        }
    };
    motu_vk::encode_instance(tlas_from_blas, hit, blas_address, local_index)
}

/// Sets an encoded instance's 8-bit visibility mask (the top byte of its custom-index word,
/// byte 51): `encode_instance` gives every active instance 0xFF; the streamer narrows it so
/// a ray's cull mask can skip triangle instances or see the probe-only marks.
pub(crate) fn set_instance_mask(instance: &mut [u8; 64], mask: u8) {
    instance[51] = mask;
}

/// How many of TLAS `t`'s last instances a full build leaves out of the hardware TLAS as a box
/// list ([`TlasRecord::box_list_instances`]): the trailing AABB instances whose PIs (TLASes or
/// LOD selectors, at most [`BOX_LIST_CAPACITY`] in all) raygen tests itself. A split root's
/// pieces are such PIs: in the hardware walk every piece box a ray crosses costs an
/// intersection and an any-hit invocation, in raygen a slab test. At least one instance stays
/// in the hardware TLAS (its walk is what the box list rides on).
pub(crate) fn box_list_instances(view: &HierarchyView<'_>, t: usize) -> u32 {
    let rec = &view.tlases[t];
    let (base, count) = (rec.instance_base as usize, rec.instance_count as usize);
    let Some(insts) = view.instances.get(base..base + count) else {
        return 0;
    };
    let (mut n, mut pis) = (0usize, 0u32);
    for inst in insts.iter().rev() {
        if n + 1 >= count {
            break;
        }
        let Some(b) = view.blases.get(inst.blas as usize) else {
            break;
        };
        let items = b.item_base as usize..(b.item_base + b.item_count) as usize;
        let ok = b.kind == BLAS_AABBS
            && b.item_count > 0
            && pis + b.item_count <= BOX_LIST_CAPACITY
            && view.pis.get(items).is_some_and(|ps| {
                ps.iter()
                    .all(|p| p.kind == PI_TLAS || p.kind == PI_LOD_SELECTOR)
            });
        if !ok {
            break;
        }
        pis += b.item_count;
        n += 1;
    }
    n as u32
}

/// `view`'s TLAS records as a full build uploads them: each with its box list.
pub(crate) fn tlases_with_box_lists(view: &HierarchyView<'_>) -> Vec<TlasRecord> {
    (0..view.tlases.len())
        .map(|t| TlasRecord {
            box_list_instances: box_list_instances(view, t),
            ..view.tlases[t]
        })
        .collect()
}

/// The most PI candidates one TLAS walk can record, [`MAX_PI_CAPACITY`] at most: the most PIs
/// any TLAS's hardware walk can meet (its AABB instances' PIs, less a box list's, which raygen
/// tests itself when `box_lists`), at least 1. The traversal payload carries that many
/// candidate slots (`PI_CAPACITY`, a specialisation constant): on the H200's software traversal
/// every byte of payload costs every trace, and a split root whose pieces are a box list, or a
/// scene `auto` made single-level, needs no slots at all. A walk meeting more PIs than slots
/// keeps the nearest and re-walks for the rest, so the image never depends on it.
pub(crate) fn pi_capacity(view: &HierarchyView<'_>, box_lists: bool) -> u32 {
    let mut most = 0u32;
    for (t, rec) in view.tlases.iter().enumerate() {
        let listed = if box_lists {
            box_list_instances(view, t) as usize
        } else {
            0
        };
        let (base, count) = (rec.instance_base as usize, rec.instance_count as usize);
        let Some(insts) = view
            .instances
            .get(base..(base + count).saturating_sub(listed))
        else {
            return MAX_PI_CAPACITY;
        };
        let mut pis = 0u32;
        for inst in insts {
            match view.blases.get(inst.blas as usize) {
                Some(b) if b.kind == BLAS_AABBS => pis = pis.saturating_add(b.item_count),
                Some(_) => {}
                None => return MAX_PI_CAPACITY,
            }
            if pis >= MAX_PI_CAPACITY {
                return MAX_PI_CAPACITY;
            }
        }
        most = most.max(pis);
    }
    most.max(1)
}

/// The default (and largest) candidate list of a TLAS walk (`PI_CAPACITY` of `common.glsl`).
pub(crate) const MAX_PI_CAPACITY: u32 = 8;

/// The AABB build input of every programmable instance (`VkAabbPositionsKHR`: min then max),
/// indexed like the PI table.
pub(crate) fn pi_aabbs(view: &HierarchyView<'_>) -> Vec<[f32; 6]> {
    view.pis
        .iter()
        .map(|p| {
            let (a, b) = (p.aabb_min, p.aabb_max);
            [a[0], a[1], a[2], b[0], b[1], b[2]]
        })
        .collect()
}

#[cfg(test)]
mod tests;
