//! The partitioner: geometry becomes triangle-BLAS units of at most
//! [`crate::CompileOptions::max_blas_triangles`] triangles, spatially coherent, so that no single
//! structure is larger than a streaming budget can hold (issue 14).
//!
//! - A mesh over the bound is split into **clusters** by recursive median splits of its
//!   triangle centroids along the largest axis ([`crate::split::median_partition`]: it halves by
//!   index, so it always terminates and every cluster gets `≥ bound / 2` triangles). Each
//!   cluster becomes a compiled mesh of its own (only the vertices it uses) with a **primitive
//!   map**: cluster triangle → source triangle, ascending, so hit records still name the source
//!   mesh and its primitive. Only one source mesh's data is in memory at a time, and each
//!   cluster goes to the sink as soon as it is made.
//! - Small meshes of one prototype (or one element of the root) are **grouped by location**:
//!   recursive splits at the triangle-weighted median of the mesh bounds' centres until each
//!   group is under the bound — never one BLAS per mesh, never one BLAS for everything.

use crate::split::median_partition;
use motu_scene::{Aabb, MeshData};

/// The default bound: 2^16 triangles. Chosen from the size models (BENCHMARKS.md "VRAM model
/// vs driver sizes": lavapipe 104 B/triangle built, H200 91.7 B/triangle + 67.8 B/triangle of
/// build scratch) and the default island (`motu gen island --scale 0.002`, 261 MiB full build,
/// 16.2 MiB always resident): a 2^16 unit needs ≤ 6.5 MiB of AS (≤ 10.5 MiB with H200 scratch,
/// plus ~1.2 MiB of geometry), so the island's streaming floor (skeleton + the largest unit)
/// is ~24 MiB, under 10% of its full build; at 2^17 it would be ~29 MiB, at 2^19 (no split on
/// that island: its largest BLAS has 448k triangles) ~70 MiB. The cost is small: units only
/// multiply the instances of prototypes over the bound (island: 55,497 → 55,802 instances,
/// 34 → 71 BLASes, full build 258 → 261 MiB). It is the cap of the automatic bound
/// ([`auto_max_blas_triangles`]), which `motu import` uses when no bound is given.
pub const DEFAULT_MAX_BLAS_TRIANGLES: u32 = 1 << 16;

/// The smallest bound [`auto_max_blas_triangles`] picks: below it a unit's fixed costs (an
/// instance, a BLAS header, a build step) outweigh what a smaller floor would save.
pub const MIN_AUTO_MAX_BLAS_TRIANGLES: u32 = 1 << 12;

/// How many triangles one instance record weighs in [`auto_max_blas_triangles`]'s estimate of
/// the whole build: an instance costs ~300 B (instance record, TLAS node share, tables; the
/// default island's report: 3.4 MB for 13,970 instances), a triangle ~120 B (BLAS + geometry).
pub const AUTO_TRIANGLES_PER_INSTANCE: u64 = 2;

/// The share of the whole build one unit aims at, as a divisor (`whole / 256`): a camera path
/// streamed at a quarter of the full build holds ~64 units beside the skeleton, and a frame's
/// working set is made of whole units, so coarser units overshoot what the frame's rays touch
/// (island 0.002 at a quarter: 2^16 units, 80–100 MB working sets and 1.48 passes a frame;
/// 8,537, 35 MB and 1.00; BENCHMARKS.md "Units a 256th of the build").
pub const AUTO_UNITS_PER_SCENE: u64 = 256;

/// A 2^16 unit at most this share of the whole build (`whole / 128`) is small enough: the
/// default bound is kept.
pub const AUTO_KEEP_UNITS_PER_SCENE: u64 = 128;

/// The instance records a smaller bound may add, as a share of the whole build (`whole / 16`):
/// splitting a mesh into `c` clusters places each of its instances `c` times.
pub const AUTO_MAX_ADDED_SHARE: u64 = 16;

/// The unique triangles from which [`auto_max_blas_triangles`] is certainly
/// [`DEFAULT_MAX_BLAS_TRIANGLES`] whatever else the scene holds (its estimate of the whole
/// build only grows with instances): an import that has stored this many triangles knows the
/// bound before the scene is parsed.
pub fn auto_bound_settles_at_triangles() -> u64 {
    u64::from(DEFAULT_MAX_BLAS_TRIANGLES) * AUTO_KEEP_UNITS_PER_SCENE
}

