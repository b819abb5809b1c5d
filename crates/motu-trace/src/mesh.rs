//! Mesh geometry access (implemented by the caller, e.g. the package reader over mapped chunks)
//! and the per-mesh triangle BVH.

use crate::bvh::{Aabb, BuildParams, Bvh, BvhNode};
use crate::ray::LocalRay;

/// One compiled mesh's geometry in its own space.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshGeometry {
    pub positions: Vec<[f32; 3]>,
    /// Three per triangle.
    pub indices: Vec<u32>,
    pub normals: Option<Vec<[f32; 3]>>,
    /// A cluster of a partitioned mesh (`FLAG_PRIMITIVE_MAP`): each triangle's index in the
    /// source mesh, which hits report instead of the cluster's own index.
    pub primitive_map: Option<Vec<u32>>,
    /// Per-vertex texture coordinates.
    pub uvs: Option<Vec<[f32; 2]>>,
}

/// Loads the geometry of a compiled mesh, by its index in the hierarchy's mesh table.
/// Called at most once per mesh per [`crate::Tracer`], possibly from several threads.
pub trait MeshSource: Sync {
    fn load(&self, mesh_record: u32) -> Result<MeshGeometry, LoadError>;
}

/// Why a [`MeshSource`] could not load a mesh: the source's own error, kept as the cause.
pub type LoadError = Box<dyn std::error::Error + Send + Sync>;

/// A triangle BVH with the triangles copied in leaf order (9 floats each) so a leaf reads one
/// contiguous run.
#[derive(Clone, Debug)]
pub struct MeshBvh {
    pub nodes: Vec<BvhNode>,
    /// Vertices of triangle slot `i`: `tri_verts[i]`.
    pub tri_verts: Vec<[[f32; 3]; 3]>,
    /// The triangle index within the mesh of slot `i` (within the source mesh for a cluster).
    pub tri_prim: Vec<u32>,
    /// The triangle index within this compiled mesh of slot `i` (differs from `tri_prim` for
    /// a cluster, whose hits report source primitives): what shading reads attributes by.
    pub tri_local: Vec<u32>,
    /// Per-vertex attributes for shading (kept only when the mesh has some).
    pub attributes: Option<Box<VertexAttributes>>,
    pub bounds: Aabb,
}

/// What shading interpolates: the mesh's indices with its per-vertex normals and texture
/// coordinates (in the mesh's space).
#[derive(Clone, Debug, Default)]
pub struct VertexAttributes {
    pub indices: Vec<u32>,
    pub normals: Option<Vec<[f32; 3]>>,
    pub uvs: Option<Vec<[f32; 2]>>,
}

/// Why a mesh could not be used.
#[derive(Debug, Clone, thiserror::Error)]
pub enum MeshError {
    #[error("loading failed: {0}")]
    Load(String),
    /// The mesh source failed (shared: the tracer hands a mesh's one failure to every ray
    /// that needs it).
    #[error("loading failed: {0}")]
    Source(#[source] std::sync::Arc<dyn std::error::Error + Send + Sync>),
    #[error("index count {0} is not a multiple of 3")]
    IndexCount(usize),
    #[error("triangle {triangle} uses vertex {index} of {vertex_count}")]
    IndexRange {
        triangle: usize,
        index: u32,
        vertex_count: usize,
    },
    #[error("vertex {0} is not finite")]
    NotFinite(usize),
    #[error("primitive map has {got} entries for {triangles} triangles")]
    PrimitiveMap { got: usize, triangles: usize },
    #[error("geometry bounds {actual:?} exceed the mesh record's bounds {record:?}")]
    Bounds { actual: Aabb, record: Aabb },
}

impl MeshBvh {
    /// Validates `g` and builds its BVH. `record_bounds`, when given, must contain the geometry
    /// (TLAS and BLAS boxes are derived from mesh records, so a record that lies would make the
    /// oracle miss hits the GPU finds).
    pub fn build(
        g: &MeshGeometry,
        record_bounds: Option<Aabb>,
        params: BuildParams,
    ) -> Result<Self, MeshError> {
        if g.indices.len() % 3 != 0 {
            return Err(MeshError::IndexCount(g.indices.len()));
        }
        if let Some(i) = g
            .positions
            .iter()
            .position(|p| !p.iter().all(|v| v.is_finite()))
        {
            return Err(MeshError::NotFinite(i));
        }
        let tri_count = g.indices.len() / 3;
        if let Some(map) = &g.primitive_map {
            if map.len() != tri_count {
                return Err(MeshError::PrimitiveMap {
                    got: map.len(),
                    triangles: tri_count,
                });
            }
        }
        let mut verts = Vec::with_capacity(tri_count);
        let mut boxes = Vec::with_capacity(tri_count);
        for (t, tri) in g.indices.chunks_exact(3).enumerate() {
            let mut v = [[0.0f32; 3]; 3];
            let mut b = Aabb::EMPTY;
            for k in 0..3 {
                let p = *g
                    .positions
                    .get(tri[k] as usize)
                    .ok_or(MeshError::IndexRange {
                        triangle: t,
                        index: tri[k],
                        vertex_count: g.positions.len(),
                    })?;
                v[k] = p;
                b.grow_point(p);
            }
            verts.push(v);
            boxes.push(b);
        }
        let bvh = Bvh::build(&boxes, params);
        let bounds = bvh.bounds();
        if let Some(record) = record_bounds {
            let mag = (0..3)
                .map(|a| record.min[a].abs().max(record.max[a].abs()))
                .fold(0.0f32, f32::max);
            if !bounds.is_empty() && !record.contains(&bounds, 1e-5 * mag.max(1.0)) {
                return Err(MeshError::Bounds {
                    actual: bounds,
                    record,
                });
            }
        }
        let nv = g.positions.len();
        let normals = g.normals.clone().filter(|n| n.len() == nv);
        let uvs = g.uvs.clone().filter(|u| u.len() == nv);
        let attributes = (normals.is_some() || uvs.is_some()).then(|| {
            Box::new(VertexAttributes {
                indices: g.indices.clone(),
                normals,
                uvs,
            })
        });
        Ok(Self {
            tri_verts: bvh.order.iter().map(|&i| verts[i as usize]).collect(),
            tri_prim: match &g.primitive_map {
                Some(map) => bvh.order.iter().map(|&i| map[i as usize]).collect(),
                None => bvh.order.clone(),
            },
            tri_local: bvh.order,
            attributes,
            nodes: bvh.nodes,
            bounds,
        })
    }

