//! Hand-built hierarchies and a brute-force reference, for tests here and in other crates
//! (e.g. GPU tests that need a hierarchy without running the compiler).
//!
//! [`HierarchyBuilder`] creates the tables bottom-up, computing bounds, PI boxes and selector
//! spheres the way a compiler must; [`BruteForce`] flattens a hierarchy to world triangles
//! (in f64, independently of the traversal's matrix code) and intersects every one.
//! These are test helpers: they panic on programming errors (a singular PI transform).

use motu_abi::*;

use crate::bvh::Aabb;
use crate::mesh::{MeshGeometry, MeshSource};

/// All tables owned, plus the mesh geometry (so it is its own [`MeshSource`]).
#[derive(Clone, Debug, Default)]
pub struct OwnedHierarchy {
    pub root_tlas: u32,
    pub tlases: Vec<TlasRecord>,
    pub instances: Vec<InstanceRecord>,
    pub blases: Vec<BlasRecord>,
    pub geometries: Vec<GeometryRecord>,
    pub pis: Vec<PiRecord>,
    pub lod_selectors: Vec<LodSelectorRecord>,
    pub lod_levels: Vec<u32>,
    pub meshes: Vec<MeshRecord>,
    pub materials: Vec<MaterialRecord>,
    pub textures: Vec<motu_abi::TextureRecord>,
    pub texels: Vec<u32>,
    /// Geometry of mesh record `i`.
    pub geometry: Vec<MeshGeometry>,
}

impl OwnedHierarchy {
    pub fn view(&self) -> HierarchyView<'_> {
        HierarchyView {
            root_tlas: self.root_tlas,
            tlases: &self.tlases,
            instances: &self.instances,
            blases: &self.blases,
            geometries: &self.geometries,
            pis: &self.pis,
            lod_selectors: &self.lod_selectors,
            lod_levels: &self.lod_levels,
            meshes: &self.meshes,
            materials: &self.materials,
            textures: &self.textures,
            texels: &self.texels,
        }
    }
}

impl MeshSource for OwnedHierarchy {
    fn load(&self, mesh_record: u32) -> Result<MeshGeometry, crate::LoadError> {
        self.geometry
            .get(mesh_record as usize)
            .cloned()
            .ok_or_else(|| format!("no geometry for mesh record {mesh_record}").into())
    }
}

/// Where a programmable instance continues.
#[derive(Clone, Copy, Debug)]
pub enum PiTarget {
    Tlas(u32),
    LodSelector(u32),
}

/// Builds an [`OwnedHierarchy`] bottom-up.
#[derive(Debug, Default)]
pub struct HierarchyBuilder {
    h: OwnedHierarchy,
    tlas_bounds: Vec<Aabb>,
    blas_bounds: Vec<Aabb>,
    selector_bounds: Vec<Aabb>,
    /// The `(parent_from_child, target)` list of every PI BLAS, by BLAS id.
    pi_sources: std::collections::HashMap<u32, Vec<([f32; 12], PiTarget)>>,
}

impl HierarchyBuilder {
    /// Starts with material 0 (light grey).
    pub fn new() -> Self {
        let mut b = Self::default();
        b.material([0.8, 0.8, 0.8]);
        b
    }

    pub fn material(&mut self, base_color: [f32; 3]) -> u32 {
        self.h.materials.push(MaterialRecord {
            base_color,
            opacity: 1.0,
            ..MaterialRecord::default()
        });
        self.h.materials.len() as u32 - 1
    }

    /// Adds a compiled mesh record (bounds computed from `geometry`).
    pub fn mesh(
        &mut self,
        source_mesh: u32,
        lod: u32,
        material: u32,
        geometry: MeshGeometry,
    ) -> u32 {
        let mut b = Aabb::EMPTY;
        for &p in &geometry.positions {
            b.grow_point(p);
        }
        self.h.meshes.push(MeshRecord {
            source_mesh,
            lod,
            material,
            vertex_count: geometry.positions.len() as u32,
            triangle_count: (geometry.indices.len() / 3) as u32,
            normals_offset: NONE_U64,
            bounds_min: b.min,
            bounds_max: b.max,
            ..Default::default()
        });
        self.h.geometry.push(geometry);
        self.h.meshes.len() as u32 - 1
    }