/// The partitioner's bound when the user gives none (`motu import` without
/// `--max-blas-triangles`): [`DEFAULT_MAX_BLAS_TRIANGLES`], or less on a scene so small that a
/// 2^16 unit would be a large share of its whole build — the streaming floor holds the largest
/// unit, so that share is what a budget below the full build cannot go under.
///
/// `whole` = unique triangles + [`AUTO_TRIANGLES_PER_INSTANCE`] × instance edges estimates the
/// full build in triangles. When a 2^16 unit is more than a 128th of it, the bound is `whole /
/// 256` (at least [`MIN_AUTO_MAX_BLAS_TRIANGLES`]), doubled while the instance records that
/// splitting adds (each mesh's extra clusters × the paths that place it: a conservative count
/// for `ml`) would cost more than a 16th of the build: heavily instanced meshes are not split
/// (a fractal of one 30k-triangle mesh placed 25k times keeps its one BLAS). On the default
/// `gen island` (521,130 triangles, 13,958 instances) the bound is 4,096 and the floor at 96×64
/// falls from 18% to 8% of the full build, for +8% instances, +0.4% AS bytes and the same traces
/// per ray (BENCHMARKS.md "Partition bound"); scenes over ~8.4M triangle-equivalents keep 2^16.
pub fn auto_max_blas_triangles(scene: &motu_scene::Scene) -> u32 {
    let st = scene.stats();
    let paths = scene.path_counts();
    let placements: Vec<(u32, u64)> = scene
        .prototype_ids()
        .flat_map(|p| {
            let n = paths[p.index()].max(1);
            scene.meshes_of(p).iter().map(move |&m| (m, n))
        })
        .map(|(m, n)| (scene.mesh(m).triangle_count, n))
        .collect();
    auto_bound(st.unique_triangles, st.instances, &placements)
}

/// [`auto_max_blas_triangles`] from the scene's unique triangles, instance edges and each
/// mesh's (triangles, placements).
pub fn auto_bound(unique_triangles: u64, instances: u64, placements: &[(u32, u64)]) -> u32 {
    let cap = DEFAULT_MAX_BLAS_TRIANGLES;
    let whole =
        unique_triangles.saturating_add(instances.saturating_mul(AUTO_TRIANGLES_PER_INSTANCE));
    if whole >= auto_bound_settles_at_triangles() {
        return cap;
    }
    let added = |bound: u32| -> u64 {
        placements
            .iter()
            .map(|&(t, n)| {
                let extra = cluster_count(u64::from(t), bound) - cluster_count(u64::from(t), cap);
                extra.saturating_mul(n)
            })
            .fold(0u64, u64::saturating_add)
    };
    let mut bound = whole
        .div_ceil(AUTO_UNITS_PER_SCENE)
        .clamp(u64::from(MIN_AUTO_MAX_BLAS_TRIANGLES), u64::from(cap)) as u32;
    while bound < cap
        && added(bound).saturating_mul(AUTO_TRIANGLES_PER_INSTANCE) > whole / AUTO_MAX_ADDED_SHARE
    {
        bound = bound.saturating_mul(2).min(cap);
    }
    bound
}

/// One cluster of a partitioned mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct Cluster {
    /// The cluster's own vertices (those its triangles use, renumbered in first-use order) and
    /// triangles; normals and UVs follow the vertices.
    pub data: MeshData,
    /// For each triangle of `data`, its index in the source mesh (ascending).
    pub primitive_map: Vec<u32>,
    pub bounds: Aabb,
}

/// How many clusters [`partition_mesh`] makes for `triangles` (it halves by index).
pub fn cluster_count(triangles: u64, bound: u32) -> u64 {
    let bound = u64::from(bound.max(1));
    if triangles <= bound {
        return 1;
    }
    let half = triangles / 2;
    cluster_count(half, bound as u32) + cluster_count(triangles - half, bound as u32)
}

/// Splits `mesh` into spatial clusters of at most `bound` triangles, calling `emit` for each in
/// spatial order (left half before right half). A mesh within the bound is one cluster.
///
/// O(triangles · log(triangles / bound)) for the median splits (large ranges on two threads),
/// then O(triangles) to list each cluster's triangles in ascending order (one counting pass,
/// no sort); clusters are cut out of the mesh a few at a time in parallel and emitted in order,
/// so at most a batch of clusters is in memory beside the mesh.
pub fn partition_mesh<E>(
    mesh: &MeshData,
    bound: u32,
    emit: &mut dyn FnMut(Cluster) -> Result<(), E>,
) -> Result<(), E> {
    use rayon::prelude::*;
    let tris = mesh.triangle_count();
    let centroid = |t: u32| -> [f32; 3] {
        let i = 3 * t as usize;
        let p = |k: usize| mesh.positions[mesh.indices[i + k] as usize];
        let (a, b, c) = (p(0), p(1), p(2));
        std::array::from_fn(|k| (a[k] + b[k] + c[k]) * (1.0 / 3.0))
    };
    let mut order: Vec<(u32, [f32; 3])> = (0..tris as u32)
        .into_par_iter()
        .map(|t| (t, centroid(t)))
        .collect();
    let mut ranges = Vec::new();
    median_partition(&mut order, |o| o.1, bound.max(1) as usize, &mut ranges);
    // Each triangle's cluster, then every cluster's triangles in ascending order (what
    // sorting each range gave) by one counting pass over the triangles.
    let mut cluster_of_tri = vec![0u32; tris];
    for (k, &(a, b)) in ranges.iter().enumerate() {
        for o in &order[a..b] {
            cluster_of_tri[o.0 as usize] = k as u32;
        }
    }
    drop(order);
    let mut next: Vec<usize> = ranges.iter().map(|&(a, _)| a).collect();
    let mut prims = vec![0u32; tris];
    for (t, &k) in cluster_of_tri.iter().enumerate() {
        prims[next[k as usize]] = t as u32;
        next[k as usize] += 1;
    }
    drop(cluster_of_tri);
    // A vertex map of the source's size per worker (at most `MAX_CUTTERS`), reused.
    let workers = rayon::current_num_threads()
        .clamp(1, MAX_CUTTERS)
        .min(ranges.len());
    let mut remaps: Vec<Vec<u32>> = (0..workers)
        .map(|_| vec![u32::MAX; mesh.positions.len()])
        .collect();
    for group in ranges.chunks(2 * workers) {
        let per = group.len().div_ceil(workers);
        let clusters: Vec<Vec<Cluster>> = remaps
            .par_iter_mut()
            .zip(group.par_chunks(per))
            .map(|(remap, rs)| {
                rs.iter()
                    .map(|&(a, b)| cluster_of(mesh, prims[a..b].to_vec(), remap))
                    .collect()
            })
            .collect();
        for c in clusters.into_iter().flatten() {
            emit(c)?;
        }
    }
    Ok(())
}

