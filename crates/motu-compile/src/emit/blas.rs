//! BLASes: a prototype's geometry groups, baked copies, triangle BLASes grouped by location under
//! the bound, AABB BLASes and the TLAS split.

use crate::analyze::edge_ref;
use crate::partition::{group_by_location, Item};
use crate::split::median_partition;
use crate::tables::{next_id, set_bounds};
use crate::{tlas_split, xform, CompileError};
use motu_abi::{
    BlasRecord, GeometryRecord, PiRecord, BLAS_TRIANGLES, FLAG_NEEDS_ANY_HIT, NONE_U32,
};
use motu_scene::{Aabb, MeshData, MeshId, PrototypeId, Scene, Transform34};

use super::{pi_centre, Emitter};

impl Emitter<'_, '_, '_, '_> {
    /// `G(P)`: `P`'s non-LOD meshes as triangle BLASes of at most [`Self::bound`] triangles
    /// (for the root, per element first, so every root placement has one element): a mesh over
    /// the bound is split into clusters (a BLAS each); the others, one geometry each, are
    /// grouped by location under the bound.
    pub(super) fn g_for_proto(&mut self, p: PrototypeId) -> Result<(u32, u32), CompileError> {
        let g = self.g_of_proto[p.index()];
        if g.1 > 0 {
            return Ok(g);
        }
        let scene = self.plan.scene;
        let bound = self.bound();
        // (element, record, item); few per prototype.
        let mut small: Vec<(u32, u32, Item)> = Vec::new();
        let mut big: Vec<(u32, usize, MeshId)> = Vec::new();
        for (j, &m) in scene.meshes_of(p).iter().enumerate() {
            if !self.plan.mesh_kept(p, j, m) || self.plan.mesh_gets_lod(m) {
                continue;
            }
            let info = scene.mesh(m);
            let element = if p == Scene::ROOT {
                self.mesh_element(p, j)
            } else {
                NONE_U32
            };
            if info.triangle_count > bound {
                big.push((element, j, m));
                continue;
            }
            let record = self.record_for(p, j, m)?;
            let item = Item {
                index: NONE_U32, // set once sorted by element
                centre: info.bounds.center().to_array(),
                triangles: u64::from(info.triangle_count),
            };
            small.push((element, record, item));
        }
        let first = next_id(self.out.blases.len(), "BLASes")?;
        for (element, j, m) in big {
            let template = self.source_record(p, j, m);
            let (r0, n) = match self.stored_records(m, &template)? {
                Some(made) => made,
                None => {
                    let data = self.load_source(m)?;
                    self.made_records(m, &template, 0, &data, None)?
                }
            };
            for r in r0..r0 + n {
                self.triangle_blas(&[r], element)?;
            }
        }
        small.sort_by_key(|it| it.0);
        for (k, it) in small.iter_mut().enumerate() {
            it.2.index = k as u32;
        }
        let records: Vec<u32> = small.iter().map(|it| it.1).collect();
        let mut items: Vec<Item> = Vec::new();
        let mut k = 0;
        while k < small.len() {
            let element = small[k].0;
            let run_end = small[k..]
                .iter()
                .position(|it| it.0 != element)
                .map_or(small.len(), |n| k + n);
            items.clear();
            items.extend(small[k..run_end].iter().map(|it| it.2));
            self.blases_by_location(&mut items, &records, element)?;
            k = run_end;
        }
        let count = next_id(self.out.blases.len(), "BLASes")? - first;
        self.g_of_proto[p.index()] = (first, count);
        Ok((first, count))
    }