    pub fn triangle_blas(&mut self, meshes: &[u32]) -> u32 {
        let base = self.h.geometries.len() as u32;
        let mut b = Aabb::EMPTY;
        let mut tris = 0;
        for &m in meshes {
            self.h.geometries.push(GeometryRecord {
                mesh: m,
                _pad: [0; 3],
            });
            let r = &self.h.meshes[m as usize];
            b = b.union(&Aabb::new(r.bounds_min, r.bounds_max));
            tris += r.triangle_count;
        }
        self.push_blas(BLAS_TRIANGLES, base, meshes.len() as u32, b, tris)
    }

    fn push_blas(&mut self, kind: u32, base: u32, count: u32, b: Aabb, prims: u32) -> u32 {
        self.h.blases.push(BlasRecord {
            kind,
            item_base: base,
            item_count: count,
            level: 1,
            bounds_min: b.min,
            primitive_count: prims,
            bounds_max: b.max,
            _pad: 0,
        });
        self.blas_bounds.push(b);
        self.h.blases.len() as u32 - 1
    }

    /// A TLAS over `(tlas_from_blas, blas)` instances. A PI BLAS placed with a transform other
    /// than the identity is rebuilt with that transform folded into its PIs (hierarchies place
    /// AABB BLASes with the identity only: `HierarchyView::check_references`).
    pub fn tlas(&mut self, instances: &[([f32; 12], u32)]) -> u32 {
        let instances: Vec<([f32; 12], u32)> = instances
            .iter()
            .map(|&(m, blas)| match self.pi_sources.get(&blas) {
                Some(src) if m != crate::ray::IDENTITY_3X4 => {
                    let folded: Vec<_> = src
                        .iter()
                        .map(|(p, t)| (crate::ray::compose(&m, p), *t))
                        .collect();
                    (crate::ray::IDENTITY_3X4, self.pi_blas(&folded))
                }
                _ => (m, blas),
            })
            .collect();
        let base = self.h.instances.len() as u32;
        let mut b = Aabb::EMPTY;
        for &(m, blas) in &instances {
            self.h.instances.push(InstanceRecord {
                tlas_from_blas: m,
                blas,
                element: NONE_U32,
                ..Default::default()
            });
            b = b.union(&self.blas_bounds[blas as usize].transformed(&m));
        }
        self.h.tlases.push(TlasRecord {
            instance_base: base,
            instance_count: instances.len() as u32,
            level: 0,
            element: NONE_U32,
            bounds_min: b.min,
            box_list_instances: 0,
            bounds_max: b.max,
            _pad1: 0,
        });
        self.tlas_bounds.push(b);
        self.h.tlases.len() as u32 - 1
    }

    /// A BLAS of programmable instances, each `(parent_from_child, target)`; the AABB is the
    /// target's bounds mapped into this BLAS's space, and `child_from_parent` is stored.
    pub fn pi_blas(&mut self, pis: &[([f32; 12], PiTarget)]) -> u32 {
        let base = self.h.pis.len() as u32;
        let mut b = Aabb::EMPTY;
        for &(parent_from_child, target) in pis {
            let (kind, id, child_bounds) = match target {
                PiTarget::Tlas(t) => (PI_TLAS, t, self.tlas_bounds[t as usize]),
                PiTarget::LodSelector(s) => (PI_LOD_SELECTOR, s, self.selector_bounds[s as usize]),
            };
            let aabb = child_bounds.transformed(&parent_from_child);
            let child_from_parent = crate::ray::invert(&parent_from_child)
                .expect("fixture PI transform must be invertible");
            self.h.pis.push(PiRecord {
                child_from_parent,
                aabb_min: aabb.min,
                kind,
                aabb_max: aabb.max,
                target: id,
            });
            b = b.union(&aabb);
        }
        let id = self.push_blas(BLAS_AABBS, base, pis.len() as u32, b, pis.len() as u32);
        self.pi_sources.insert(id, pis.to_vec());
        id
    }

    /// A selector over TLASes (finest first); its sphere bounds all levels.
    pub fn lod_selector(&mut self, levels: &[u32], source_mesh: u32) -> u32 {
        let base = self.h.lod_levels.len() as u32;
        let mut b = Aabb::EMPTY;
        for &t in levels {
            self.h.lod_levels.push(t);
            b = b.union(&self.tlas_bounds[t as usize]);
        }
        let c = b.centroid();
        let radius = crate::ray::length(crate::ray::sub(b.max, c));
        self.h.lod_selectors.push(LodSelectorRecord {
            center: c,
            radius,
            level_base: base,
            level_count: levels.len() as u32,
            source_mesh,
            _pad: 0,
        });
        self.selector_bounds.push(b);
        self.h.lod_selectors.len() as u32 - 1
    }

