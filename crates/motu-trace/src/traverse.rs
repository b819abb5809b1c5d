//! The multi-level traversal: TLAS → instance → BLAS → triangles, or → programmable instance →
//! child TLAS / LOD selector, with an explicit level stack and the GPU's closest-hit semantics.

use std::sync::OnceLock;

use motu_abi::lod::{select_lod, LodParams, RAY_PRIMARY};
use motu_abi::{
    xform_vector, HierarchyView, BLAS_TRIANGLES, FLAG_NEEDS_ANY_HIT, NONE_U32, PI_LOD_SELECTOR,
    PI_TLAS,
};
use rayon::prelude::*;

use crate::bvh::{Aabb, BuildParams, Bvh, BvhNode};
use crate::mesh::{MeshBvh, MeshError, MeshSource};
use crate::ray::{compose, invert, length, normalize, transpose_vector, LocalRay, IDENTITY_3X4};
use crate::TraceError;

/// What one ray asks of the traversal.
#[derive(Clone, Copy, Debug)]
pub struct RayQuery {
    /// `motu_abi::lod::RAY_PRIMARY` or `RAY_SHADOW` (LOD bias).
    pub kind: u32,
    /// Hits at `t <= t_min` are ignored (0 for primary rays; see the crate docs).
    pub t_min: f32,
    pub t_max: f32,
    /// Stop at the first hit found (shadow rays), like `gl_RayFlagsTerminateOnFirstHitEXT`.
    pub any_hit: bool,
    /// LOD rule inputs, including `forced_lod`.
    pub lod: LodParams,
    /// From `CameraParams::pixels_per_unit_at_1`.
    pub pixels_per_unit_at_1: f32,
    /// Uniform number in [0, 1) for stochastic LOD.
    pub lod_u: f32,
    /// TLAS walks this ray may make before it is cut short ([`Hit::truncated`]), like the
    /// GPU's `MAX_TRACES_PER_RAY`.
    pub max_traces: u32,
}

impl Default for RayQuery {
    fn default() -> Self {
        Self {
            kind: RAY_PRIMARY,
            t_min: 0.0,
            t_max: f32::INFINITY,
            any_hit: false,
            lod: LodParams::default(),
            pixels_per_unit_at_1: 1.0,
            lod_u: 0.0,
            max_traces: motu_abi::DEFAULT_MAX_TRACES_PER_RAY,
        }
    }
}

/// The closest hit (or a miss) of one ray, plus what it cost.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// World-space distance along the unit world direction; `INFINITY` on a miss.
    pub t: f32,
    /// Index into the hierarchy's mesh table, `NONE_U32` on a miss.
    pub mesh_record: u32,
    /// `MeshRecord::source_mesh` of the hit mesh.
    pub source_mesh: u32,
    /// Triangle index reported for the hit: within the source mesh (a cluster's primitive map
    /// applied).
    pub primitive: u32,
    /// The hit triangle's BVH slot in the hit compiled mesh (`MeshBvh::tri_verts`,
    /// `tri_local`): how shading finds the triangle's attributes.
    pub slot: u32,
    /// The level chosen by the innermost LOD selector on the path, else `MeshRecord::lod`.
    pub lod: u32,
    /// Composed transform from world into the hit mesh's space.
    pub object_from_world: [f32; 12],
    /// Geometric normal in mesh space (unnormalised, winding order).
    pub object_normal: [f32; 3],
    /// TLAS walks (one per `traceRayEXT` / ray query on the GPU).
    pub traces: u32,
    /// Deepest the level stack got for this ray.
    pub max_stack: u32,
    /// The walk was cut short at `RayQuery::max_traces`: the hit may not be the closest.
    pub truncated: bool,
}

impl Hit {
    pub const MISS: Self = Self {
        t: f32::INFINITY,
        mesh_record: NONE_U32,
        source_mesh: NONE_U32,
        primitive: 0,
        slot: 0,
        lod: 0,
        object_from_world: IDENTITY_3X4,
        object_normal: [0.0, 0.0, 1.0],
        traces: 0,
        max_stack: 0,
        truncated: false,
    };