    /// A baked prototype `p` (`Plan::bakes`): every kept mesh in its subtree, one copy per
    /// path from `p` transformed into `p`'s space, as mesh records of the source mesh with a
    /// primitive map to its triangles (hits name the source mesh and triangle, as instanced
    /// copies do), grouped by location into triangle BLASes under the bound.
    pub(super) fn bake_for_proto(&mut self, p: PrototypeId) -> Result<(u32, u32), CompileError> {
        let b = self.bake_of_proto[p.index()];
        if b.1 > 0 {
            return Ok(b);
        }
        let scene = self.plan.scene;
        // Per source mesh (in id order): its owner and index there, and every placement.
        let mut uses: std::collections::BTreeMap<u32, (PrototypeId, usize, Vec<Transform34>)> =
            std::collections::BTreeMap::new();
        let mut stack = vec![(p, Transform34::IDENTITY)];
        while let Some((q, proto_from_q)) = stack.pop() {
            for (j, &m) in scene.meshes_of(q).iter().enumerate() {
                if self.plan.mesh_kept(q, j, m) {
                    uses.entry(m.0)
                        .or_insert_with(|| (q, j, Vec::new()))
                        .2
                        .push(proto_from_q);
                }
            }
            let base = scene.edge_base(q) as usize;
            for (k, e) in scene.walk_edges(q).enumerate() {
                if self.plan.edge_kept(q, base + k, edge_ref!(e)) {
                    stack.push((e.child, xform::compose(&proto_from_q, &e.parent_from_child)));
                }
            }
        }
        let mut records: Vec<(u32, Item)> = Vec::new();
        for (m, (q, j, placements)) in uses {
            let m = MeshId(m);
            let data = self.load_source(m)?;
            let (baked, map) = bake_copies(&data, &placements);
            drop(data);
            let template = self.source_record(q, j, m);
            let (r0, n) = self.made_records(m, &template, 0, &baked, Some(&map))?;
            for r in r0..r0 + n {
                let rec = &self.out.meshes[r as usize];
                let bounds = xform::aabb_from_record(rec.bounds_min, rec.bounds_max);
                records.push((
                    r,
                    Item {
                        index: records.len() as u32,
                        centre: bounds.center().to_array(),
                        triangles: u64::from(rec.triangle_count),
                    },
                ));
            }
        }
        let first = next_id(self.out.blases.len(), "BLASes")?;
        let (ids, mut items): (Vec<u32>, Vec<Item>) = records.into_iter().unzip();
        self.blases_by_location(&mut items, &ids, NONE_U32)?;
        let count = next_id(self.out.blases.len(), "BLASes")? - first;
        self.out.report.baked_prototypes += 1;
        self.bake_of_proto[p.index()] = (first, count);
        Ok((first, count))
    }

    /// Triangle BLASes of `element` over mesh records `records[item.index]` for `items`,
    /// grouped by location under the bound.
    pub(super) fn blases_by_location(
        &mut self,
        items: &mut [Item],
        records: &[u32],
        element: u32,
    ) -> Result<(), CompileError> {
        let mut ranges: Vec<(usize, usize)> = Vec::new();
        group_by_location(items, u64::from(self.bound()), &mut ranges);
        let mut group: Vec<u32> = Vec::new();
        for &(a, b) in &ranges {
            group.clear();
            group.extend(items[a..b].iter().map(|it| records[it.index as usize]));
            // Mesh order inside a group: as in the scene (stable ids per geometry).
            group.sort_unstable();
            self.triangle_blas(&group, element)?;
        }
        Ok(())
    }

    pub(super) fn triangle_blas(
        &mut self,
        records: &[u32],
        element: u32,
    ) -> Result<u32, CompileError> {
        let id = next_id(self.out.blases.len(), "BLASes")?;
        let item_base = next_id(self.out.geometries.len(), "geometries")?;
        let mut bounds = Aabb::EMPTY;
        let (mut tris, mut flags) = (0u64, 0u32);
        for &r in records {
            next_id(self.out.geometries.len(), "geometries")?;
            self.out.geometries.push(GeometryRecord {
                mesh: r,
                _pad: [0; 3],
            });
            let m = &self.out.meshes[r as usize];
            bounds = bounds.union(&xform::aabb_from_record(m.bounds_min, m.bounds_max));
            tris += u64::from(m.triangle_count);
            flags |= m.flags & FLAG_NEEDS_ANY_HIT;
        }
        let primitive_count = u32::try_from(tris).map_err(|_| CompileError::TooMany {
            what: "triangles in one BLAS",
            count: tris,
        })?;
        let mut rec = BlasRecord {
            kind: BLAS_TRIANGLES,
            item_base,
            item_count: records.len() as u32,
            primitive_count,
            ..Default::default()
        };
        set_bounds(&mut rec.bounds_min, &mut rec.bounds_max, &bounds);
        self.out.blases.push(rec);
        self.blas_flags.push(flags);
        self.blas_element.push(element);
        Ok(id)
    }