    pub fn finish(mut self, root_tlas: u32) -> OwnedHierarchy {
        self.h.root_tlas = root_tlas;
        self.h
    }
}

/// A row-major 3×4 with uniform scale `s`, rotation `angle_rad` about +Y, then translation.
pub fn srt(s: f32, angle_rad: f32, t: [f32; 3]) -> [f32; 12] {
    let (sn, cs) = angle_rad.sin_cos();
    [
        s * cs,
        0.0,
        s * sn,
        t[0],
        0.0,
        s,
        0.0,
        t[1],
        -s * sn,
        0.0,
        s * cs,
        t[2],
    ]
}

type M64 = [[f64; 4]; 3];

fn m64(m: &[f32; 12]) -> M64 {
    std::array::from_fn(|r| std::array::from_fn(|c| m[r * 4 + c] as f64))
}

fn mul64(a: &M64, b: &M64) -> M64 {
    std::array::from_fn(|r| {
        std::array::from_fn(|c| {
            let t = if c == 3 { a[r][3] } else { 0.0 };
            t + (0..3).map(|k| a[r][k] * b[k][c]).sum::<f64>()
        })
    })
}

fn inv64(m: &M64) -> M64 {
    let a = |r: usize, c: usize| m[r][c];
    let det = a(0, 0) * (a(1, 1) * a(2, 2) - a(1, 2) * a(2, 1))
        - a(0, 1) * (a(1, 0) * a(2, 2) - a(1, 2) * a(2, 0))
        + a(0, 2) * (a(1, 0) * a(2, 1) - a(1, 1) * a(2, 0));
    let cof =
        |r0: usize, c0: usize, r1: usize, c1: usize| a(r0, c0) * a(r1, c1) - a(r0, c1) * a(r1, c0);
    let l = [
        [cof(1, 1, 2, 2), -cof(0, 1, 2, 2), cof(0, 1, 1, 2)],
        [-cof(1, 0, 2, 2), cof(0, 0, 2, 2), -cof(0, 0, 1, 2)],
        [cof(1, 0, 2, 1), -cof(0, 0, 2, 1), cof(0, 0, 1, 1)],
    ];
    std::array::from_fn(|r| {
        let row = [l[r][0] / det, l[r][1] / det, l[r][2] / det];
        let t = -(row[0] * m[0][3] + row[1] * m[1][3] + row[2] * m[2][3]);
        [row[0], row[1], row[2], t]
    })
}

/// One leaf instance of a flattened hierarchy.
#[derive(Clone, Copy, Debug)]
pub struct FlatInstance {
    pub world_from_mesh: [[f64; 4]; 3],
    pub mesh_record: u32,
    /// The selector level taken on the path, if any.
    pub lod: Option<u32>,
}

/// Every mesh instance reachable from the root, taking level `lod_level` (clamped) at every
/// selector; recursion is fine here, fixtures are shallow.
pub fn flatten(view: &HierarchyView<'_>, lod_level: u32) -> Vec<FlatInstance> {
    fn rec(
        v: &HierarchyView<'_>,
        t: u32,
        world_from_tlas: M64,
        lod: Option<u32>,
        lod_level: u32,
        out: &mut Vec<FlatInstance>,
    ) {
        let tl = &v.tlases[t as usize];
        for inst in &v.instances[tl.instance_base as usize..][..tl.instance_count as usize] {
            let world_from_blas = mul64(&world_from_tlas, &m64(&inst.tlas_from_blas));
            let b = &v.blases[inst.blas as usize];
            let items = b.item_base as usize..(b.item_base + b.item_count) as usize;
            if b.kind == BLAS_TRIANGLES {
                for g in &v.geometries[items] {
                    out.push(FlatInstance {
                        world_from_mesh: world_from_blas,
                        mesh_record: g.mesh,
                        lod,
                    });
                }
                continue;
            }
            for p in &v.pis[items] {
                let world_from_child = mul64(&world_from_blas, &inv64(&m64(&p.child_from_parent)));
                match p.kind {
                    PI_TLAS => rec(v, p.target, world_from_child, lod, lod_level, out),
                    _ => {
                        let s = &v.lod_selectors[p.target as usize];
                        let level = lod_level.min(s.level_count - 1);
                        let tlas = v.lod_levels[(s.level_base + level) as usize];
                        rec(v, tlas, world_from_child, Some(level), lod_level, out);
                    }
                }
            }
        }
    }
    let mut out = Vec::new();
    let id = m64(&crate::ray::IDENTITY_3X4);
    rec(view, view.root_tlas, id, None, lod_level, &mut out);
    out
}