/// Clusters cut out of one mesh at once, at most (each worker holds a vertex map of the
/// source mesh's size).
const MAX_CUTTERS: usize = 4;

/// The sub-mesh of `prims` (source triangle ids), its vertices renumbered in first-use order;
/// `remap` is scratch of the source's vertex count, all `u32::MAX` on entry and on return.
fn cluster_of(mesh: &MeshData, prims: Vec<u32>, remap: &mut [u32]) -> Cluster {
    let mut order: Vec<u32> = Vec::new();
    let mut indices = Vec::with_capacity(prims.len() * 3);
    for &t in &prims {
        for k in 0..3 {
            let v = mesh.indices[3 * t as usize + k];
            let slot = &mut remap[v as usize];
            if *slot == u32::MAX {
                *slot = order.len() as u32;
                order.push(v);
            }
            indices.push(*slot);
        }
    }
    let mut bounds = Aabb::EMPTY;
    let positions: Vec<[f32; 3]> = order
        .iter()
        .map(|&v| {
            let p = mesh.positions[v as usize];
            bounds = bounds.union(&Aabb { min: p, max: p });
            p
        })
        .collect();
    let normals = mesh
        .normals
        .as_ref()
        .map(|n| order.iter().map(|&v| n[v as usize]).collect());
    let uvs = mesh
        .uvs
        .as_ref()
        .map(|uv| order.iter().map(|&v| uv[v as usize]).collect());
    for &v in &order {
        remap[v as usize] = u32::MAX;
    }
    Cluster {
        data: MeshData {
            positions,
            normals,
            uvs,
            indices,
        },
        primitive_map: prims,
        bounds,
    }
}

/// One small mesh to group: its index in the caller's list, bounds centre and triangles.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Item {
    pub index: u32,
    pub centre: [f32; 3],
    pub triangles: u64,
}

/// Partitions `items` in place into consecutive groups whose triangle sums are at most
/// `bound` (an item over the bound is a group of its own), appended to `out` as `(begin, end)`
/// in spatial order: recursive splits at the triangle-weighted median along the largest axis
/// of the centres. Terminates on any input: each split leaves both sides non-empty.
pub(crate) fn group_by_location(items: &mut [Item], bound: u64, out: &mut Vec<(usize, usize)>) {
    let mut stack = vec![(0usize, items.len())];
    while let Some((begin, end)) = stack.pop() {
        let slice = &mut items[begin..end];
        let total: u64 = slice.iter().map(|i| i.triangles).sum();
        if slice.is_empty() {
            continue;
        }
        if total <= bound || slice.len() == 1 {
            out.push((begin, end));
            continue;
        }
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for it in slice.iter() {
            for k in 0..3 {
                lo[k] = lo[k].min(it.centre[k]);
                hi[k] = hi[k].max(it.centre[k]);
            }
        }
        let extent: [f32; 3] = std::array::from_fn(|k| hi[k] - lo[k]);
        let axis = (0..3)
            .filter(|&k| extent[k].is_finite())
            .max_by(|&a, &b| extent[a].total_cmp(&extent[b]))
            .unwrap_or(0);
        // Stable, so coincident centres keep the caller's (mesh) order: deterministic groups.
        slice.sort_by(|a, b| a.centre[axis].total_cmp(&b.centre[axis]));
        // The first item whose prefix sum reaches half the total goes to whichever side
        // leaves the heavier side lighter.
        let mut acc = 0u64;
        let mut mid = slice.len() / 2;
        for (k, it) in slice.iter().enumerate() {
            acc += it.triangles;
            if 2 * acc >= total {
                let before = acc - it.triangles;
                mid = if before.max(total - before) < acc.max(total - acc) {
                    k
                } else {
                    k + 1
                };
                break;
            }
        }
        let mid = mid.clamp(1, slice.len() - 1);
        // Right first so the left half is popped (and emitted) first.
        stack.push((begin + mid, end));
        stack.push((begin, begin + mid));
    }
}

#[cfg(test)]
mod tests;