    pub fn is_hit(&self) -> bool {
        self.mesh_record != NONE_U32
    }

    /// Unit geometric normal in world space (`object_from_worldᵀ n`: the inverse transpose of
    /// `world_from_object` without inverting), not face-forwarded.
    pub fn world_normal(&self) -> [f32; 3] {
        normalize(transpose_vector(
            &self.object_from_world,
            self.object_normal,
        ))
    }
}

/// One pending TLAS walk: the GPU's traversal payload.
#[derive(Clone, Copy, Debug)]
struct Entry {
    tlas_from_world: [f32; 12],
    t_near: f32,
    tlas: u32,
    /// Level of the innermost selector on the path, `NONE_U32` if none.
    lod: u32,
}

/// Per-thread scratch so no ray allocates; reuse one per worker.
#[derive(Debug, Default)]
pub struct Scratch {
    tlas_stack: Vec<u32>,
    blas_stack: Vec<u32>,
    mesh_stack: Vec<u32>,
    levels: Vec<Entry>,
    candidates: Vec<Entry>,
}

struct TlasAccel {
    bvh: Bvh,
    /// Per instance of the TLAS (local index), the inverse of `tlas_from_blas`.
    blas_from_tlas: Vec<[f32; 12]>,
}

/// The traversal state over one hierarchy: validated tables plus lazily built acceleration
/// structures (each mesh, TLAS and BLAS built once, on first touch or in [`Tracer::prepare`]).
pub struct Tracer<'a> {
    view: HierarchyView<'a>,
    source: &'a dyn MeshSource,
    /// Per BLAS, the boxes of its items (mesh record bounds or PI AABBs).
    blas_bounds: Vec<Aabb>,
    meshes: Vec<OnceLock<Result<MeshBvh, MeshError>>>,
    tlas_accels: Vec<OnceLock<TlasAccel>>,
    blas_accels: Vec<OnceLock<Bvh>>,
}

impl std::fmt::Debug for Tracer<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Tracer")
            .field("tlases", &self.view.tlases.len())
            .field("blases", &self.view.blases.len())
            .field("meshes", &self.view.meshes.len())
            .finish()
    }
}

fn record_box(min: [f32; 3], max: [f32; 3]) -> Aabb {
    let b = Aabb::new(min, max);
    if (0..3).all(|a| min[a].is_finite() && max[a].is_finite()) {
        b
    } else {
        Aabb::EMPTY
    }
}

impl<'a> Tracer<'a> {
    /// Checks every reference and that the hierarchy is acyclic, so traversal cannot index out
    /// of range or loop.
    pub fn new(view: HierarchyView<'a>, source: &'a dyn MeshSource) -> Result<Self, TraceError> {
        view.check_references()?;
        check_acyclic(&view)?;
        let blas_bounds = view
            .blases
            .iter()
            .map(|b| {
                let (base, n) = (b.item_base as usize, b.item_count as usize);
                if b.kind == BLAS_TRIANGLES {
                    view.geometries[base..base + n]
                        .iter()
                        .map(|g| {
                            let m = &view.meshes[g.mesh as usize];
                            record_box(m.bounds_min, m.bounds_max)
                        })
                        .fold(Aabb::EMPTY, |a, b| a.union(&b))
                } else {
                    view.pis[base..base + n]
                        .iter()
                        .map(|p| record_box(p.aabb_min, p.aabb_max))
                        .fold(Aabb::EMPTY, |a, b| a.union(&b))
                }
            })
            .collect();
        Ok(Self {
            view,
            source,
            blas_bounds,
            meshes: (0..view.meshes.len()).map(|_| OnceLock::new()).collect(),
            tlas_accels: (0..view.tlases.len()).map(|_| OnceLock::new()).collect(),
            blas_accels: (0..view.blases.len()).map(|_| OnceLock::new()).collect(),
        })
    }