    /// One AABB BLAS over `pis[begin..end]`, instanced with identity by the TLAS being emitted;
    /// several (median-split by AABB centre) when over the primitive cap, and in the root TLAS
    /// one group per element.
    pub(super) fn aabb_blases(&mut self, begin: usize, end: usize) -> Result<(), CompileError> {
        let cap = self.plan.opts.max_primitives_per_blas as usize;
        // Runs of one element: (begin, end, element).
        let mut runs: Vec<(usize, usize, u32)> = Vec::new();
        if self.in_root && self.pi_elements.len() == end - begin {
            let mut tagged: Vec<(u32, PiRecord)> = self
                .pi_elements
                .iter()
                .copied()
                .zip(self.out.pis[begin..end].iter().copied())
                .collect();
            tagged.sort_by_key(|t| t.0);
            for (k, (element, pi)) in tagged.iter().enumerate() {
                self.out.pis[begin + k] = *pi;
                match runs.last_mut() {
                    Some(run) if run.2 == *element => run.1 += 1,
                    _ => runs.push((begin + k, begin + k + 1, *element)),
                }
            }
        } else {
            runs.push((begin, end, NONE_U32));
        }
        let mut ranges = Vec::new();
        for (a, b, element) in runs {
            ranges.clear();
            if b - a > cap {
                self.out.report.split_aabb_blases += 1;
                median_partition(&mut self.out.pis[a..b], pi_centre, cap, &mut ranges);
            } else {
                ranges.push((0, b - a));
            }
            for &(x, y) in &ranges {
                let blas = self.aabb_blas(a + x, a + y)?;
                self.push_instance(blas, &Transform34::IDENTITY, element)?;
            }
        }
        Ok(())
    }

    pub(super) fn aabb_blas(&mut self, begin: usize, end: usize) -> Result<u32, CompileError> {
        let id = tlas_split::push_aabb_blas(&mut self.out, begin, end)?;
        self.blas_flags.push(0);
        self.blas_element.push(NONE_U32);
        Ok(id)
    }

    /// Splits `tlas` until its instance count fits the cap ([`tlas_split::split_tlas`]).
    pub(super) fn split_tlas(&mut self, tlas: u32) -> Result<(), CompileError> {
        let per_blas = self.plan.opts.max_primitives_per_blas as usize;
        let (flags, elements) = (&mut self.blas_flags, &mut self.blas_element);
        tlas_split::split_tlas(
            &mut self.out,
            tlas,
            self.instance_cap,
            per_blas,
            self.in_root,
            self.plan.opts.split_scratch_dir.as_deref(),
            &mut |element| {
                flags.push(0);
                elements.push(element);
            },
        )
    }
}

/// `data` copied once per placement (`proto_from_mesh`), positions and normals transformed (a
/// mirroring placement flips the winding back), with each copy's triangle-to-source map.
pub(super) fn bake_copies(data: &MeshData, placements: &[Transform34]) -> (MeshData, Vec<u32>) {
    let (nv, nt) = (data.positions.len(), data.triangle_count());
    let copies = placements.len();
    let mut out = MeshData {
        positions: Vec::with_capacity(nv * copies),
        normals: data
            .normals
            .as_ref()
            .map(|_| Vec::with_capacity(nv * copies)),
        uvs: data.uvs.as_ref().map(|_| Vec::with_capacity(nv * copies)),
        indices: Vec::with_capacity(3 * nt * copies),
    };
    let mut map = Vec::with_capacity(nt * copies);
    for xf in placements {
        let m = xf.to_mat4();
        let linear = glam::Mat3::from_mat4(m);
        // Normals by the cofactor matrix (the inverse transpose up to det, defined even when
        // the placement is singular), its sign kept so they still point outward.
        let det = linear.determinant();
        let cofactor = glam::Mat3::from_cols(
            linear.y_axis.cross(linear.z_axis),
            linear.z_axis.cross(linear.x_axis),
            linear.x_axis.cross(linear.y_axis),
        );
        let sign = if det < 0.0 { -1.0 } else { 1.0 };
        let base = out.positions.len() as u32;
        out.positions.extend(
            data.positions
                .iter()
                .map(|&p| m.transform_point3(glam::Vec3::from(p)).to_array()),
        );
        if let (Some(on), Some(n)) = (out.normals.as_mut(), data.normals.as_ref()) {
            on.extend(n.iter().map(|&v| {
                (sign * (cofactor * glam::Vec3::from(v)))
                    .normalize_or_zero()
                    .to_array()
            }));
        }
        if let (Some(ou), Some(u)) = (out.uvs.as_mut(), data.uvs.as_ref()) {
            ou.extend_from_slice(u);
        }
        for t in data.indices.chunks_exact(3) {
            let (a, b, c) = (t[0] + base, t[1] + base, t[2] + base);
            if det < 0.0 {
                out.indices.extend_from_slice(&[a, c, b]);
            } else {
                out.indices.extend_from_slice(&[a, b, c]);
            }
        }
        map.extend(0..nt as u32);
    }
    (out, map)
}