/// A hit of the brute-force reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BruteHit {
    pub t: f64,
    pub mesh_record: u32,
    pub primitive: u32,
}

/// Every triangle of every flattened instance in world space (f64).
#[derive(Clone, Debug)]
pub struct BruteForce {
    tris: Vec<([[f64; 3]; 3], u32, u32)>,
}

impl BruteForce {
    pub fn new(h: &OwnedHierarchy, lod_level: u32) -> Self {
        let mut tris = Vec::new();
        for fi in flatten(&h.view(), lod_level) {
            let g = &h.geometry[fi.mesh_record as usize];
            let m = &fi.world_from_mesh;
            let xf = |p: [f32; 3]| -> [f64; 3] {
                std::array::from_fn(|r| {
                    m[r][0] * p[0] as f64 + m[r][1] * p[1] as f64 + m[r][2] * p[2] as f64 + m[r][3]
                })
            };
            for (i, t) in g.indices.chunks_exact(3).enumerate() {
                let v = [t[0], t[1], t[2]].map(|k| xf(g.positions[k as usize]));
                tris.push((v, fi.mesh_record, i as u32));
            }
        }
        Self { tris }
    }

    pub fn triangle_count(&self) -> usize {
        self.tris.len()
    }

    /// Closest hit with `t > t_min` along the normalised `dir` (Möller–Trumbore in f64).
    pub fn closest(&self, org: [f32; 3], dir: [f32; 3], t_min: f64) -> Option<BruteHit> {
        self.closest_within(org, dir, t_min, 0.0)
    }

    /// [`closest`](Self::closest) with each triangle grown (`edge_eps` > 0) or shrunk (< 0) by
    /// `edge_eps` in barycentric terms: what f32 traversal may decide either way on a ray
    /// that grazes an edge.
    pub fn closest_within(
        &self,
        org: [f32; 3],
        dir: [f32; 3],
        t_min: f64,
        edge_eps: f64,
    ) -> Option<BruteHit> {
        let o = org.map(|v| v as f64);
        let len = dir
            .iter()
            .map(|&v| (v as f64) * (v as f64))
            .sum::<f64>()
            .sqrt();
        let d = dir.map(|v| v as f64 / len);
        let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
        let cross = |a: [f64; 3], b: [f64; 3]| {
            [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ]
        };
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let mut best: Option<BruteHit> = None;
        for &([v0, v1, v2], mesh_record, primitive) in &self.tris {
            let e1 = sub(v1, v0);
            let e2 = sub(v2, v0);
            let p = cross(d, e2);
            let det = dot(e1, p);
            if det.abs() < 1e-300 {
                continue;
            }
            let s = sub(o, v0);
            let u = dot(s, p) / det;
            let q = cross(s, e1);
            let v = dot(d, q) / det;
            if u < -edge_eps || v < -edge_eps || u + v > 1.0 + edge_eps {
                continue;
            }
            let t = dot(e2, q) / det;
            if t > t_min && best.is_none_or(|b| t < b.t) {
                best = Some(BruteHit {
                    t,
                    mesh_record,
                    primitive,
                });
            }
        }
        best
    }
}

/// A closed octahedron-like mesh of `2 n (n - 1)` triangles around the origin with radius 1:
/// a UV sphere with `n` segments and `n` rings (used by tests and the bench).
pub fn uv_sphere(n: u32) -> MeshGeometry {
    let n = n.max(3);
    let mut positions = Vec::new();
    for r in 0..=n {
        let phi = std::f32::consts::PI * r as f32 / n as f32;
        for s in 0..n {
            let th = 2.0 * std::f32::consts::PI * s as f32 / n as f32;
            positions.push([phi.sin() * th.cos(), phi.cos(), phi.sin() * th.sin()]);
        }
    }
    let mut indices = Vec::new();
    for r in 0..n {
        for s in 0..n {
            let a = r * n + s;
            let b = r * n + (s + 1) % n;
            let c = a + n;
            let d = b + n;
            if r != 0 {
                indices.extend([a, b, c]);
            }
            if r != n - 1 {
                indices.extend([b, d, c]);
            }
        }
    }
    MeshGeometry {
        positions,
        indices,
        normals: None,
        primitive_map: None,
        uvs: None,
    }
}