    pub fn view(&self) -> &HierarchyView<'a> {
        &self.view
    }

    /// Builds every acceleration structure reachable from the root (all LOD levels), in
    /// parallel. Optional: traversal builds what it touches (serially) otherwise. Do not call
    /// it from inside a rayon job that also traces with this tracer.
    pub fn prepare(&self) -> Result<(), TraceError> {
        let _span = tracing::info_span!("prepare").entered();
        let (tlases, blases, meshes) = reachable(&self.view);
        let par = BuildParams::default();
        meshes.par_iter().for_each(|&m| {
            self.meshes[m as usize].get_or_init(|| self.load_mesh(m, par));
        });
        blases.par_iter().for_each(|&b| {
            self.blas_accels[b as usize].get_or_init(|| self.build_blas(b, par));
        });
        tlases.par_iter().for_each(|&t| {
            self.tlas_accels[t as usize].get_or_init(|| self.build_tlas(t, par));
        });
        tracing::info!(
            tlases = tlases.len(),
            blases = blases.len(),
            meshes = meshes.len(),
            "acceleration structures ready"
        );
        self.first_error()
    }

    /// The first mesh that failed to load or validate, if any (failed meshes trace as empty).
    pub fn first_error(&self) -> Result<(), TraceError> {
        for (i, m) in self.meshes.iter().enumerate() {
            if let Some(Err(e)) = m.get() {
                return Err(TraceError::Mesh {
                    mesh: i as u32,
                    source: e.clone(),
                });
            }
        }
        Ok(())
    }

    /// Meshes whose BVH is built.
    pub fn meshes_built(&self) -> usize {
        self.meshes
            .iter()
            .filter(|m| matches!(m.get(), Some(Ok(_))))
            .count()
    }

    fn load_mesh(&self, m: u32, params: BuildParams) -> Result<MeshBvh, MeshError> {
        let rec = &self.view.meshes[m as usize];
        let g = self
            .source
            .load(m)
            .map_err(|e| MeshError::Source(e.into()))?;
        if g.indices.len() / 3 != rec.triangle_count as usize {
            tracing::warn!(
                mesh = m,
                record = rec.triangle_count,
                loaded = g.indices.len() / 3,
                "triangle count differs from the mesh record"
            );
        }
        // A cluster's hits name source primitives: without its map they would be wrong.
        if (rec.flags & motu_abi::FLAG_PRIMITIVE_MAP != 0) != g.primitive_map.is_some() {
            return Err(MeshError::Load(format!(
                "mesh record {m}: the record {} a primitive map, the loaded mesh {}",
                if rec.flags & motu_abi::FLAG_PRIMITIVE_MAP != 0 {
                    "has"
                } else {
                    "has no"
                },
                if g.primitive_map.is_some() {
                    "has one"
                } else {
                    "has none"
                }
            )));
        }
        MeshBvh::build(&g, Some(record_box(rec.bounds_min, rec.bounds_max)), params)
    }

    /// Mesh record `m`'s triangles and shading attributes (loaded on first use); `None`
    /// when it failed to load (reported by [`Tracer::first_error`]).
    pub fn mesh_bvh(&self, m: u32) -> Option<&MeshBvh> {
        self.mesh(m)
    }

    fn mesh(&self, m: u32) -> Option<&MeshBvh> {
        self.meshes[m as usize]
            .get_or_init(|| self.load_mesh(m, BuildParams::default().serial()))
            .as_ref()
            .ok()
    }

    fn build_blas(&self, b: u32, params: BuildParams) -> Bvh {
        let blas = &self.view.blases[b as usize];
        let (base, n) = (blas.item_base as usize, blas.item_count as usize);
        let boxes: Vec<Aabb> = if blas.kind == BLAS_TRIANGLES {
            self.view.geometries[base..base + n]
                .iter()
                .map(|g| {
                    let m = &self.view.meshes[g.mesh as usize];
                    record_box(m.bounds_min, m.bounds_max)
                })
                .collect()
        } else {
            self.view.pis[base..base + n]
                .iter()
                .map(|p| record_box(p.aabb_min, p.aabb_max))
                .collect()
        };
        Bvh::build(
            &boxes,
            BuildParams {
                max_leaf: 2,
                ..params
            },
        )
    }

    fn blas_accel(&self, b: u32) -> &Bvh {
        self.blas_accels[b as usize]
            .get_or_init(|| self.build_blas(b, BuildParams::default().serial()))
    }

    fn build_tlas(&self, t: u32, params: BuildParams) -> TlasAccel {
        let tlas = &self.view.tlases[t as usize];
        let insts = &self.view.instances[tlas.instance_range()];
        let mut boxes = Vec::with_capacity(insts.len());
        let mut blas_from_tlas = Vec::with_capacity(insts.len());
        for inst in insts {
            match invert(&inst.tlas_from_blas) {
                Some(inv) => {
                    // Padded: the box of transformed corners must stay conservative in f32.
                    boxes.push(
                        self.blas_bounds[inst.blas as usize]
                            .transformed(&inst.tlas_from_blas)
                            .padded(1e-6),
                    );
                    blas_from_tlas.push(inv);
                }
                None => {
                    // A singular instance has no volume: it can never be hit.
                    boxes.push(Aabb::EMPTY);
                    blas_from_tlas.push(IDENTITY_3X4);
                }
            }
        }
        TlasAccel {
            bvh: Bvh::build(
                &boxes,
                BuildParams {
                    max_leaf: 2,
                    ..params
                },
            ),
            blas_from_tlas,
        }
    }

    fn tlas_accel(&self, t: u32) -> &TlasAccel {
        self.tlas_accels[t as usize]
            .get_or_init(|| self.build_tlas(t, BuildParams::default().serial()))
    }

    /// Traces one world ray (`dir` is normalised here, so `t` is a world distance).
    pub fn trace(
        &self,
        world_org: [f32; 3],
        world_dir: [f32; 3],
        q: &RayQuery,
        scratch: &mut Scratch,
    ) -> Hit {
        let world = LocalRay::new(world_org, normalize(world_dir));
        let mut hit = Hit::MISS;
        let mut best_t = q.t_max;
        let Scratch {
            tlas_stack,
            blas_stack,
            mesh_stack,
            levels,
            candidates,
        } = scratch;
        levels.clear();
        levels.push(Entry {
            tlas_from_world: IDENTITY_3X4,
            t_near: q.t_min,
            tlas: self.view.root_tlas,
            lod: NONE_U32,
        });
        let mut max_stack = 1usize;
        let mut traces = 0u32;
        let mut truncated = false;
        let v = &self.view;
        while let Some(e) = levels.pop() {
            // A payload that cannot beat the best hit is skipped without a trace (GPU rule).
            if e.t_near >= best_t {
                continue;
            }
            if traces >= q.max_traces {
                truncated = true;
                break;
            }
            traces += 1;
            let tlas_ray = world.transformed(&e.tlas_from_world);
            let accel = self.tlas_accel(e.tlas);
            let inst_base = v.tlases[e.tlas as usize].instance_base as usize;
            candidates.clear();
            let stop = walk(
                &accel.bvh,
                &tlas_ray,
                q.t_min,
                &mut best_t,
                tlas_stack,
                |local, best_t| {
                    let inst = &v.instances[inst_base + local as usize];
                    let blas_from_tlas = &accel.blas_from_tlas[local as usize];
                    let blas_ray = tlas_ray.transformed(blas_from_tlas);
                    let blas = &v.blases[inst.blas as usize];
                    let items = blas.item_base as usize;
                    let triangles = blas.kind == BLAS_TRIANGLES;
                    walk(
                        self.blas_accel(inst.blas),
                        &blas_ray,
                        q.t_min,
                        best_t,
                        blas_stack,
                        |j, best_t| {
                            let item = items + j as usize;
                            if triangles {
                                let mesh_record = v.geometries[item].mesh;
                                let Some(mesh) = self.mesh(mesh_record) else {
                                    return false;
                                };
                                let rec = &v.meshes[mesh_record as usize];
                                // Alpha-tested meshes: the GPU's any-hit coverage test.
                                let alpha = |slot: u32, b: [f32; 3]| {
                                    crate::coverage::coverage(v, mesh, rec, slot, b)
                                        >= motu_abi::shade::ALPHA_CUTOFF
                                };
                                let accept: Option<&dyn Fn(u32, [f32; 3]) -> bool> =
                                    if rec.flags & FLAG_NEEDS_ANY_HIT != 0 {
                                        Some(&alpha)
                                    } else {
                                        None
                                    };
                                let Some(slot) = mesh.intersect_filtered(
                                    &blas_ray, q.t_min, best_t, q.any_hit, mesh_stack, accept,
                                ) else {
                                    return false;
                                };
                                hit = Hit {
                                    t: *best_t,
                                    mesh_record,
                                    source_mesh: rec.source_mesh,
                                    primitive: mesh.tri_prim[slot as usize],
                                    slot,
                                    lod: if e.lod == NONE_U32 { rec.lod } else { e.lod },
                                    object_from_world: compose(blas_from_tlas, &e.tlas_from_world),
                                    object_normal: mesh.geometric_normal(slot),
                                    traces: 0,
                                    max_stack: 0,
                                    truncated: false,
                                };
                                return q.any_hit;
                            }
                            let pi = &v.pis[item];
                            let Some(t_near) =
                                blas_ray.hit_box(&pi.aabb_min, &pi.aabb_max, q.t_min, *best_t)
                            else {
                                return false;
                            };
                            let child_from_world = compose(
                                &pi.child_from_parent,
                                &compose(blas_from_tlas, &e.tlas_from_world),
                            );
                            let (tlas, lod) = match pi.kind {
                                PI_TLAS => (pi.target, e.lod),
                                PI_LOD_SELECTOR => {
                                    let sel = &v.lod_selectors[pi.target as usize];
                                    let dir_len =
                                        length(xform_vector(&child_from_world, world.dir));
                                    let level = select_lod(
                                        &q.lod,
                                        q.pixels_per_unit_at_1,
                                        sel.radius,
                                        dir_len,
                                        t_near,
                                        sel.level_count,
                                        q.kind,
                                        q.lod_u,
                                    );
                                    (v.lod_levels[(sel.level_base + level) as usize], level)
                                }
                                // Unreachable after `check_references`.
                                _ => return false,
                            };
                            candidates.push(Entry {
                                tlas_from_world: child_from_world,
                                t_near,
                                tlas,
                                lod,
                            });
                            false
                        },
                    )
                },
            );
            if stop {
                break;
            }
            // Near-to-far: push the farthest first so the nearest pops next.
            candidates.sort_unstable_by(|a, b| b.t_near.total_cmp(&a.t_near));
            levels.extend(candidates.iter().filter(|c| c.t_near < best_t).copied());
            max_stack = max_stack.max(levels.len());
        }
        hit.traces = traces;
        hit.max_stack = max_stack as u32;
        hit.truncated = truncated;
        hit
    }
}