    /// Closest hit in `(t_min, *t_max)`: shrinks `t_max` and returns the triangle slot.
    /// With `any_hit`, returns at the first hit found. `stack` is scratch.
    #[inline]
    pub fn intersect(
        &self,
        ray: &LocalRay,
        t_min: f32,
        t_max: &mut f32,
        any_hit: bool,
        stack: &mut Vec<u32>,
    ) -> Option<u32> {
        self.intersect_filtered(ray, t_min, t_max, any_hit, stack, None)
    }

    /// [`MeshBvh::intersect`] where `accept(slot, barycentrics)` may reject a candidate hit
    /// (alpha cut-outs: the GPU's any-hit test), so traversal looks past it.
    #[inline]
    pub fn intersect_filtered(
        &self,
        ray: &LocalRay,
        t_min: f32,
        t_max: &mut f32,
        any_hit: bool,
        stack: &mut Vec<u32>,
        accept: Option<&dyn Fn(u32, [f32; 3]) -> bool>,
    ) -> Option<u32> {
        let root = self.nodes.first()?;
        ray.hit_box(&root.min, &root.max, t_min, *t_max)?;
        let mut found = None;
        stack.clear();
        let mut node = 0u32;
        loop {
            let n = self.nodes[node as usize];
            if n.is_leaf() {
                for slot in n.first..n.first + n.count {
                    let [v0, v1, v2] = self.tri_verts[slot as usize];
                    if let Some((t, b)) = ray.hit_triangle_bary(v0, v1, v2, t_min, *t_max) {
                        if accept.is_some_and(|f| !f(slot, b)) {
                            continue;
                        }
                        *t_max = t;
                        found = Some(slot);
                        if any_hit {
                            return found;
                        }
                    }
                }
            } else {
                let (a, b) = (n.first, n.first + 1);
                let na = &self.nodes[a as usize];
                let nb = &self.nodes[b as usize];
                let ha = ray.hit_box(&na.min, &na.max, t_min, *t_max);
                let hb = ray.hit_box(&nb.min, &nb.max, t_min, *t_max);
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
            // Pop until a node still in reach (t_max may have shrunk since the push).
            loop {
                let Some(next) = stack.pop() else {
                    return found;
                };
                let nn = &self.nodes[next as usize];
                if ray.hit_box(&nn.min, &nn.max, t_min, *t_max).is_some() {
                    node = next;
                    break;
                }
            }
        }
    }

    /// Geometric normal (unnormalised, mesh space, winding `v0 → v1 → v2`) of a slot.
    pub fn geometric_normal(&self, slot: u32) -> [f32; 3] {
        let [v0, v1, v2] = self.tri_verts[slot as usize];
        crate::ray::cross(crate::ray::sub(v1, v0), crate::ray::sub(v2, v0))
    }
}

#[cfg(test)]
mod tests;