/// Walks a BVH near-to-far, calling `item(index, t_max)` for each item of every reached
/// leaf; `item` may shrink `t_max` and returns `true` to stop. Returns whether it stopped.
#[inline]
fn walk(
    bvh: &Bvh,
    ray: &LocalRay,
    t_min: f32,
    t_max: &mut f32,
    stack: &mut Vec<u32>,
    mut item: impl FnMut(u32, &mut f32) -> bool,
) -> bool {
    let nodes: &[BvhNode] = &bvh.nodes;
    let Some(root) = nodes.first() else {
        return false;
    };
    if ray.hit_box(&root.min, &root.max, t_min, *t_max).is_none() {
        return false;
    }
    stack.clear();
    let mut node = 0u32;
    loop {
        let n = nodes[node as usize];
        if n.is_leaf() {
            for slot in n.first..n.first + n.count {
                if item(bvh.order[slot as usize], t_max) {
                    return true;
                }
            }
        } else {
            let (a, b) = (n.first, n.first + 1);
            let ha = ray.hit_box(
                &nodes[a as usize].min,
                &nodes[a as usize].max,
                t_min,
                *t_max,
            );
            let hb = ray.hit_box(
                &nodes[b as usize].min,
                &nodes[b as usize].max,
                t_min,
                *t_max,
            );
            match (ha, hb) {
                (Some(ta), Some(tb)) => {
                    let (near, far) = if ta <= tb { (a, b) } else { (b, a) };
                    stack.push(far);
                    node = near;
                    continue;
                }
                (Some(_), None) => {
                    node = a;
                    continue;
                }
                (None, Some(_)) => {
                    node = b;
                    continue;
                }
                (None, None) => {}
            }
        }
        loop {
            let Some(next) = stack.pop() else {
                return false;
            };
            let nn = &nodes[next as usize];
            if ray.hit_box(&nn.min, &nn.max, t_min, *t_max).is_some() {
                node = next;
                break;
            }
        }
    }
}

/// TLASes, BLASes and meshes reachable from the root (every LOD level included).
fn reachable(v: &HierarchyView<'_>) -> (Vec<u32>, Vec<u32>, Vec<u32>) {
    let mut seen_t = vec![false; v.tlases.len()];
    let mut seen_b = vec![false; v.blases.len()];
    let mut seen_m = vec![false; v.meshes.len()];
    let mut todo = vec![v.root_tlas];
    seen_t[v.root_tlas as usize] = true;
    while let Some(t) = todo.pop() {
        for child in tlas_children(v, t, &mut seen_b, &mut seen_m) {
            if !std::mem::replace(&mut seen_t[child as usize], true) {
                todo.push(child);
            }
        }
    }
    let ids = |s: Vec<bool>| {
        s.iter()
            .enumerate()
            .filter(|(_, &b)| b)
            .map(|(i, _)| i as u32)
            .collect::<Vec<u32>>()
    };
    (ids(seen_t), ids(seen_b), ids(seen_m))
}

/// TLASes one PI away from TLAS `t`; marks the BLASes and meshes met on the way.
fn tlas_children(
    v: &HierarchyView<'_>,
    t: u32,
    seen_b: &mut [bool],
    seen_m: &mut [bool],
) -> Vec<u32> {
    let mut out = Vec::new();
    let tl = &v.tlases[t as usize];
    for inst in &v.instances[tl.instance_range()] {
        let b = &v.blases[inst.blas as usize];
        let first_visit = !std::mem::replace(&mut seen_b[inst.blas as usize], true);
        let (base, n) = (b.item_base as usize, b.item_count as usize);
        if b.kind == BLAS_TRIANGLES {
            if first_visit {
                for g in &v.geometries[base..base + n] {
                    seen_m[g.mesh as usize] = true;
                }
            }
            continue;
        }
        for p in &v.pis[base..base + n] {
            if p.kind == PI_TLAS {
                out.push(p.target);
            } else if p.kind == PI_LOD_SELECTOR {
                let s = &v.lod_selectors[p.target as usize];
                out.extend_from_slice(
                    &v.lod_levels[s.level_base as usize..(s.level_base + s.level_count) as usize],
                );
            }
        }
    }
    out.sort_unstable();
    out.dedup();
    out
}

/// Rejects a PI path that leads back to a TLAS already on it (traversal would never end).
fn check_acyclic(v: &HierarchyView<'_>) -> Result<(), TraceError> {
    // 0 = unvisited, 1 = on the DFS path, 2 = done.
    let mut state = vec![0u8; v.tlases.len()];
    let mut seen_b = vec![false; v.blases.len()];
    let mut seen_m = vec![false; v.meshes.len()];
    let mut children: Vec<Option<Vec<u32>>> = vec![None; v.tlases.len()];
    for start in 0..v.tlases.len() as u32 {
        if state[start as usize] != 0 {
            continue;
        }
        let mut path: Vec<(u32, usize)> = vec![(start, 0)];
        state[start as usize] = 1;
        while let Some(&mut (t, ref mut next)) = path.last_mut() {
            let kids = children[t as usize]
                .get_or_insert_with(|| tlas_children(v, t, &mut seen_b, &mut seen_m));
            if let Some(&c) = kids.get(*next) {
                *next += 1;
                match state[c as usize] {
                    0 => {
                        state[c as usize] = 1;
                        path.push((c, 0));
                    }
                    1 => return Err(TraceError::Cycle { tlas: c }),
                    _ => {}
                }
            } else {
                state[t as usize] = 2;
                children[t as usize] = None;
                path.pop();
            }
        }
    }
    Ok(())
}
